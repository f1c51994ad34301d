//! The SYNC0 output of an ESC's distributed-clocks cyclic unit: at which instants of the
//! device's DC system time a SYNC0 pulse comes (Beckhoff ESC datasheet section II, registers
//! 0x0980–0x09A7; the bit meanings as in the EtherCAT IP core register description).
//!
//! * 0x0981 SYNC activation: bit 0 cyclic unit (sync out unit) on, bit 1 SYNC0 generation,
//!   bit 2 SYNC1, bit 3 auto-activation by writing 0x0990, bit 4 extend a 32-bit start time to
//!   64 bit, bit 5 start time plausibility check, bit 6 near-future configuration (0: half the
//!   DC width, 2^63 ns with a 64-bit system time; 1: about 2.1 s, 2^31 ns).
//! * 0x0990 start time of cyclic operation (system time, ns); read back it is the system time of
//!   the next SYNC0 pulse.
//! * 0x09A0 SYNC0 cycle time (ns); 0 = single shot (one pulse).
//! * 0x0984 activation status: bit 0 first SYNC0 pulse pending, bit 2 the start time was outside
//!   the near future when the unit was activated.
//!
//! Writing 0x0981 with bits 0 and 1 set takes the start time and cycle time written before. A
//! start time in the near future gives the first pulse at the start time, then one every cycle
//! ([`Activation::Scheduled`]). Without the plausibility check the ESC generates SYNC0 "if the
//! start time is reached": a start time in the past is reached again only when the 64-bit
//! system time wraps around, i.e. never, so the unit stays armed and gives no SYNC0
//! ([`Activation::StartMissed`]) — which is why masters write a start time well ahead (SOEM
//! and the IgH master 100 ms after the system time they read). With the check (bit 5)
//! the pulses start at once: first pulse at the activation, then every cycle
//! ([`Activation::Immediate`]). Clearing bit 0 or bit 1 stops the pulses.
//!
//! The emulated drives cannot follow a SYNC0 faster than [`MIN_SYNC0_CYCLE_NS`]: a shorter cycle
//! time is refused like a drive's application refuses it (no pulses,
//! [`Activation::CycleTooShort`]). Sans-IO: every time is an argument.

/// Shortest SYNC0 cycle time the emulated devices run (50 µs; real servo drives need 62.5 µs
/// or more).
pub const MIN_SYNC0_CYCLE_NS: u64 = 50_000;

/// 0x0981 bits.
const ACT_CYCLIC: u8 = 0x01;
const ACT_SYNC0: u8 = 0x02;
const ACT_PLAUSIBILITY: u8 = 0x20;
const ACT_NEAR_FUTURE_2S: u8 = 0x40;

/// What writing 0x0981 did to SYNC0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Activation {
    /// SYNC0 off (bit 0 or bit 1 clear).
    Off,
    /// First pulse at `first` (system time, the start time), then every `cycle` ns (0: once).
    Scheduled {
        /// System time of the first pulse.
        first: u64,
        /// Cycle time, ns (0 = single shot).
        cycle: u64,
    },
    /// The start time was outside the near future and the plausibility check is on: the first
    /// pulse comes at once (`first` = the system time of the activation), then every `cycle`.
    Immediate {
        /// System time of the first pulse.
        first: u64,
        /// Cycle time, ns (0 = single shot).
        cycle: u64,
    },
    /// The start time lay `late_ns` in the past and the plausibility check is off: no pulse.
    StartMissed {
        /// The start time written to 0x0990.
        start: u64,
        /// How far it lay in the past at the activation, ns.
        late_ns: u64,
    },
    /// The cycle time is shorter than [`MIN_SYNC0_CYCLE_NS`] (and not 0): no pulse.
    CycleTooShort {
        /// The cycle time written to 0x09A0, ns.
        cycle: u64,
    },
}

/// SYNC0 state of one ESC (see the module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Sync0Unit {
    next: Option<u64>,
    cycle: u64,
    pulses: u64,
}

impl Sync0Unit {
    /// The unit was (re)configured by a write of `activation` to 0x0981, with `start` in 0x0990,
    /// `cycle` in 0x09A0 and the device's system time `sys_now`.
    pub fn activate(&mut self, activation: u8, start: u64, cycle: u32, sys_now: u64) -> Activation {
        self.next = None;
        self.cycle = 0;
        self.pulses = 0;
        if activation & (ACT_CYCLIC | ACT_SYNC0) != ACT_CYCLIC | ACT_SYNC0 {
            return Activation::Off;
        }
        let cycle = u64::from(cycle);
        if cycle != 0 && cycle < MIN_SYNC0_CYCLE_NS {
            return Activation::CycleTooShort { cycle };
        }
        let near_future: u64 = if activation & ACT_NEAR_FUTURE_2S != 0 {
            1 << 31
        } else {
            1 << 63
        };
        let ahead = start.wrapping_sub(sys_now);
        let (first, result) = if ahead < near_future {
            (
                start,
                Activation::Scheduled {
                    first: start,
                    cycle,
                },
            )
        } else if activation & ACT_PLAUSIBILITY != 0 {
            (
                sys_now,
                Activation::Immediate {
                    first: sys_now,
                    cycle,
                },
            )
        } else {
            return Activation::StartMissed {
                start,
                late_ns: sys_now.wrapping_sub(start),
            };
        };
        self.next = Some(first);
        self.cycle = cycle;
        result
    }

    /// Stop the pulses (the cyclic unit was switched off).
    pub fn stop(&mut self) {
        self.next = None;
    }

    /// System time of the next pulse, if one is scheduled.
    pub fn next_pulse(&self) -> Option<u64> {
        self.next
    }

    /// Cycle time of the running schedule, ns (0 = single shot or off).
    pub fn cycle(&self) -> u64 {
        self.cycle
    }

    /// Pulses generated since the activation.
    pub fn pulses(&self) -> u64 {
        self.pulses
    }

    /// Generate the next pulse: returns its system time and schedules the one after it (none
    /// after a single shot).
    pub fn fire(&mut self) -> Option<u64> {
        let t = self.next?;
        self.pulses += 1;
        self.next = (self.cycle != 0).then(|| t.wrapping_add(self.cycle));
        Some(t)
    }

    /// Drop every pulse that lies more than `keep` cycles before `sys_now` (without generating
    /// them); returns how many were dropped. Used when the emulator itself fell behind.
    pub fn skip_overdue(&mut self, sys_now: u64, keep: u64) -> u64 {
        let (Some(next), cycle) = (self.next, self.cycle) else {
            return 0;
        };
        if cycle == 0 {
            return 0;
        }
        let late = sys_now.wrapping_sub(next);
        if late >= 1 << 63 {
            return 0; // next pulse in the future
        }
        let overdue = late / cycle + 1;
        if overdue <= keep {
            return 0;
        }
        let skip = overdue - keep;
        self.next = Some(next.wrapping_add(skip.saturating_mul(cycle)));
        skip
    }

    /// The first pulse since the activation is still pending.
    pub fn first_pending(&self) -> bool {
        self.next.is_some() && self.pulses == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn future_start_gives_pulses_at_start_plus_k_cycles() {
        let mut u = Sync0Unit::default();
        let a = u.activate(0x03, 3_000_000, 1_000_000, 2_400_000);
        assert_eq!(
            a,
            Activation::Scheduled {
                first: 3_000_000,
                cycle: 1_000_000
            }
        );
        assert!(u.first_pending());
        let got: Vec<u64> = (0..3).filter_map(|_| u.fire()).collect();
        assert_eq!(got, [3_000_000, 4_000_000, 5_000_000]);
        assert_eq!(u.pulses(), 3);
        assert!(!u.first_pending());
    }

    #[test]
    fn past_start_without_check_generates_nothing() {
        let mut u = Sync0Unit::default();
        let a = u.activate(0x03, 1_000_000, 1_000_000, 1_250_000);
        assert_eq!(
            a,
            Activation::StartMissed {
                start: 1_000_000,
                late_ns: 250_000
            }
        );
        assert_eq!(u.next_pulse(), None);
        assert_eq!(u.fire(), None);
    }

    #[test]
    fn past_start_with_plausibility_check_starts_at_once() {
        let mut u = Sync0Unit::default();
        let a = u.activate(0x23, 1_000_000, 1_000_000, 1_250_000);
        assert_eq!(
            a,
            Activation::Immediate {
                first: 1_250_000,
                cycle: 1_000_000
            }
        );
        assert_eq!(u.fire(), Some(1_250_000));
        assert_eq!(u.fire(), Some(2_250_000));
        // Near future of about 2.1 s (bit 6): a start 3 s ahead counts as outside.
        let a = u.activate(0x63, 3_000_000_000, 1_000_000, 0);
        assert_eq!(
            a,
            Activation::Immediate {
                first: 0,
                cycle: 1_000_000
            }
        );
    }

    #[test]
    fn off_single_shot_and_short_cycles() {
        let mut u = Sync0Unit::default();
        assert_eq!(u.activate(0x01, 10, 1_000_000, 0), Activation::Off);
        assert_eq!(u.activate(0x02, 10, 1_000_000, 0), Activation::Off);
        assert_eq!(
            u.activate(0x03, 10, 1_000, 0),
            Activation::CycleTooShort { cycle: 1_000 }
        );
        assert_eq!(u.next_pulse(), None);
        u.activate(0x03, 10, 0, 0);
        assert_eq!(u.fire(), Some(10));
        assert_eq!(u.fire(), None);
    }

    #[test]
    fn skip_overdue_keeps_the_latest_pulses() {
        let mut u = Sync0Unit::default();
        u.activate(0x03, 1_000, 100_000, 0);
        // At 1_000 + 10 cycles + a bit, 11 pulses are due; keep 2.
        assert_eq!(u.skip_overdue(1_000 + 1_000_000 + 5, 2), 9);
        assert_eq!(u.fire(), Some(1_000 + 900_000));
        assert_eq!(u.fire(), Some(1_000 + 1_000_000));
        assert_eq!(u.skip_overdue(1_000 + 1_000_000 + 5, 2), 0);
    }
}
