//! The time-driven side of an [`Esc`]: SYNC0 of the DC cyclic unit ([`super::dc`]) and the
//! sync-manager (process-data) watchdog, and the [`EscEvent`]s that report them. Sans-IO: the
//! caller passes its clock's `now`, asks for the next deadline ([`Esc::sync0_due_at`],
//! [`Esc::watchdog_deadline`]) and calls back then ([`Esc::fire_sync0`], [`Esc::tick`]); the
//! segment does this for all its devices ([`super::segment::Stepping::OwnClock`]).
//!
//! Watchdog (Beckhoff ESC datasheet section I "Watchdogs"; ETG register defaults): 0x0400
//! divider (default 0x09C2: (2498 + 2) × 40 ns = 100 µs per tick), 0x0420 sync-manager watchdog
//! time in ticks (default 1000 = 100 ms, 0 = off), retriggered by every complete write of an
//! output SM whose control byte has the watchdog trigger (bit 6), 0x0440 bit 0 status (0 =
//! expired), 0x0442 expiry counter. The device application reacts only in OP: outputs to their
//! safe state ([`super::EscApplication::outputs_invalid`]), SAFE-OP with the error indication
//! and AL status code 0x001B. The time counts from the OP entry until the first write.

use super::{dc, reg, AlState, AlStatusCode, Esc};

/// Something an ESC did by itself that a user of the emulator wants to know; the segment
/// collects them with the ring position ([`super::segment::SegmentEvent`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EscEvent {
    /// 0x0981 was written: what became of SYNC0.
    Sync0(dc::Activation),
    /// The sync-manager watchdog expired in OP after `after_ns` without process data: the
    /// device is in SAFE-OP with AL status code 0x001B.
    WatchdogExpired {
        /// Time since the last process-data write (or OP entry), ns.
        after_ns: u64,
    },
    /// SYNC0 pulses that were overdue by too many cycles were dropped without being generated
    /// (the emulator itself fell behind).
    Sync0Skipped {
        /// How many.
        pulses: u64,
    },
}

impl std::fmt::Display for EscEvent {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use dc::Activation;
        let ms = |ns: u64| ns as f64 / 1e6;
        match *self {
            EscEvent::Sync0(Activation::Off) => write!(f, "SYNC0 off"),
            EscEvent::Sync0(Activation::Scheduled { first, cycle }) => write!(
                f,
                "SYNC0 every {:.3} ms from system time {first} ns",
                ms(cycle)
            ),
            EscEvent::Sync0(Activation::Immediate { first, cycle }) => write!(
                f,
                "SYNC0 start time outside the near future, the plausibility check (0x0981 bit 5) \
                 starts it at once: every {:.3} ms from system time {first} ns",
                ms(cycle)
            ),
            EscEvent::Sync0(Activation::StartMissed { start, late_ns }) => write!(
                f,
                "SYNC0 start time {start} ns lay {:.3} ms in the past when 0x0981 activated it: \
                 no SYNC0 (the ESC waits for a start time the system time never reaches again; \
                 write it further ahead or set the plausibility check, 0x0981 bit 5)",
                ms(late_ns)
            ),
            EscEvent::Sync0(Activation::CycleTooShort { cycle }) => write!(
                f,
                "SYNC0 cycle time {cycle} ns is below the {} ns the emulated devices run: no SYNC0",
                dc::MIN_SYNC0_CYCLE_NS
            ),
            EscEvent::WatchdogExpired { after_ns } => write!(
                f,
                "sync-manager watchdog expired after {:.1} ms without process data \
                 \u{2192} SAFE-OP, AL status 0x001B",
                ms(after_ns)
            ),
            EscEvent::Sync0Skipped { pulses } => write!(
                f,
                "the emulator fell behind its clock: {pulses} SYNC0 pulses dropped"
            ),
        }
    }
}

/// At most this many [`EscEvent`]s wait for [`Esc::take_events`]; later ones are dropped.
const MAX_EVENTS: usize = 32;

impl Esc {
    /// When the process-data watchdog expires if no process data come (on the caller's clock):
    /// the last output SM write (or the OP entry) + [`Self::pd_watchdog_ns`]. `None` unless the
    /// device is in OP with an active output SM whose watchdog trigger (control bit 6) is on and
    /// a non-zero watchdog time.
    pub fn watchdog_deadline(&self) -> Option<u64> {
        // Cheapest checks first: a segment asks every device at every frame.
        if self.state != AlState::Op {
            return None;
        }
        let last = self.last_output_ns?;
        let wd = self.pd_watchdog_ns();
        if wd == 0 || !self.watchdog_guarded() {
            return None;
        }
        Some(last.saturating_add(wd))
    }

    /// Is an active output SM's watchdog trigger on? Cached until a sync manager register or the
    /// AL state changes ([`Esc::sm_config_changed`]).
    fn watchdog_guarded(&self) -> bool {
        if let Some(g) = self.wd_guarded.get() {
            return g;
        }
        let g = (0..self.sm_count()).any(|n| {
            self.active_sm(n).is_some_and(|sm| {
                !self.mailbox_sm(n, &sm) && sm.ecat_writes() && sm.control & 0x40 != 0
            })
        });
        self.wd_guarded.set(Some(g));
        g
    }

    /// Advance time without traffic: runs the process-data watchdog. If an output SM with the
    /// watchdog trigger (control bit 6) is active in OP and was not written for
    /// [`Self::pd_watchdog_ns`] (counted from the OP entry until the first write), the device
    /// drops to SAFE-OP with AL status code 0x001B, clears 0x0440 bit 0, increments 0x0442, puts
    /// the application's outputs into their safe state and reports
    /// [`EscEvent::WatchdogExpired`].
    pub fn tick(&mut self, now_ns: u64) {
        let wd = self.pd_watchdog_ns();
        if wd == 0 || self.state != AlState::Op || !self.watchdog_guarded() {
            return;
        }
        let last = *self.last_output_ns.get_or_insert(now_ns);
        let idle = now_ns.saturating_sub(last);
        if idle >= wd {
            self.mem[usize::from(reg::WD_STATUS_PD)] &= !0x01;
            let c = usize::from(reg::WD_COUNTER_PD);
            self.mem[c] = self.mem[c].saturating_add(1);
            self.last_output_ns = None;
            self.raise_al_error(AlState::SafeOp, AlStatusCode::SYNC_MANAGER_WATCHDOG);
            self.push_event(EscEvent::WatchdogExpired { after_ns: idle });
        }
    }

    fn push_event(&mut self, e: EscEvent) {
        if self.events.len() < MAX_EVENTS {
            self.events.push(e);
        }
    }

    /// The events since the last call (at most 32; later ones are dropped).
    pub fn take_events(&mut self) -> Vec<EscEvent> {
        std::mem::take(&mut self.events)
    }

    /// The SYNC0 unit (schedule and pulse count).
    pub fn sync0_unit(&self) -> &dc::Sync0Unit {
        &self.sync0
    }

    /// Next SYNC0 pulse (system time, ns) at or after the system time of `now_ns`, if SYNC0
    /// runs (0x0981 activated it with a start time in the near future, or at once with the
    /// plausibility check). Pulses not yet generated with [`Self::fire_sync0`] are counted as if
    /// they had been.
    pub fn next_sync0(&self, now_ns: u64) -> Option<u64> {
        if !self.cfg.dc {
            return None;
        }
        let next = self.sync0.next_pulse()?;
        let cycle = self.sync0.cycle();
        let late = self.system_time(now_ns).wrapping_sub(next);
        if late == 0 || late >= 1 << 63 || cycle == 0 {
            return Some(next);
        }
        Some(next.wrapping_add(late.div_ceil(cycle).saturating_mul(cycle)))
    }

    /// When the next SYNC0 pulse is due on the caller's clock (`now_ns` is that clock's present:
    /// the pulse's system time is converted through this device's local clock and 0x0920);
    /// earlier than `now_ns` if overdue. `None` if SYNC0 does not run.
    pub fn sync0_due_at(&self, now_ns: u64) -> Option<u64> {
        if !self.cfg.dc {
            return None;
        }
        let next = self.sync0.next_pulse()?;
        let sys_now = self.system_time(now_ns);
        let ahead = next.wrapping_sub(sys_now);
        Some(if ahead < 1 << 63 {
            now_ns.saturating_add(ahead)
        } else {
            now_ns.saturating_sub(sys_now.wrapping_sub(next))
        })
    }

    /// Generate the pending SYNC0 pulse. Returns `None` if none is scheduled, else whether it
    /// was a sync error: the device was in OP at this pulse and the previous one, has an output
    /// SM, and no process data reached it in between (the application then works with the same
    /// outputs again; counted in [`Self::sync_errors`]).
    pub fn fire_sync0(&mut self) -> Option<bool> {
        self.sync0.fire()?;
        self.mem[usize::from(reg::DC_ACTIVATION_STATUS)] &= !0x01;
        let in_op = self.state == AlState::Op;
        let has_outputs = (0..self.sm_count()).any(|n| {
            self.active_sm(n)
                .is_some_and(|sm| !self.mailbox_sm(n, &sm) && sm.ecat_writes())
        });
        let error = in_op && self.op_at_last_sync0 && has_outputs && !self.outputs_since_sync0;
        if error {
            self.sync_errors += 1;
        }
        self.op_at_last_sync0 = in_op;
        self.outputs_since_sync0 = false;
        Some(error)
    }

    /// Drop the SYNC0 pulses that are overdue by more than `keep` cycles at `now_ns` (the
    /// emulator fell behind); returns how many ([`EscEvent::Sync0Skipped`] if any).
    pub fn skip_overdue_sync0(&mut self, now_ns: u64, keep: u64) -> u64 {
        let sys_now = self.system_time(now_ns);
        let pulses = self.sync0.skip_overdue(sys_now, keep);
        if pulses > 0 {
            self.push_event(EscEvent::Sync0Skipped { pulses });
        }
        pulses
    }

    /// SYNC0 pulses in OP without process data since the previous one (see [`Self::fire_sync0`]).
    pub fn sync_errors(&self) -> u64 {
        self.sync_errors
    }

    /// 0x0981 written: (re)arm SYNC0 from 0x0990 / 0x09A0 ([`dc::Sync0Unit::activate`]);
    /// 0x0984 bit 0 = first SYNC0 pulse pending, bit 1 = SYNC1 activated, bit 2 = the start time
    /// was outside the near future.
    pub(super) fn sync_activation_written(&mut self, now: u64) {
        let act = self.mem[usize::from(reg::DC_SYNC_ACTIVATION)];
        let was_running = self.sync0.next_pulse().is_some();
        let a = self.sync0.activate(
            act,
            self.peek_u64(reg::DC_START_TIME),
            self.peek_u32(reg::DC_SYNC0_CYCLE),
            self.system_time(now),
        );
        let mut status = 0u8;
        if self.sync0.first_pending() {
            status |= 0x01;
        }
        if act & 0x05 == 0x05 {
            status |= 0x02;
        }
        if matches!(a, dc::Activation::Immediate { .. }) {
            status |= 0x04;
        }
        self.mem[usize::from(reg::DC_ACTIVATION_STATUS)] = status;
        self.outputs_since_sync0 = false;
        self.op_at_last_sync0 = false;
        if a != dc::Activation::Off || was_running {
            self.push_event(EscEvent::Sync0(a));
        }
    }
}
