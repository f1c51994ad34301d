//! EL1252-style timestamp terminal, device side: observes input edges with their times, stamps
//! them with the DC clock and writes the process image of
//! [`crate::drive::el1252`] (Beckhoff EL1252 documentation; FCT-C4 §7.5).

use crate::core::measure::timestamp::DcClock;
use crate::drive::el1252::{encode_image, Channel, LatchMode, ST_FALLING, ST_LEVEL, ST_RISING};
use crate::drive::DriveError;
use crate::units::Nanos;

/// The device model of a one- or two-channel timestamp terminal.
#[derive(Debug, Clone, PartialEq)]
pub struct El1252Device {
    clock: DcClock,
    mode: LatchMode,
    channels: Vec<Channel>,
    /// Single-event: an edge of this kind is kept until read.
    kept: Vec<(bool, bool)>,
    /// Added to every timestamp (ns; [`Self::set_stamp_offset_ns`]).
    stamp_offset_ns: i64,
}

impl El1252Device {
    /// `channels` channels (1 or 2; others are clamped), all in `mode`.
    pub fn new(channels: usize, mode: LatchMode, clock: DcClock) -> Self {
        let n = channels.clamp(1, 2);
        El1252Device {
            clock,
            mode,
            channels: vec![Channel::default(); n],
            kept: vec![(false, false); n],
            stamp_offset_ns: 0,
        }
    }

    /// Fault knob: stamp every edge `offset_ns` later than it happened (negative: earlier), as
    /// a terminal with a wrong dead time would — so a test can tell that a measured value
    /// follows this terminal's timestamps. 0 by default (the EL1252 stamps within 1 µs).
    pub fn set_stamp_offset_ns(&mut self, offset_ns: i64) {
        self.stamp_offset_ns = offset_ns;
    }

    /// Bytes of the process image.
    pub fn image_len(&self) -> usize {
        self.channels.len() * crate::drive::el1252::CHANNEL_LEN
    }

    /// An input edge on `channel` (1-based) at virtual time `at`; unknown channels are ignored.
    pub fn edge(&mut self, channel: u8, rising: bool, at: Nanos) {
        let Some(i) = usize::from(channel).checked_sub(1) else {
            return;
        };
        let (Some(c), Some(k)) = (self.channels.get_mut(i), self.kept.get_mut(i)) else {
            return;
        };
        let t =
            u64::try_from(self.clock.dc_time(at).saturating_add(self.stamp_offset_ns)).unwrap_or(0);
        if rising {
            c.status |= ST_LEVEL;
        } else {
            c.status &= !ST_LEVEL;
        }
        match self.mode {
            LatchMode::Continuous => {
                if rising {
                    c.latch_pos = t;
                } else {
                    c.latch_neg = t;
                }
            }
            LatchMode::SingleEvent => {
                if rising && !k.0 {
                    k.0 = true;
                    c.latch_pos = t;
                    c.status |= ST_RISING;
                } else if !rising && !k.1 {
                    k.1 = true;
                    c.latch_neg = t;
                    c.status |= ST_FALLING;
                }
            }
        }
    }

    /// Write the image; in single-event mode the kept events count as read afterwards (flags
    /// cleared for the next cycle, timestamps stay).
    pub fn write_image(&mut self, out: &mut [u8]) -> Result<(), DriveError> {
        encode_image(&self.channels, out)?;
        if self.mode == LatchMode::SingleEvent {
            for (c, k) in self.channels.iter_mut().zip(self.kept.iter_mut()) {
                c.status &= !(ST_RISING | ST_FALLING);
                *k = (false, false);
            }
        }
        Ok(())
    }
}

/// The terminal as a device of the simulated world (an EtherCAT SubDevice hosting it, a probe
/// surface wired to its channels): no outputs, the timestamp image as inputs, input edges
/// stamped; it has no axis, so no trajectory, position, stop or objects.
impl super::DriveModel for El1252Device {
    fn rx_len(&self) -> usize {
        0
    }

    fn tx_len(&self) -> usize {
        self.image_len()
    }

    fn begin_step(&mut self, _now: Nanos, _dt_s: f64, _rx: &[u8]) {}

    fn input_edge(&mut self, input: u8, rising: bool, at: Nanos) {
        self.edge(input, rising, at);
    }

    fn finish_step(&mut self, tx: &mut [u8]) {
        // The image always fits `tx_len` bytes; a shorter buffer keeps its old content.
        let _ = self.write_image(tx);
    }

    fn set_input_level(&mut self, input: u8, level: bool) {
        if let Some(c) = usize::from(input)
            .checked_sub(1)
            .and_then(|i| self.channels.get_mut(i))
        {
            if level {
                c.status |= ST_LEVEL;
            } else {
                c.status &= !ST_LEVEL;
            }
        }
    }

    fn input_level(&self, input: u8) -> Option<bool> {
        let c = self.channels.get(usize::from(input).checked_sub(1)?)?;
        Some(c.status & ST_LEVEL != 0)
    }

    fn state(&self) -> super::PowerState {
        super::PowerState::OperationEnabled
    }

    fn last_error_code(&self) -> u16 {
        0
    }

    fn inject_fault(&mut self, _code: u16) {}

    fn read_object(&self, _index: u16, _sub: u8) -> Result<i64, u32> {
        Err(super::abort::NO_OBJECT)
    }

    fn write_object(&mut self, _index: u16, _sub: u8, _value: i64) -> Result<(), u32> {
        Err(super::abort::NO_OBJECT)
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn std::any::Any {
        self
    }
}
