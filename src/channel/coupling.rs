//! Axis couplings (`#SET AX LINK`, `#ENABLE AX LINK`, FCT-C4 §7.3.1): a gantry slave follows
//! its master with the offset it had when the coupling was enabled. Block preparation moves the
//! slave along with its master (so its path is checked against its own software limit
//! switches); a programmed move of a coupled slave is refused. In a measurement the master
//! measures: slaves neither need to latch nor are monitored for the fixed stop (§7.3 "Measurement
//! with gantry axes").

use super::Channel;
use crate::messages::{ids, CncMessage};

/// One coupling: `slave` follows `master`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisCoupling {
    /// Slave axis index.
    pub slave: usize,
    /// Master axis index.
    pub master: usize,
}

#[derive(Debug, Clone, PartialEq)]
struct Group {
    number: i64,
    links: Vec<AxisCoupling>,
    /// Offsets (slave − master) captured at enabling; `None` while disabled.
    offsets: Option<Vec<f64>>,
}

/// The coupling groups of a channel.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Couplings {
    groups: Vec<Group>,
}

impl Couplings {
    /// Enabled (slave, master, offset) triples.
    pub(super) fn active(&self) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
        self.groups
            .iter()
            .filter_map(|g| g.offsets.as_ref().map(|o| (g, o)))
            .flat_map(|(g, o)| {
                g.links
                    .iter()
                    .zip(o)
                    .map(|(l, off)| (l.slave, l.master, *off))
            })
    }
}

impl Channel {
    /// `#SET AX LINK [group, …]`: define (or redefine, while disabled) a coupling group.
    pub fn define_coupling(
        &mut self,
        group: i64,
        links: Vec<AxisCoupling>,
    ) -> Result<(), CncMessage> {
        let n = self.axes.len();
        for l in &links {
            if l.slave >= n || l.master >= n || l.slave == l.master {
                return Err(CncMessage::error(
                    ids::NC_EVALUATION,
                    format!("#SET AX LINK[{group}]: invalid coupling"),
                ));
            }
        }
        if let Some(g) = self.couplings.groups.iter_mut().find(|g| g.number == group) {
            if g.offsets.is_some() {
                return Err(CncMessage::error(
                    ids::NC_EVALUATION,
                    format!(
                        "#SET AX LINK[{group}]: the group is enabled; disable it before redefining"
                    ),
                ));
            }
            g.links = links;
        } else {
            self.couplings.groups.push(Group {
                number: group,
                links,
                offsets: None,
            });
        }
        Ok(())
    }

    /// `#ENABLE AX LINK [group]` / `#DISABLE AX LINK [group]` (`None` = all groups).
    pub fn enable_coupling(&mut self, group: Option<i64>, enable: bool) -> Result<(), CncMessage> {
        let cmd = self.command_positions();
        let mut found = false;
        for g in &mut self.couplings.groups {
            if group.is_some_and(|n| n != g.number) {
                continue;
            }
            found = true;
            g.offsets = enable.then(|| {
                g.links
                    .iter()
                    .map(|l| cmd[l.slave] - cmd[l.master])
                    .collect()
            });
        }
        if !found && group.is_some() {
            return Err(CncMessage::error(
                ids::NC_EVALUATION,
                format!(
                    "AX LINK group {} is not defined (#SET AX LINK first)",
                    group.unwrap_or(0)
                ),
            ));
        }
        Ok(())
    }

    /// Whether axis `i` is an enabled coupling slave.
    pub fn is_coupled_slave(&self, i: usize) -> bool {
        self.couplings.active().any(|(s, _, _)| s == i)
    }

    /// Apply the enabled couplings to a motion target: slaves follow their masters. Errors when
    /// the program moves a coupled slave itself.
    pub(super) fn couple_target(&self, target: &mut [f64]) -> Result<(), CncMessage> {
        for (slave, master, off) in self.couplings.active() {
            let cur = self.axes[slave].command();
            if (target[slave] - cur).abs() > 1e-9 {
                return Err(CncMessage::error(
                    ids::NC_EVALUATION,
                    format!(
                        "axis {} is coupled to {} (#ENABLE AX LINK) and cannot be programmed",
                        self.axes[slave].name(),
                        self.axes[master].name()
                    ),
                ));
            }
            target[slave] = target[master] + off;
        }
        Ok(())
    }
}
