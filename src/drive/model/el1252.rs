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

    /// Stamp from now on with the DC time base on which model time `now` is DC system time
    /// `system_time` (ns since 2000; see [`DriveModel::set_dc_time`](super::DriveModel::set_dc_time)).
    pub fn set_dc_clock_at(&mut self, now: Nanos, system_time: u64) {
        let sys = i64::try_from(system_time).unwrap_or(i64::MAX);
        let now = i64::try_from(now.0).unwrap_or(i64::MAX);
        self.clock = DcClock::new(sys.saturating_sub(now));
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

    /// The hosting ESC's system time at the step's end: the edges of the step are stamped on
    /// that time base (the terminal's DC clock), not on the model's virtual time.
    fn set_dc_time(&mut self, now: Nanos, system_time: u64) {
        self.set_dc_clock_at(now, system_time);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::el1252::decode_image;

    #[test]
    fn edges_are_stamped_on_the_hosting_devices_system_time() {
        let mut d = El1252Device::new(2, LatchMode::Continuous, DcClock::default());
        // Model time 5 ms is system time 40 s + 7 ns on the hosting ESC (its SYNC0).
        let sys: u64 = 40_000_000_007;
        d.set_dc_clock_at(Nanos(5_000_000), sys);
        // An edge 300 ns before the step's end, one 1 µs after the previous SYNC0.
        d.edge(1, true, Nanos(5_000_000 - 300));
        d.edge(2, true, Nanos(4_001_000));
        let mut image = vec![0; d.image_len()];
        d.write_image(&mut image).unwrap();
        let ch = decode_image(&image, 2).unwrap();
        assert_eq!(ch[0].latch_pos, sys - 300);
        assert_eq!(ch[1].latch_pos, sys - 999_000);
    }
}
