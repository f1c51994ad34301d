//! EL1252-style timestamp terminal, device side: observes input edges with their times, stamps
//! them with the DC clock and writes the process image of
//! [`crate::drive::el1252`] (notes cnc.md §4.3; seed 004 §7.5).

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
        }
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
        let t = u64::try_from(self.clock.dc_time(at)).unwrap_or(0);
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
