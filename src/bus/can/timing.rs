//! Time on the wire of classic CAN frames (ISO 11898-1): the bit count of a concrete frame with
//! its real stuff bits, the worst-case bit count of a frame of `n` data bytes, the bit rate and
//! the arbitration order.
//!
//! # Frame format (ISO 11898-1 §10.4.2, data and remote frames)
//!
//! | field | base format (11-bit id) | extended format (29-bit id) |
//! |---|---|---|
//! | start of frame | 1 | 1 |
//! | arbitration | identifier 11, RTR 1 | base identifier 11, SRR 1, IDE 1, identifier extension 18, RTR 1 |
//! | control | IDE 1, r0 1, DLC 4 | r1 1, r0 1, DLC 4 |
//! | data | 8 n (none in a remote frame) | 8 n |
//! | CRC sequence | 15 | 15 |
//! | CRC delimiter, ACK slot, ACK delimiter | 3 | 3 |
//! | end of frame | 7 | 7 |
//! | intermission (interframe space) | 3 | 3 |
//!
//! So a base-format data frame has 44 + 8 n bits from start of frame to end of frame, 47 + 8 n
//! with the intermission that separates it from the next frame (the bus time it takes from
//! another). Bit stuffing (§10.5) covers start of frame to the end of the CRC sequence, the
//! first g + 8 n bits with g = 34 (base) or 54 (extended): after five equal bits the sender
//! inserts one of the opposite level, which itself starts the next run.
//!
//! **Worst case** ([`worst_case_bits`]): at most one stuff bit per four bits after the first,
//! ⌊(g + 8 n − 1) / 4⌋, so a frame takes at most g + 8 n + 13 + ⌊(g + 8 n − 1) / 4⌋ bit times —
//! R. I. Davis, A. Burns, R. J. Bril, J. J. Lukkien, "Controller Area Network (CAN)
//! schedulability analysis: Refuted, revisited and revised", Real-Time Systems 35 (2007), eq. (1)
//! (there τ_bit times C_m, with 13 = the unstuffed tail: CRC delimiter, ACK, EOF, intermission).
//! Base format, 8 data bytes: 47 + 64 + 24 = 135 bits (Vector's CAN e-learning, "Bit
//! Stuffing": 24 stuff bits at most, 132 bits without the intermission); 0 data bytes (SYNC):
//! 47 + 8 = 55.
//!
//! **A concrete frame** ([`frame_bits`]): the bit sequence is built (identifier, control field,
//! data, CRC-15 with the generator x¹⁵ + x¹⁴ + x¹⁰ + x⁸ + x⁷ + x⁴ + x³ + 1 = 0x4599, §10.4.2.6)
//! and its stuff bits counted, so the virtual bus gives each frame the time it really takes.

use crate::units::Nanos;

use super::CanFrame;

/// Bits from start of frame to the end of the CRC sequence without data (the stuffed part),
/// base format: SOF 1, identifier 11, RTR 1, IDE 1, r0 1, DLC 4, CRC 15.
pub const STUFFED_OVERHEAD_BASE: u32 = 34;
/// The same for the extended format: SOF 1, base identifier 11, SRR 1, IDE 1, extension 18,
/// RTR 1, r1 1, r0 1, DLC 4, CRC 15.
pub const STUFFED_OVERHEAD_EXTENDED: u32 = 54;
/// The unstuffed tail: CRC delimiter 1, ACK slot 1, ACK delimiter 1, end of frame 7,
/// intermission 3.
pub const TAIL_BITS: u32 = 13;

/// CRC-15 generator polynomial of CAN (ISO 11898-1 §10.4.2.6), without the x¹⁵ term.
const CRC15_POLY: u16 = 0x4599;

/// A bus bit rate in bit/s (positive).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Bitrate(u32);

impl Bitrate {
    /// 1 Mbit/s, the default of a machine file.
    pub const DEFAULT: Bitrate = Bitrate(1_000_000);

    /// `bps` bit/s; `None` for 0.
    pub const fn new(bps: u32) -> Option<Bitrate> {
        if bps == 0 {
            None
        } else {
            Some(Bitrate(bps))
        }
    }

    /// Bit/s.
    pub const fn bps(self) -> u32 {
        self.0
    }

    /// The time `bits` bit times take, rounded up to whole ns (exact for every CiA 301 rate:
    /// 1 µs at 1 Mbit/s, 2 µs at 500 kbit/s …).
    pub fn time_of(self, bits: u64) -> Nanos {
        let ns = u128::from(bits) * 1_000_000_000;
        let t = ns.div_ceil(u128::from(self.0));
        Nanos(u64::try_from(t).unwrap_or(u64::MAX))
    }

    /// `kbit/s` text for messages: `1000 kbit/s`, `500 kbit/s`, `33.3 kbit/s`.
    pub fn describe(self) -> String {
        if self.0.is_multiple_of(1000) {
            format!("{} kbit/s", self.0 / 1000)
        } else {
            format!("{:.1} kbit/s", f64::from(self.0) / 1000.0)
        }
    }
}

impl Default for Bitrate {
    fn default() -> Self {
        Bitrate::DEFAULT
    }
}

/// Worst-case bit times of a data frame with `data_len` bytes (clamped to 8), intermission
/// included: g + 8 n + 13 + ⌊(g + 8 n − 1) / 4⌋ (module documentation).
pub fn worst_case_bits(data_len: usize, extended: bool) -> u32 {
    let n = data_len.min(8) as u32;
    let g = if extended {
        STUFFED_OVERHEAD_EXTENDED
    } else {
        STUFFED_OVERHEAD_BASE
    };
    let stuffed = g + 8 * n;
    stuffed + TAIL_BITS + (stuffed - 1) / 4
}

/// Bit times of a data frame with `data_len` bytes without any stuff bit (intermission
/// included): 47 + 8 n base, 67 + 8 n extended.
pub fn nominal_bits(data_len: usize, extended: bool) -> u32 {
    let n = data_len.min(8) as u32;
    let g = if extended {
        STUFFED_OVERHEAD_EXTENDED
    } else {
        STUFFED_OVERHEAD_BASE
    };
    g + 8 * n + TAIL_BITS
}

/// A frame's bits as the sender puts them on the wire, counted as they come: the CRC-15 over
/// the bits before the CRC sequence, the stuff bits over everything up to its end.
#[derive(Debug, Default)]
struct Sender {
    bits: u32,
    crc: u16,
    last: Option<bool>,
    run: u32,
    stuff: u32,
}

impl Sender {
    /// One bit (`false` dominant, `true` recessive); `crc`: it is covered by the CRC.
    fn bit(&mut self, b: bool, crc: bool) {
        if crc {
            let next = b ^ (self.crc & 0x4000 != 0);
            self.crc = (self.crc << 1) & 0x7FFF;
            if next {
                self.crc ^= CRC15_POLY;
            }
        }
        self.bits += 1;
        if Some(b) == self.last {
            self.run += 1;
        } else {
            self.last = Some(b);
            self.run = 1;
        }
        if self.run == 5 {
            // The stuff bit has the other level and starts a new run of one.
            self.stuff += 1;
            self.last = Some(!b);
            self.run = 1;
        }
    }

    /// `n` bits of `value`, most significant first.
    fn field(&mut self, value: u32, n: u32, crc: bool) {
        for k in (0..n).rev() {
            self.bit((value >> k) & 1 != 0, crc);
        }
    }
}

/// CRC-15 of CAN over `bits` (ISO 11898-1 §10.4.2.6: shift register, generator 0x4599).
pub fn crc15(bits: &[bool]) -> u16 {
    let mut s = Sender::default();
    bits.iter().for_each(|&b| s.bit(b, true));
    s.crc
}

/// Stuff bits the sender inserts into `bits` (five equal bits → one of the other level, which
/// counts towards the next run).
pub fn stuff_bits(bits: &[bool]) -> u32 {
    let mut s = Sender::default();
    bits.iter().for_each(|&b| s.bit(b, false));
    s.stuff
}

/// Bit times `frame` takes on the bus: its fields with their real stuff bits plus the unstuffed
/// tail and the intermission (module documentation). An error frame (a controller's report in
/// SocketCAN, not a frame on the wire) takes 0.
pub fn frame_bits(frame: &CanFrame) -> u32 {
    if frame.error {
        return 0;
    }
    let mut s = Sender::default();
    s.field(0, 1, true); // start of frame, dominant
    if frame.extended {
        let id = frame.id & super::CAN_EFF_MASK;
        s.field(id >> 18, 11, true); // base identifier
        s.field(0b11, 2, true); // SRR, IDE: recessive
        s.field(id & 0x3_FFFF, 18, true); // identifier extension
        s.field(u32::from(frame.rtr), 1, true);
        s.field(0, 2, true); // r1, r0
    } else {
        s.field(frame.id & super::CAN_SFF_MASK, 11, true);
        s.field(u32::from(frame.rtr), 1, true);
        s.field(0, 2, true); // IDE (dominant: base format), r0
    }
    s.field(u32::from(frame.len.min(8)), 4, true);
    if !frame.rtr {
        for &b in frame.payload() {
            s.field(u32::from(b), 8, true);
        }
    }
    let crc = s.crc;
    s.field(u32::from(crc), 15, false);
    s.bits + s.stuff + TAIL_BITS
}

/// The time `frame` takes on the bus at `bitrate` ([`frame_bits`]).
pub fn wire_time(frame: &CanFrame, bitrate: Bitrate) -> Nanos {
    bitrate.time_of(u64::from(frame_bits(frame)))
}

/// The arbitration field of `frame` as one number: the frame with the smaller value wins
/// arbitration (a dominant bit, 0, overwrites a recessive one). Bits, MSB first: identifier
/// (base format) or base identifier (extended), then RTR (base) / SRR = 1 (extended), IDE,
/// identifier extension and RTR (extended only). So a lower identifier wins, and at equal base
/// identifiers a base data frame wins over a base remote frame, which wins over any extended
/// frame (ISO 11898-1 §10.4.2.2).
pub fn arbitration_key(frame: &CanFrame) -> u32 {
    if frame.extended {
        let id = frame.id & super::CAN_EFF_MASK;
        ((id >> 18) << 21) | (1 << 20) | (1 << 19) | ((id & 0x3_FFFF) << 1) | u32::from(frame.rtr)
    } else {
        ((frame.id & super::CAN_SFF_MASK) << 21) | (u32::from(frame.rtr) << 20)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worst_case_follows_the_stuffing_bound() {
        // Davis et al. (2007) eq. (1), base format: 135 bits for 8 bytes, 55 for none.
        assert_eq!(worst_case_bits(8, false), 135);
        assert_eq!(worst_case_bits(0, false), 55);
        assert_eq!(worst_case_bits(1, false), 65);
        assert_eq!(worst_case_bits(7, false), 125);
        assert_eq!(nominal_bits(8, false), 111);
        assert_eq!(nominal_bits(0, false), 47);
        // Extended format, 8 bytes: 54 + 64 + 13 + ⌊117 / 4⌋ = 160.
        assert_eq!(worst_case_bits(8, true), 160);
        assert_eq!(worst_case_bits(9, false), 135, "clamped to 8 bytes");
    }

    #[test]
    fn stuffing_counts_runs_including_the_inserted_bit() {
        assert_eq!(stuff_bits(&[false; 5]), 1);
        assert_eq!(stuff_bits(&[false; 4]), 0);
        // 00000 (1) 1111 (0): the stuff bit starts the run of ones.
        let mut v = vec![false; 5];
        v.extend([true; 4]);
        assert_eq!(stuff_bits(&v), 2);
        // 11111 (0) 11111 (0) 111: the stuff bit of the other level ends the run.
        assert_eq!(stuff_bits(&[true; 13]), 2);
        // The worst case: 00000 (1) 1111 (0) 0000 (1) 1111 (0) — one stuff bit per four bits
        // after the first, ⌊(17 − 1) / 4⌋ = 4.
        let mut w = vec![false; 5];
        for k in 0..3 {
            w.extend([k % 2 == 0; 4]);
        }
        assert_eq!(stuff_bits(&w), 4);
    }

    #[test]
    fn a_frame_takes_between_its_nominal_and_its_worst_case_bits() {
        for len in 0..=8usize {
            for fill in [0x00u8, 0xFF, 0x55, 0xAA, 0x0F, 0x3C] {
                for id in [0x000u16, 0x080, 0x181, 0x7FF, 0x555] {
                    let f = CanFrame::new(id, &vec![fill; len]).unwrap();
                    let bits = frame_bits(&f);
                    assert!(
                        (nominal_bits(len, false)..=worst_case_bits(len, false)).contains(&bits),
                        "{f:?}: {bits}"
                    );
                }
            }
        }
    }

    #[test]
    fn crc15_is_the_can_crc() {
        // The register of a single recessive bit is the generator itself.
        assert_eq!(crc15(&[true]), 0x4599);
        assert_eq!(crc15(&[false; 20]), 0);
        // Linear: crc(a xor b) = crc(a) xor crc(b) for equal lengths.
        let a: Vec<bool> = (0..40).map(|k| k % 3 == 0).collect();
        let b: Vec<bool> = (0..40).map(|k| k % 7 < 2).collect();
        let x: Vec<bool> = a.iter().zip(&b).map(|(p, q)| p ^ q).collect();
        assert_eq!(crc15(&x), crc15(&a) ^ crc15(&b));
    }

    #[test]
    fn time_at_the_cia301_rates() {
        let r = Bitrate::new(500_000).unwrap();
        assert_eq!(r.time_of(135), Nanos(270_000));
        assert_eq!(Bitrate::DEFAULT.time_of(55), Nanos(55_000));
        assert_eq!(Bitrate::new(0), None);
        assert_eq!(r.describe(), "500 kbit/s");
        assert_eq!(Bitrate::new(33_333).unwrap().describe(), "33.3 kbit/s");
    }

    #[test]
    fn lower_identifier_and_dominant_bits_win_arbitration() {
        let sync = CanFrame::new(0x080, &[]).unwrap();
        let tpdo = CanFrame::new(0x181, &[0; 8]).unwrap();
        assert!(arbitration_key(&sync) < arbitration_key(&tpdo));
        let remote = CanFrame::remote(0x181, 8).unwrap();
        assert!(arbitration_key(&tpdo) < arbitration_key(&remote));
        let ext = CanFrame::new_extended(0x181 << 18, &[]).unwrap();
        assert!(arbitration_key(&remote) < arbitration_key(&ext));
        let ext_low = CanFrame::new_extended(0x180 << 18 | 0x3_FFFF, &[]).unwrap();
        assert!(arbitration_key(&ext_low) < arbitration_key(&tpdo));
    }
}
