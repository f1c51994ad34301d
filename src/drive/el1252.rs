//! EL1252-style two-channel timestamp input: process-data codec, master-side decoder and the
//! PLC glue of `PLC_TIMESTAMP` (FCT-C4 §7.5: the terminal's input goes to the probing-signal
//! control unit, its latched timestamp "LatchPos2" to the timestamp control unit; Beckhoff
//! EL1252 documentation). The device side is [`crate::drive::model::el1252::El1252Device`].
//!
//! # Process image per channel ([`CHANNEL_LEN`] = 17 bytes, little-endian; layout assumption)
//!
//! | bytes | field |
//! |---|---|
//! | 0 | status: bit 0 rising edge seen, bit 1 falling edge seen (single-event mode only: 1 = rising, 2 = falling seen), bit 4 input level (assumption) |
//! | 1..9 | `LatchPosR` u64: DC time of the last kept rising edge, ns since 2000-01-01 |
//! | 9..17 | `LatchNegR` u64: DC time of the last kept falling edge |
//!
//! Channels follow each other (channel 1 at 0, channel 2 at 17).
//!
//! # Modes (Beckhoff EL1252 documentation)
//!
//! - **Continuous** (default): the timestamp is updated on every change — the last edge of a
//!   cycle wins; no edge flags.
//! - **Single event**: the first change after a read is kept (timestamp and flag) until the
//!   master reads it (the master acknowledges by reading; modelled as: kept until the next
//!   exchange after it was published).
//!
//! The master ([`Decoder`]) reports an edge when a timestamp differs from the one it saw
//! before (continuous), or when a flag is set (single event).

use crate::core::measure::plc::AxisPlc;
use crate::drive::{DriveError, ProbeEdge};

/// Bytes per channel.
pub const CHANNEL_LEN: usize = 17;
/// Status bit 0: rising edge seen (single-event mode).
pub const ST_RISING: u8 = 1 << 0;
/// Status bit 1: falling edge seen (single-event mode).
pub const ST_FALLING: u8 = 1 << 1;
/// Status bit 4: input level (assumption).
pub const ST_LEVEL: u8 = 1 << 4;

/// Latch mode of a channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LatchMode {
    /// Last edge wins (the terminal's default).
    #[default]
    Continuous,
    /// First edge after a read is kept until read.
    SingleEvent,
}

/// One channel's process data.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Channel {
    /// Status byte.
    pub status: u8,
    /// `LatchPosR`, ns since 2000-01-01.
    pub latch_pos: u64,
    /// `LatchNegR`, ns since 2000-01-01.
    pub latch_neg: u64,
}

impl Channel {
    /// Encode at `out[0..CHANNEL_LEN]`.
    pub fn encode(&self, out: &mut [u8]) -> Result<(), DriveError> {
        let got = out.len();
        let o = out
            .get_mut(..CHANNEL_LEN)
            .ok_or(DriveError::ImageTooShort {
                expected: CHANNEL_LEN,
                got,
            })?;
        o[0] = self.status;
        o[1..9].copy_from_slice(&self.latch_pos.to_le_bytes());
        o[9..17].copy_from_slice(&self.latch_neg.to_le_bytes());
        Ok(())
    }

    /// Decode from `b[0..CHANNEL_LEN]`.
    pub fn decode(b: &[u8]) -> Result<Self, DriveError> {
        let b = b.get(..CHANNEL_LEN).ok_or(DriveError::ImageTooShort {
            expected: CHANNEL_LEN,
            got: b.len(),
        })?;
        let u64_at = |at: usize| {
            let mut a = [0u8; 8];
            a.copy_from_slice(&b[at..at + 8]);
            u64::from_le_bytes(a)
        };
        Ok(Channel {
            status: b[0],
            latch_pos: u64_at(1),
            latch_neg: u64_at(9),
        })
    }

    /// Input level.
    pub fn level(&self) -> bool {
        self.status & ST_LEVEL != 0
    }
}

/// Encode `channels` one after the other.
pub fn encode_image(channels: &[Channel], out: &mut [u8]) -> Result<(), DriveError> {
    let need = channels.len() * CHANNEL_LEN;
    if out.len() < need {
        return Err(DriveError::ImageTooShort {
            expected: need,
            got: out.len(),
        });
    }
    for (i, c) in channels.iter().enumerate() {
        c.encode(&mut out[i * CHANNEL_LEN..])?;
    }
    Ok(())
}

/// Decode `n` channels.
pub fn decode_image(image: &[u8], n: usize) -> Result<Vec<Channel>, DriveError> {
    let need = n * CHANNEL_LEN;
    if image.len() < need {
        return Err(DriveError::ImageTooShort {
            expected: need,
            got: image.len(),
        });
    }
    (0..n)
        .map(|i| Channel::decode(&image[i * CHANNEL_LEN..]))
        .collect()
}

/// An edge decoded by the master.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Edge {
    /// Channel 1 or 2.
    pub channel: u8,
    /// Rising (true) or falling.
    pub rising: bool,
    /// DC time, ns since 2000-01-01.
    pub dc_time: i64,
}

/// Master-side decoder: turns each cycle's image into edges with DC timestamps.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decoder {
    mode: LatchMode,
    last: Vec<Option<Channel>>,
}

impl Decoder {
    /// A decoder for `channels` channels in `mode`.
    pub fn new(channels: usize, mode: LatchMode) -> Self {
        Decoder {
            mode,
            last: vec![None; channels],
        }
    }

    /// Decode one cycle's image; edges in time order. The first image is the reference (its
    /// timestamps are not edges).
    pub fn decode(&mut self, image: &[u8]) -> Result<(Vec<bool>, Vec<Edge>), DriveError> {
        let chans = decode_image(image, self.last.len())?;
        let mut levels = Vec::with_capacity(chans.len());
        let mut edges = Vec::new();
        for (i, (c, last)) in chans.iter().zip(self.last.iter_mut()).enumerate() {
            let channel = (i + 1) as u8;
            levels.push(c.level());
            let mk = |rising: bool, t: u64| Edge {
                channel,
                rising,
                dc_time: i64::try_from(t).unwrap_or(i64::MAX),
            };
            match self.mode {
                LatchMode::SingleEvent => {
                    if c.status & ST_RISING != 0 && last.is_none_or(|l| l.latch_pos != c.latch_pos)
                    {
                        edges.push(mk(true, c.latch_pos));
                    }
                    if c.status & ST_FALLING != 0 && last.is_none_or(|l| l.latch_neg != c.latch_neg)
                    {
                        edges.push(mk(false, c.latch_neg));
                    }
                }
                LatchMode::Continuous => {
                    if let Some(l) = last {
                        if l.latch_pos != c.latch_pos {
                            edges.push(mk(true, c.latch_pos));
                        }
                        if l.latch_neg != c.latch_neg {
                            edges.push(mk(false, c.latch_neg));
                        }
                    }
                }
            }
            *last = Some(*c);
        }
        edges.sort_by_key(|e| e.dc_time);
        Ok((levels, edges))
    }
}

/// PLC glue (FCT-C4 §7.5 example): the channel's input level goes to the probing-signal
/// control unit, the timestamp of the latest edge of P-AXIS-00518's kind to the timestamp
/// control unit, both by `plc_command` as a PLC program linking "Input" and "LatchPos2" would.
pub fn feed_plc(plc: &mut AxisPlc, channel: u8, level: bool, edges: &[Edge], edge: ProbeEdge) {
    let rising = edge == ProbeEdge::Positive;
    if let Some(e) = edges
        .iter()
        .rev()
        .find(|e| e.channel == channel && e.rising == rising)
    {
        plc.timestamp.plc_command(e.dc_time);
    }
    plc.probing_signal.plc_command(level);
}
