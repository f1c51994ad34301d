//! Acyclic drive access from the NC program (`#DRIVE WR/RD`, `#IDENT WR/RD`, FCT-C4 §7.3):
//! the channel queues object reads / writes, the machine carries them over the link's mailbox
//! (SDO / CoE) and reports back. A waiting request (`WAIT`, `SYN`) keeps the channel busy until
//! the answer arrives; a failure aborts the program.

use super::{Channel, Mode};
use crate::messages::{ids, CncMessage};

/// Read or write.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AcyclicOp {
    /// Read the object.
    Read,
    /// Write this wire value.
    Write(i64),
}

/// One acyclic access for the machine to carry out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AcyclicRequest {
    /// Identifier for [`Channel::acyclic_done`].
    pub id: u64,
    /// Channel axis (= device on the link).
    pub axis: usize,
    /// Object index.
    pub index: u16,
    /// Sub-index.
    pub sub: u8,
    /// Read or write.
    pub op: AcyclicOp,
}

/// Pending and finished acyclic requests of the channel.
#[derive(Debug, Clone, Default)]
pub(super) struct AcyclicState {
    next_id: u64,
    queued: Vec<AcyclicRequest>,
    /// Requests sent, awaiting an answer: (id, description for messages).
    pending: Vec<(u64, String)>,
    /// Answers not yet taken by the executor.
    results: Vec<(u64, Result<i64, String>)>,
}

impl Channel {
    /// Queue an acyclic access to axis `axis`'s drive. With `wait` the channel is busy until the
    /// answer is in. `what` describes the access for messages (`#DRIVE KEY=TORQUE_LIMIT`).
    /// A `cyclic` drive function (`commu = "CYCLIC"`) is not sent over the mailbox: the axis's
    /// adapter takes it into its command telegram at once, and the answer is there right away.
    pub fn queue_acyclic(
        &mut self,
        axis: usize,
        index: u16,
        sub: u8,
        op: AcyclicOp,
        wait: bool,
        what: &str,
    ) -> u64 {
        let a = &mut self.acyclic;
        a.next_id += 1;
        let id = a.next_id;
        a.pending.push((id, what.to_string()));
        a.queued.push(AcyclicRequest {
            id,
            axis,
            index,
            sub,
            op,
        });
        if wait && matches!(self.mode, Mode::Idle) {
            self.mode = Mode::WaitAcyclic { id };
        }
        id
    }

    /// A cyclic drive function (see [`queue_acyclic`](Self::queue_acyclic)): carried out on
    /// the axis's adapter now; the answer is taken like an acyclic one.
    pub fn cyclic_function(
        &mut self,
        axis: usize,
        index: u16,
        sub: u8,
        op: AcyclicOp,
        what: &str,
    ) -> u64 {
        let a = &mut self.acyclic;
        a.next_id += 1;
        let id = a.next_id;
        a.pending.push((id, what.to_string()));
        let result = match self.axes.get_mut(axis) {
            None => Err(format!("no axis {axis}")),
            Some(ax) => match op {
                AcyclicOp::Read => ax.read_cyclic(index, sub),
                AcyclicOp::Write(v) => ax.write_cyclic(index, sub, v).map(|()| v),
            }
            .map_err(|e| e.to_string()),
        };
        self.acyclic_done(id, result);
        id
    }

    /// Requests for the machine to carry out now.
    pub fn take_acyclic_requests(&mut self) -> Vec<AcyclicRequest> {
        std::mem::take(&mut self.acyclic.queued)
    }

    /// The machine reports the answer to request `id` (the value read, or the value written).
    pub fn acyclic_done(&mut self, id: u64, result: Result<i64, String>) {
        let Some(k) = self.acyclic.pending.iter().position(|(i, _)| *i == id) else {
            return;
        };
        let (_, what) = self.acyclic.pending.remove(k);
        if let Err(e) = &result {
            self.push(CncMessage::error(
                ids::ACYCLIC_FAILED,
                format!("{what}: {e}"),
            ));
            if !matches!(self.mode, Mode::Stopping { .. } | Mode::Aborted) {
                self.begin_stop(super::ChannelState::Aborted);
            }
        }
        if let Mode::WaitAcyclic { id: w } = self.mode {
            if w == id && result.is_ok() {
                self.mode = Mode::Idle;
            }
        }
        self.acyclic.results.push((id, result));
    }

    /// Take the answer of request `id`, if it has arrived.
    pub fn take_acyclic_result(&mut self, id: u64) -> Option<Result<i64, String>> {
        let k = self.acyclic.results.iter().position(|(i, _)| *i == id)?;
        Some(self.acyclic.results.remove(k).1)
    }
}
