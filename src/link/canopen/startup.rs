//! Start-up of one axis's node in PRE-OPERATIONAL (the part of [`super::CanopenLink`]'s boot
//! that talks to the node by SDO about its PDOs, [`super::fit`]): ask which objects of the
//! drive definition the node offers and which PDOs it has, fit the master's layout into them,
//! write the mapping by the CiA 301 procedure (fitting again after a refusal), disable the
//! node's other PDOs, and write the mode of operation 0x6060 = 8 (CSP) when no RPDO carries it.

use super::fit::{self, NodePdos, Refusal};
use super::{decode_le, other, CanopenLink};
use crate::bus::canopen::pdo::{Direction, PdoSlots, MAX_ENTRIES, MAX_PDOS};
use crate::drive::ds402::MODE_CSP;
use crate::link::LinkError;

impl CanopenLink {
    /// An SDO upload of axis `i`'s node: the data, or the abort code; other failures (time-out,
    /// bus) are errors.
    fn ask(&mut self, i: usize, index: u16, sub: u8) -> Result<Result<Vec<u8>, u32>, LinkError> {
        match self.sdo_transfer(i, index, sub, None) {
            Ok(data) => Ok(Ok(data)),
            Err(LinkError::Abort { code, .. }) => Ok(Err(code)),
            Err(e) => Err(e),
        }
    }

    /// The PDOs axis `i`'s node offers, per direction ([`fit::NodePdos`]): PDO k + 1 exists when
    /// its communication parameter answers sub 1 (CiA 301 §7.5.2.35 / .37); it takes as many
    /// entries as its mapping parameter has sub-indices, found from [`MAX_ENTRIES`] down to
    /// the current number of entries (sub 0), the first that answers (§7.5.2.36 / .38: the
    /// entries are sub-indices 1 … n).
    pub(super) fn ask_pdo_slots(&mut self, i: usize) -> Result<NodePdos, LinkError> {
        let mut pdos = NodePdos {
            rx: PdoSlots {
                entries: [0; MAX_PDOS],
            },
            tx: PdoSlots {
                entries: [0; MAX_PDOS],
            },
        };
        for dir in [Direction::Rx, Direction::Tx] {
            for k in 0..MAX_PDOS as u8 {
                if !fit::is_there(&self.ask(i, dir.comm_index(k), 1)?) {
                    continue;
                }
                let map = dir.mapping_index(k);
                let count = self.ask(i, map, 0)?;
                if !fit::is_there(&count) {
                    continue;
                }
                let now = count.map_or(0, |d| d.first().copied().unwrap_or(0));
                let mut entries = now.min(MAX_ENTRIES);
                for j in (now.max(1)..=MAX_ENTRIES).rev() {
                    if j <= entries {
                        break;
                    }
                    if fit::is_there(&self.ask(i, map, j)?) {
                        entries = j;
                        break;
                    }
                }
                pdos.of(dir).entries[usize::from(k)] = entries;
            }
        }
        let node = self.axes[i].node;
        tracing::debug!(target: "fieldprobe::link::canopen", node, "node {node} offers {} and {}",
            pdos.rx.describe(Direction::Rx), pdos.tx.describe(Direction::Tx));
        Ok(pdos)
    }

    /// Start-up, axis `i`: ask its node for every object of the drive definition's PDO
    /// mapping and for its PDOs, fit the definition to what the node offers and write the
    /// mapping ([`fit`]); an object the node refuses in the mapping is left out (touch probe)
    /// or refuses the start-up (anything else), a mapping sub-index it refuses lowers what the
    /// master assumes that PDO takes, and the mapping is written again from the start. Then
    /// 0x6060 = 8 by SDO when no RPDO carries it.
    pub(super) fn fit_and_map(&mut self, i: usize) -> Result<(), LinkError> {
        let node = self.axes[i].node;
        let configured = self.axes[i].def.clone();
        let mut lacking: Vec<fit::Lacking> = Vec::new();
        for e in configured
            .rxpdo
            .entries()
            .iter()
            .chain(configured.txpdo.entries())
        {
            if lacking.iter().any(|l| (l.index, l.sub) == (e.index, e.sub)) {
                continue;
            }
            let answer = self.ask(i, e.index, e.sub)?;
            let offer = fit::Offer::from_upload(answer.as_deref().map_err(|&c| c), e.ty);
            if let fit::Offer::Lacking(why) = offer {
                lacking.push(fit::Lacking {
                    index: e.index,
                    sub: e.sub,
                    why,
                });
            }
        }
        let mut pdos = self.ask_pdo_slots(i)?;
        let mode_by_sdo = loop {
            let (def, warning) = fit::fit(&configured, node, &lacking)?;
            let planned = fit::plan(&def, node, &pdos)?;
            let a = &mut self.axes[i];
            a.rx_sent = vec![None; planned.rx.len()];
            a.tx_held = vec![None; planned.tx.len()];
            a.rx = planned.rx;
            a.tx = planned.tx;
            a.def = planned.def;
            a.warning = warning;
            match self.write_mapping(i, &pdos)? {
                None => break planned.mode_by_sdo,
                Some(Refusal::Object(refused)) => {
                    if lacking
                        .iter()
                        .any(|l| (l.index, l.sub) == (refused.index, refused.sub))
                    {
                        // Refused although not mapped: cannot happen with a consistent node.
                        return Err(other(format!(
                            "node {node}: start-up: the node refuses {:#06X}:{:02X} in its PDO \
                             mapping ({}), which the master left out",
                            refused.index, refused.sub, refused.why
                        )));
                    }
                    lacking.push(refused);
                }
                Some(Refusal::NoSubIndex {
                    direction,
                    pdo,
                    sub,
                }) => {
                    let slot = &mut pdos.of(direction).entries[usize::from(pdo)];
                    if sub == 0 || *slot < sub {
                        return Err(other(format!(
                            "node {node}: start-up: mapping parameter {:#06X} refuses sub-index \
                             {sub} (SDO abort 0x06090011), which the master did not plan to use",
                            direction.mapping_index(pdo)
                        )));
                    }
                    tracing::info!(target: "fieldprobe::link::canopen", node,
                        "node {node}: mapping parameter {:#06X} has no sub-index {sub} (SDO abort \
                         0x06090011): it takes {} entries", direction.mapping_index(pdo), sub - 1);
                    *slot = sub - 1;
                }
            }
        };
        if mode_by_sdo {
            self.write_mode_of_operation(i)?;
        }
        Ok(())
    }

    /// Write axis `i`'s planned PDOs by the CiA 301 remap procedure and disable the node's
    /// other PDOs (of `pdos`); `Some(refusal)` when the node refused a mapping entry in a way
    /// the master fits around ([`fit::refusal`]).
    fn write_mapping(&mut self, i: usize, pdos: &NodePdos) -> Result<Option<Refusal>, LinkError> {
        let node = self.axes[i].node;
        let mut writes = Vec::new();
        for dir in [Direction::Rx, Direction::Tx] {
            let (planned, offered) = match dir {
                Direction::Rx => (self.axes[i].rx.clone(), pdos.rx),
                Direction::Tx => (self.axes[i].tx.clone(), pdos.tx),
            };
            for p in &planned {
                writes.extend(p.remap_writes());
            }
            for (k, _) in offered.present() {
                if planned.iter().any(|p| p.number == k) {
                    continue;
                }
                let cob = u32::from(dir.default_cob(k, node)) | 0x8000_0000;
                writes.push((dir.comm_index(k), 1, cob.to_le_bytes().to_vec()));
            }
        }
        for (index, sub, data) in writes {
            match self.sdo_transfer(i, index, sub, Some(&data)) {
                Ok(_) => {}
                Err(e @ LinkError::Abort { code, .. })
                    if sub >= 1
                        && ((0x1600..=0x17FF).contains(&index)
                            || (0x1A00..=0x1BFF).contains(&index)) =>
                {
                    let value = decode_le(&data, false) as u32;
                    return match fit::refusal(code, index, sub, value) {
                        Some(r) => Ok(Some(r)),
                        None => Err(e),
                    };
                }
                Err(e) => return Err(e),
            }
        }
        Ok(None)
    }

    /// 0x6060 modes of operation = 8 (cyclic synchronous position, CiA 402 §6.2) by SDO, for a
    /// mapping without it; a refusal stops the start-up naming node and object.
    fn write_mode_of_operation(&mut self, i: usize) -> Result<(), LinkError> {
        let node = self.axes[i].node;
        match self.sdo_transfer(i, 0x6060, 0, Some(&MODE_CSP.to_le_bytes())) {
            Ok(_) => {
                tracing::debug!(target: "fieldprobe::link::canopen", node,
                    "0x6060:00 modes of operation = 8 (CSP) by SDO: no RPDO carries it");
                Ok(())
            }
            Err(LinkError::Abort { code, .. }) => Err(other(format!(
                "node {node}: start-up: writing 0x6060:00 modes of operation = {MODE_CSP} (cyclic \
                 synchronous position; no RPDO carries it) refused, abort code {code:#010x} ({})",
                crate::bus::abort::abort_text(code)
            ))),
            Err(e) => Err(e),
        }
    }
}
