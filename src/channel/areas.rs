//! Workspace and protection areas in the channel (FCT-C14): the channel's
//! [`AreaTable`], the `#CONTROL AREA` commands and definition blocks from the executor, the path
//! check of block preparation, and the PLC datum / control unit of FCT-C14 §6.3.
//!
//! The table lives as long as the channel: areas survive program end and program start, a
//! controller reset ([`Channel::reset`]) deactivates them (FCT-C14 §3 notices), and no area
//! exists at start-up. Definitions are MCS coordinates: the executor applies G54 / G92 and
//! ignores `#CS` before it hands a [`DefBlock`] over.

use super::Channel;
use crate::core::monitor::area_monitor::{
    position_inside, AreaHit, AreaMonitor, ChannelAxes, HitKind,
};
use crate::core::monitor::areas::{AreaCommand, AreaKind, AreaTable, DefBlock, Selector};
use crate::core::path::Segment;
use crate::messages::{ids, BlockRef, CncMessage};

/// A path check that refused a block.
#[derive(Debug, Clone, PartialEq)]
pub struct AreaRefusal {
    /// The block that was not executed.
    pub block: Option<BlockRef>,
    /// The refused path (ACS, one entry per channel axis).
    pub segment: Segment,
    /// What it violated and where.
    pub hit: AreaHit,
}

/// Area state of a channel.
#[derive(Debug, Clone, Default)]
pub(super) struct ChannelAreas {
    pub(super) table: AreaTable,
    pub(super) axes: ChannelAxes,
    pub(super) monitor: AreaMonitor,
    /// PLC datum `area_mon_violation_detected_r` (FCT-C14 §6.3).
    pub(super) violation_detected: bool,
    /// Control unit "suppress error output from working space monitoring in manual mode".
    pub(super) suppress_manual: bool,
    /// The last refused block.
    pub(super) refusal: Option<AreaRefusal>,
    /// Paths of the blocks that started, when recording.
    pub(super) path_log: Option<Vec<(Option<BlockRef>, Segment)>>,
}

impl ChannelAreas {
    pub(super) fn new(names: Vec<String>) -> Self {
        ChannelAreas {
            axes: ChannelAxes::new(names),
            ..Default::default()
        }
    }
}

/// Message text for a violation.
pub fn hit_text(hit: &AreaHit, axes: &ChannelAxes) -> String {
    let at = format!(
        "{}={:.6} {}={:.6} {}={:.6}",
        axes.name(hit.axes[0]),
        hit.point[0],
        axes.name(hit.axes[1]),
        hit.point[1],
        axes.name(hit.axes[2]),
        hit.point[2]
    );
    match (hit.kind, hit.id) {
        (HitKind::Protection, Some(id)) => {
            format!("the path enters protection area {id} at {at}")
        }
        (HitKind::Workspace, Some(id)) => format!("the path leaves workspace {id} at {at}"),
        (HitKind::Workspace, None) => format!(
            "the path starts outside the workspaces {:?} at {at}",
            hit.workspaces
        ),
        _ => "the path cannot be checked against the control areas (not finite)".to_string(),
    }
}

impl Channel {
    /// The control areas of this channel.
    pub fn areas(&self) -> &AreaTable {
        &self.areas.table
    }

    /// The active areas, bound to the channel axes.
    pub fn area_monitor(&self) -> &AreaMonitor {
        &self.areas.monitor
    }

    /// Which channel axes the areas use.
    pub fn area_axes(&self) -> &ChannelAxes {
        &self.areas.axes
    }

    /// PLC datum `area_mon_violation_detected_r` (FCT-C14 §6.3): a violation was detected by
    /// the workspace monitoring (a refused block, a jog stopped at an area, manual mode entered
    /// outside the permitted range). Cleared by a controller reset.
    pub fn area_mon_violation_detected_r(&self) -> bool {
        self.areas.violation_detected
    }

    /// Control unit "suppress error output from working space monitoring in manual mode" (seed
    /// 000 §6.3, used with P-CHAN-00442 = 0 / 2).
    pub fn set_area_mon_suppress_manual_w(&mut self, suppress: bool) {
        self.areas.suppress_manual = suppress;
    }

    /// The control unit as last written.
    pub fn area_mon_suppress_manual_w(&self) -> bool {
        self.areas.suppress_manual
    }

    /// The last block the path check refused.
    pub fn area_refusal(&self) -> Option<&AreaRefusal> {
        self.areas.refusal.as_ref()
    }

    /// Record the path of every block that starts (for `fieldprobe areas plot`).
    pub fn record_paths(&mut self) {
        self.areas.path_log.get_or_insert_with(Vec::new);
    }

    /// The recorded paths (block, ACS segment), if recording.
    pub fn path_log(&self) -> Option<&[(Option<BlockRef>, Segment)]> {
        self.areas.path_log.as_deref()
    }

    /// Execute `#CONTROL AREA …` (FCT-C14 §3). Errors are reported and abort the program;
    /// returns false then.
    pub fn area_command(&mut self, cmd: &AreaCommand) -> bool {
        let at = self.block;
        let pos = self.command_positions();
        let axes = self.areas.axes.clone();
        // One rule for activation and block preparation (seed 000 §3.2 "when a protection area
        // is activated, the TCP may not incur any violation at the current position"): the TCP
        // is located with the path check's tolerance band, so a TCP that ON accepts can always
        // leave, and one that no block could leave is refused here (docs/interpretations.md A18).
        let mut tcp = |a: &crate::core::monitor::areas::Area| {
            // Cannot be located: an unusable area is treated as violated.
            position_inside(a, &axes, &pos).unwrap_or(a.kind() == AreaKind::Prot)
        };
        let result = self.areas.table.apply(cmd, at, &mut tcp);
        match result {
            Ok(warnings) => {
                for w in warnings {
                    self.push(w);
                }
            }
            Err(e) => {
                if matches!(
                    e.kind,
                    crate::core::monitor::areas::AreaErrorKind::TcpInvalid { .. }
                ) {
                    self.areas.violation_detected = true;
                }
                self.report(e.message());
                return false;
            }
        }
        if let AreaCommand::End = cmd {
            // The area just defined must name channel axes that exist.
            let last = self.areas.table.areas().last().cloned();
            if let Some(area) = last {
                if let Err(text) = self.areas.axes.resolve(&area) {
                    let _ = self.areas.table.apply(
                        &AreaCommand::Clear(Selector::Id(area.id())),
                        at,
                        &mut |_: &crate::core::monitor::areas::Area| true,
                    );
                    self.report(CncMessage::error(ids::AREA_AXES, text));
                    return false;
                }
            }
        }
        self.rebuild_area_monitor()
    }

    /// One motion block between BEGIN and END (MCS, absolute, as the executor resolved it).
    pub fn area_definition_block(&mut self, block: &DefBlock) -> bool {
        match self.areas.table.definition_block(block) {
            Ok(()) => true,
            Err(e) => {
                self.report(e.message());
                false
            }
        }
    }

    /// A definition is open: motion blocks define geometry and do not move the axes.
    pub fn area_defining(&self) -> bool {
        self.areas.table.is_defining()
    }

    /// Program end or abort: areas stay; an open definition is discarded and reported as an
    /// error (the program aborts if it was still running). Returns whether one was open.
    pub fn area_program_end(&mut self) -> bool {
        match self.areas.table.program_end() {
            Some(m) => {
                self.report(m);
                true
            }
            None => false,
        }
    }

    fn rebuild_area_monitor(&mut self) -> bool {
        match AreaMonitor::build(&self.areas.table, &self.areas.axes) {
            Ok(m) => {
                self.areas.monitor = m;
                true
            }
            Err(text) => {
                self.areas.monitor = AreaMonitor::default();
                self.report(CncMessage::error(ids::AREA_AXES, text));
                false
            }
        }
    }

    /// Controller reset: areas deactivated, PLC datum cleared.
    pub(super) fn reset_areas(&mut self) {
        self.areas.table.reset();
        self.areas.violation_detected = false;
        self.areas.monitor = AreaMonitor::default();
    }

    /// Block preparation: the whole path against the active areas (FCT-C14 §2.3). Returns the
    /// error to report when the block must not run.
    pub(super) fn check_area_path(&mut self, segment: &Segment) -> Option<CncMessage> {
        if self.areas.monitor.is_empty() {
            return None;
        }
        let hit = self.areas.monitor.check_segment(segment).err()?;
        self.areas.violation_detected = true;
        let id = match hit.kind {
            HitKind::Workspace => ids::AREA_PATH_WORKSPACE,
            _ => ids::AREA_PATH_PROTECTION,
        };
        let text = format!("{}; block not executed", hit_text(&hit, &self.areas.axes));
        self.areas.refusal = Some(AreaRefusal {
            block: self.block,
            segment: segment.clone(),
            hit,
        });
        Some(CncMessage::error(id, text))
    }

    /// A block started: record its path if recording.
    pub(super) fn log_path(&mut self, segment: &Segment) {
        let block = self.block;
        if let Some(log) = self.areas.path_log.as_mut() {
            log.push((block, segment.clone()));
        }
    }
}
