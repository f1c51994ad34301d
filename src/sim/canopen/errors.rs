//! The emulated node's error state (CiA 301 §7.2.7 EMCY, §7.5.2.2 error register 0x1001,
//! §7.5.2.3 pre-defined error field 0x1003).
//!
//! The node tells [`NodeErrors::update`] which error codes are active now (a CiA 402 drive
//! fault with its 0x603F code, a SYNC or RPDO time-out, a PDO length error, a refused NMT
//! start); [`NodeErrors`] answers with the EMCY frames to send:
//! * an error that became active: EMCY with its code and the error register as it is now
//!   (the new error included), and the error goes to the top of 0x1003 (sub-index 1 = newest);
//! * an error that is gone (e.g. the drive fault after a fault reset by controlword bit 7):
//!   EMCY 0x0000 "error reset or no error" with the error register as it is now (0x00 when no
//!   error is left) — the EMCY state machine of CiA 301 §7.2.7.1, which python-canopen's EMCY
//!   consumer follows (`node.emcy.active` is emptied by a code 0x0000).
//!
//! Error register bits (CiA 301 §7.5.2.2): bit 0 generic (set while any error is active),
//! 1 current, 2 voltage, 3 temperature, 4 communication error, 5 device profile specific,
//! 6 reserved (0), 7 manufacturer specific. Which bit an error code sets besides bit 0 is read
//! from its class (CiA 301 table 21 "emergency error codes"): 0x2xxx current, 0x3xxx voltage,
//! 0x4xxx temperature, 0x81xx communication and 0x82xx protocol error (CANopenNode files both
//! under the communication bit), 0x83xx … 0x8Fxx the monitoring codes CiA 402 defines for a
//! drive (0x8311 torque, 0x84xx velocity, 0x85xx position, 0x8611 following error …) device
//! profile specific, 0xFFxx device (manufacturer) specific; every other class only bit 0.
//! The mapping of the CiA 402 monitoring codes to bit 5 is our reading: CiA 301 names the bit,
//! not the codes.
//!
//! 0x1003 entries are UNSIGNED32: error code in bits 0 … 15, manufacturer-specific additional
//! information in bits 16 … 31 (0 here: the node sends 5 zero manufacturer bytes too). The
//! field holds at most its capacity (sub-indices 1 … n); an older entry falls off the end.

/// Error register bit 0: generic error.
pub const GENERIC: u8 = 0x01;
/// Error register bit 1: current.
pub const CURRENT: u8 = 0x02;
/// Error register bit 2: voltage.
pub const VOLTAGE: u8 = 0x04;
/// Error register bit 3: temperature.
pub const TEMPERATURE: u8 = 0x08;
/// Error register bit 4: communication error (overrun, error state).
pub const COMMUNICATION: u8 = 0x10;
/// Error register bit 5: device profile specific.
pub const DEVICE_PROFILE: u8 = 0x20;
/// Error register bit 7: manufacturer specific.
pub const MANUFACTURER: u8 = 0x80;

/// EMCY error code 0x0000 "error reset or no error".
pub const ERROR_RESET: u16 = 0x0000;

/// Capacity of the built-in node's pre-defined error field 0x1003 (sub-indices 1 … 8).
pub const DEFAULT_HISTORY: u8 = 8;

/// The error register bits (0x1001) an active error with `code` sets: generic plus the bit of
/// its class (module documentation). Code 0 sets none.
pub fn register_bits(code: u16) -> u8 {
    let class = match code >> 12 {
        0x0 if code == 0 => return 0,
        0x2 => CURRENT,
        0x3 => VOLTAGE,
        0x4 => TEMPERATURE,
        0x8 => match code >> 8 {
            0x81 | 0x82 => COMMUNICATION,
            0x83..=0x8F => DEVICE_PROFILE,
            _ => 0,
        },
        0xF if code >> 8 == 0xFF => MANUFACTURER,
        _ => 0,
    };
    GENERIC | class
}

/// Active errors and the error history of one node (module documentation).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct NodeErrors {
    /// Codes active at the last [`Self::update`], in the order they became active.
    active: Vec<u16>,
    /// 0x1003 sub-index 1 … n: newest first.
    history: Vec<u32>,
    /// Capacity of 0x1003 (0: the node has no 0x1003).
    capacity: usize,
}

impl NodeErrors {
    /// No error active, empty history of `capacity` entries (0 = no 0x1003).
    pub fn new(capacity: u8) -> Self {
        NodeErrors {
            active: Vec::new(),
            history: Vec::new(),
            capacity: usize::from(capacity),
        }
    }

    /// The error register 0x1001 now: the bits of every active error.
    pub fn register(&self) -> u8 {
        self.active.iter().fold(0, |r, &c| r | register_bits(c))
    }

    /// The codes active now, oldest first.
    pub fn active(&self) -> &[u16] {
        &self.active
    }

    /// 0x1003 sub-index 1 … n (newest first).
    pub fn history(&self) -> &[u32] {
        &self.history
    }

    /// Capacity of 0x1003 (0: none).
    pub fn capacity(&self) -> u8 {
        self.capacity.min(254) as u8
    }

    /// Writing 0 to 0x1003 sub-index 0: the history is deleted (the active errors stay).
    pub fn clear_history(&mut self) {
        self.history.clear();
    }

    /// The errors active now are `now` (codes ≠ 0; duplicates count once): returns the EMCYs
    /// to send, as (error code, error register), in order — first an error reset for errors
    /// that are gone, then one EMCY per new error. Nothing when nothing changed.
    pub fn update(&mut self, now: &[u16]) -> Vec<(u16, u8)> {
        let mut out = Vec::new();
        let before = self.active.len();
        self.active.retain(|c| now.contains(c));
        if self.active.len() != before {
            out.push((ERROR_RESET, self.register()));
        }
        for &code in now {
            if code == 0 || self.active.contains(&code) {
                continue;
            }
            self.active.push(code);
            if self.capacity > 0 {
                self.history.insert(0, u32::from(code));
                self.history.truncate(self.capacity);
            }
            out.push((code, self.register()));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn register_bits_follow_the_code_class() {
        // (code, bits) from CiA 301 §7.5.2.2 and table 21, written out by hand.
        for (code, bits) in [
            (0x0000, 0x00),
            (0x1000, 0x01),
            (0x2310, 0x03),
            (0x3210, 0x05),
            (0x4210, 0x09),
            (0x5530, 0x01),
            (0x8100, 0x11),
            (0x8210, 0x11),
            (0x8250, 0x11),
            (0x8611, 0x21),
            (0xFF01, 0x81),
        ] {
            assert_eq!(register_bits(code), bits, "{code:#06x}");
        }
    }

    #[test]
    fn a_fault_then_its_reset_is_two_emcys_and_one_history_entry() {
        let mut e = NodeErrors::new(2);
        assert!(e.update(&[]).is_empty());
        assert_eq!(e.update(&[0x8611]), vec![(0x8611, 0x21)]);
        assert!(
            e.update(&[0x8611]).is_empty(),
            "still active: no second EMCY"
        );
        assert_eq!(e.register(), 0x21);
        // A communication error on top: register 0x31; then the drive fault goes.
        assert_eq!(e.update(&[0x8611, 0x8100]), vec![(0x8100, 0x31)]);
        assert_eq!(e.update(&[0x8100]), vec![(0x0000, 0x11)]);
        assert_eq!(e.update(&[]), vec![(0x0000, 0x00)]);
        assert_eq!(e.history(), &[0x8100, 0x8611]);
        // Capacity 2: the oldest falls off.
        e.update(&[0x3210]);
        assert_eq!(e.history(), &[0x3210, 0x8100]);
        e.clear_history();
        assert!(e.history().is_empty());
        assert_eq!(
            e.active(),
            &[0x3210],
            "clearing the history keeps the active errors"
        );
    }

    #[test]
    fn no_history_without_0x1003() {
        let mut e = NodeErrors::new(0);
        assert_eq!(e.update(&[0x8611]), vec![(0x8611, 0x21)]);
        assert!(e.history().is_empty());
    }
}
