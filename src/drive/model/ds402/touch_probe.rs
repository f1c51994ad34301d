//! Drive side of the CiA 402 touch probe function: 0x60B8 touch probe function, 0x60B9 touch
//! probe status, 0x60BA–0x60BD edge positions, 0x60D0 touch probe source, 0x60D5–0x60D8 edge
//! counters (CiA 402; ETG.6010 for the CoE drive profile).
//!
//! [`TouchProbes`] holds both probes of a drive. It knows nothing about time or motion: the model
//! hands it each edge of a signal together with the position to store
//! ([`TouchProbes::edge`]), already interpolated to the edge time.
//!
//! # Timing rules (CiA 402 0x60B8 / 0x60B9, as MOONS' timing diagram shows them)
//!
//! - 0x60B8 enable bit 0 → 1 (bit 8 for probe 2): 0x60B9 bit 0 set, both stored bits cleared.
//! - an edge-enable bit 4 / 5 going 1 → 0 clears its stored bit (1 / 2) and keeps the value;
//!   going 0 → 1 re-arms that edge (stored bit cleared).
//! - enable bit → 0: 0x60B9 bits 0–2 cleared, values kept.
//! - first event (bit 1 = 0): only the first matching edge after arming is stored; later edges
//!   are ignored until re-armed.
//! - continuous (bit 1 = 1): every matching edge overwrites the value, sets the stored bit, flips
//!   the per-edge toggle bit — 0x60B9 bit 6 positive / bit 7 negative (14 / 15 for probe 2),
//!   **vendor-specific, as Yaskawa Σ-X** — and increments the edge counter.
//! - the edge counters 0x60D5 (TP1 positive), 0x60D6 (TP1 negative), 0x60D7 (TP2 positive),
//!   0x60D8 (TP2 negative) count every stored edge in both modes, free-running and wrapping
//!   (`UNSIGNED16`); they are not reset by arming.
//!
//! # Trigger source (0x60B8 bits 3,2 / 11,10)
//!
//! 00b: the probe's own digital input (probe 1 ← input 1, probe 2 ← input 2); 01b: the zero
//! pulse of the position encoder; 10b: 0x60D0 sub 1 / sub 2 with the Beckhoff AX8000
//! enumeration: 1–4 = digital input 1–4, 5 = hardware zero impulse, 6 = software zero impulse
//! (both are the model's encoder zero pulse); any other value and 11b (reserved) latch nothing.
//!
//! # `rearm_requires_zero` (drive file `[probe]`)
//!
//! Plays a drive that must see 0x60B8 = 0 before it re-arms: it applies a new configuration of
//! a probe only on the 0 → 1 transition of the enable bit and ignores every other change of the
//! probe's byte while the enable bit stays set; in first-event mode it ends the single shot after
//! the latch by clearing 0x60B9 bit 0 (stored bit and value stay). Writing the same word again
//! therefore never re-arms it.

/// Digital inputs of the model (1..=`NUM_INPUTS`; AX8000 has touch probe inputs 1–4).
pub const NUM_INPUTS: u8 = 4;

/// 0x60B8 per-probe byte: enable.
const FN_ENABLE: u8 = 0x01;
/// 0x60B8 per-probe byte: continuous.
const FN_CONTINUOUS: u8 = 0x02;
/// 0x60B8 per-probe byte: sample positive edge.
const FN_POS: u8 = 0x10;
/// 0x60B8 per-probe byte: sample negative edge.
const FN_NEG: u8 = 0x20;

/// 0x60B9 per-probe byte: probe enabled.
const ST_ENABLED: u16 = 0x01;
/// 0x60B9 per-probe byte: positive edge value stored.
const ST_POS: u16 = 0x02;
/// 0x60B9 per-probe byte: negative edge value stored.
const ST_NEG: u16 = 0x04;
/// 0x60B9 per-probe byte: positive edge toggle (vendor-specific, Yaskawa Σ-X).
const ST_POS_TOGGLE: u16 = 0x40;
/// 0x60B9 per-probe byte: negative edge toggle (vendor-specific, Yaskawa Σ-X).
const ST_NEG_TOGGLE: u16 = 0x80;

/// A signal a touch probe can be triggered by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// Digital input 1..=[`NUM_INPUTS`].
    Input(u8),
    /// Zero pulse (index) of the position encoder.
    ZeroPulse,
}

/// Both touch probes of a drive (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TouchProbes {
    /// 0x60B8 as last written.
    written: u16,
    /// Configuration in effect per probe (differs from `written` only with `rearm_requires_zero`).
    applied: [u8; 2],
    /// 0x60B9.
    status: u16,
    /// 0x60BA, 0x60BB, 0x60BC, 0x60BD.
    values: [i32; 4],
    /// 0x60D5, 0x60D6, 0x60D7, 0x60D8.
    counters: [u16; 4],
    /// 0x60D0 sub 1, sub 2.
    source: [i16; 2],
    rearm_requires_zero: bool,
}

impl TouchProbes {
    /// Both probes off, 0x60D0 = {1, 2} (each probe on its own input).
    pub fn new(rearm_requires_zero: bool) -> Self {
        TouchProbes {
            written: 0,
            applied: [0; 2],
            status: 0,
            values: [0; 4],
            counters: [0; 4],
            source: [1, 2],
            rearm_requires_zero,
        }
    }

    /// 0x60B8 as last written.
    pub fn function(&self) -> u16 {
        self.written
    }

    /// 0x60B9.
    pub fn status(&self) -> u16 {
        self.status
    }

    /// 0x60BA + `i` (0 = TP1 positive … 3 = TP2 negative).
    pub fn value(&self, i: usize) -> Option<i32> {
        self.values.get(i).copied()
    }

    /// 0x60D5 + `i` (0 = TP1 positive … 3 = TP2 negative).
    pub fn counter(&self, i: usize) -> Option<u16> {
        self.counters.get(i).copied()
    }

    /// 0x60D0 sub `1` / `2`.
    pub fn source(&self, sub: u8) -> Option<i16> {
        self.source.get(usize::from(sub).checked_sub(1)?).copied()
    }

    /// Write 0x60D0 sub `1` / `2`; takes effect at the next edge.
    pub fn set_source(&mut self, sub: u8, value: i16) {
        if let Some(s) = usize::from(sub)
            .checked_sub(1)
            .and_then(|i| self.source.get_mut(i))
        {
            *s = value;
        }
    }

    /// Write 0x60B8 and apply the timing rules to each probe's byte.
    pub fn write_function(&mut self, word: u16) {
        self.written = word;
        for p in 0..2 {
            self.apply(p, (word >> (8 * p)) as u8);
        }
    }

    fn apply(&mut self, p: usize, new: u8) {
        let shift = 8 * p;
        let old = self.applied[p];
        let (old_en, new_en) = (old & FN_ENABLE != 0, new & FN_ENABLE != 0);
        if !new_en {
            self.applied[p] = new;
            self.status &= !((ST_ENABLED | ST_POS | ST_NEG) << shift);
        } else if !old_en {
            self.applied[p] = new;
            self.status |= ST_ENABLED << shift;
            self.status &= !((ST_POS | ST_NEG) << shift);
        } else if !self.rearm_requires_zero {
            self.applied[p] = new;
            for (edge, stored) in [(FN_POS, ST_POS), (FN_NEG, ST_NEG)] {
                if (old ^ new) & edge != 0 {
                    // Switched off: the stored bit goes, the value stays. Switched on: re-armed.
                    self.status &= !(stored << shift);
                }
            }
        }
    }

    /// The signal probe `p` (0 / 1) listens to now, `None` for a reserved or unknown source.
    fn signal_of(&self, p: usize) -> Option<Signal> {
        match (self.applied[p] >> 2) & 0x03 {
            0b00 => Some(Signal::Input(p as u8 + 1)),
            0b01 => Some(Signal::ZeroPulse),
            0b10 => match self.source[p] {
                v @ 1..=4 => Some(Signal::Input(v as u8)),
                5 | 6 => Some(Signal::ZeroPulse),
                _ => None,
            },
            _ => None,
        }
    }

    /// Whether an enabled probe listens to `signal` (lets the model skip zero-pulse search).
    pub fn listens(&self, signal: Signal) -> bool {
        (0..2).any(|p| {
            self.status & (ST_ENABLED << (8 * p)) != 0 && self.signal_of(p) == Some(signal)
        })
    }

    /// An edge of `signal` (`rising` = positive edge); `position` is the position at the edge
    /// time (0x6064 units). Every enabled probe listening to the signal and sampling that edge
    /// stores it per the timing rules.
    pub fn edge(&mut self, signal: Signal, rising: bool, position: i32) {
        for p in 0..2 {
            let shift = 8 * p;
            if self.status & (ST_ENABLED << shift) == 0 || self.signal_of(p) != Some(signal) {
                continue;
            }
            let f = self.applied[p];
            let (sample, stored, toggle, i) = if rising {
                (FN_POS, ST_POS, ST_POS_TOGGLE, 2 * p)
            } else {
                (FN_NEG, ST_NEG, ST_NEG_TOGGLE, 2 * p + 1)
            };
            if f & sample == 0 {
                continue;
            }
            if f & FN_CONTINUOUS != 0 {
                self.values[i] = position;
                self.status |= stored << shift;
                self.status ^= toggle << shift;
                self.counters[i] = self.counters[i].wrapping_add(1);
            } else if self.status & (stored << shift) == 0 {
                self.values[i] = position;
                self.status |= stored << shift;
                self.counters[i] = self.counters[i].wrapping_add(1);
                if self.rearm_requires_zero {
                    // The single shot is over; only 0 -> 1 of the enable bit re-arms.
                    self.status &= !(ST_ENABLED << shift);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn timing_rules() {
        let mut tp = TouchProbes::new(false);
        tp.edge(Signal::Input(1), true, 5);
        assert_eq!(
            (tp.status(), tp.value(0)),
            (0, Some(0)),
            "disabled: nothing"
        );
        tp.write_function(0x0011); // TP1 on, first event, input 1, positive edge
        assert_eq!(tp.status(), 0x0001);
        tp.edge(Signal::Input(2), true, 7);
        tp.edge(Signal::Input(1), false, 8);
        assert_eq!(tp.status(), 0x0001, "other input / other edge");
        tp.edge(Signal::Input(1), true, 9);
        tp.edge(Signal::Input(1), true, 10);
        assert_eq!(
            (tp.status(), tp.value(0), tp.counter(0)),
            (0x0003, Some(9), Some(1))
        );
        tp.write_function(0x0001); // positive edge off: stored bit goes, value stays
        assert_eq!((tp.status(), tp.value(0)), (0x0001, Some(9)));
        tp.write_function(0x0011); // re-armed
        tp.edge(Signal::Input(1), true, 11);
        assert_eq!((tp.status(), tp.value(0)), (0x0003, Some(11)));
        tp.write_function(0x0000);
        assert_eq!((tp.status(), tp.value(0)), (0x0000, Some(11)));
        // Continuous, both edges, toggles and counters.
        tp.write_function(0x0033);
        for (k, rising) in [true, false, true].into_iter().enumerate() {
            tp.edge(Signal::Input(1), rising, 20 + k as i32);
        }
        assert_eq!(tp.status(), 0x0007 | 0x0080);
        assert_eq!((tp.value(0), tp.value(1)), (Some(22), Some(21)));
        assert_eq!((tp.counter(0), tp.counter(1)), (Some(4), Some(1)));
    }

    #[test]
    fn sources_and_probe_2() {
        let mut tp = TouchProbes::new(false);
        tp.write_function(0x2900); // TP2: first event, 0x60D0:2, negative edge
        tp.set_source(2, 1);
        tp.edge(Signal::Input(2), false, 1);
        assert_eq!(tp.status(), 0x0100);
        tp.edge(Signal::Input(1), false, 2);
        assert_eq!((tp.status(), tp.value(3)), (0x0500, Some(2)));
        tp.set_source(2, 5);
        assert!(tp.listens(Signal::ZeroPulse));
        tp.set_source(2, -1);
        assert!(!tp.listens(Signal::ZeroPulse) && !tp.listens(Signal::Input(1)));
        tp.write_function(0x0007); // TP1 zero pulse, continuous, no edge sampled
        assert!(tp.listens(Signal::ZeroPulse));
        tp.edge(Signal::ZeroPulse, true, 3);
        assert_eq!(tp.status() & 0x00FF, 0x0001);
        tp.write_function(0x000D); // reserved source 11b
        assert!(!tp.listens(Signal::ZeroPulse) && !tp.listens(Signal::Input(1)));
        assert_eq!((tp.source(0), tp.source(3)), (None, None));
    }

    #[test]
    fn rearm_requires_zero_quirk() {
        let mut tp = TouchProbes::new(true);
        tp.write_function(0x0011);
        tp.edge(Signal::Input(1), true, 5);
        // Single shot over: disabled in 0x60B9, value stored.
        assert_eq!((tp.status(), tp.value(0)), (0x0002, Some(5)));
        tp.write_function(0x0011);
        tp.write_function(0x0021);
        assert_eq!(
            tp.status(),
            0x0002,
            "same or changed word while enabled: ignored"
        );
        tp.edge(Signal::Input(1), true, 6);
        assert_eq!(tp.value(0), Some(5));
        tp.write_function(0x0000);
        tp.write_function(0x0021);
        assert_eq!(
            tp.status(),
            0x0001,
            "0 -> 1 re-arms with the new configuration"
        );
        tp.edge(Signal::Input(1), false, 7);
        assert_eq!((tp.status(), tp.value(1)), (0x0004, Some(7)));
    }
}
