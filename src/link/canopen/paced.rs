//! The paced cycle of a CANopen link that leaves the process (`canopen-udp`, `socketcan:IF`):
//! the master is the SYNC producer on a wall-clock timer, one SYNC per machine cycle on the
//! absolute grid of [`CycleClock`] (CiA 301 0x1006 communication cycle period).
//!
//! # One exchange, as in the field
//!
//! ```text
//!  SYNC k−1        RPDOs (set-points computed from the TPDOs of k−1)      SYNC k      TPDOs k
//!  ───┼──── TPDOs ──┼──────────────────────────┼─────── sleep ─────────────┼────────────┼──
//!     │<────── synchronous window 0x1007 ─────>│                           │<─ window ─>│
//! ```
//!
//! 1. The RPDOs with the set-points the channel computed from the previous exchange go out at
//!    once, inside the synchronous window that followed the previous SYNC (CiA 301: synchronous
//!    RPDO data take effect at the next SYNC).
//! 2. Sleep to the next deadline of the grid ([`CycleClock::tick`]); frames that arrived
//!    meanwhile are taken (heartbeats, EMCY; a TPDO of an earlier SYNC is dropped, it must not
//!    count for this one).
//! 3. SYNC.
//! 4. Collect the TPDOs until every expected one came or the synchronous window passed (the
//!    nodes must send synchronous TPDOs inside it, CiA 301 0x1007); when the master itself was
//!    held up past the window, what is queued already still counts (never beyond the next
//!    deadline). A missing TPDO is a lost exchange ([`LinkError::Lost`]) as before.
//!
//! Every cycle is recorded in [`CycleStats`] (sent = SYNC, done = last TPDO, missed deadlines,
//! lost). While the master waits for an SDO answer between exchanges, the SYNC keeps running on
//! the grid (`Pacing::keep_alive`): SYNC-only cycles, so a drive watching its SYNC does not
//! stop because the master was busy with a parameter.
//!
//! # Stall rule
//!
//! A cycle whose [`Wake::missed`] is more than the default `max_lost_cycles` (3), i.e. at
//! least [`STALL_MISSED`] = 4, returns [`LinkError::Stalled`] after its exchange (SYNC gap ≥ 4.5
//! periods). The channel counts the missed cycles against `max_lost_cycles`
//! ([`crate::channel::Channel::link_lost`]): with the default that is error 900012. Fewer
//! missed deadlines are overruns, counted in the statistics; the exchange itself is valid.
//! The emulated node's SYNC watch (`crate::sim::canopen`) waits [`SYNC_TIMEOUT_PERIODS`] = 5
//! periods, so an overrun the master rides through (SYNC gap < 4.5 periods) does not stop the
//! drives, and a stall reported as 900012 does (a real drive's SYNC or RPDO watch has its own
//! time; CANopenNode's SYNC time-out is 1.5 periods).

use std::io::Write;

use std::time::Duration;

use super::Transport;
use crate::bus::canopen::nmt;
use crate::link::{LinkError, ProcessImage};
use crate::rt::{monotonic_ns, CycleClock, CycleRecord, CycleStats, Wake};
use crate::units::Nanos;

/// A SYNC gap of more than this many periods stops the emulated drives
/// ([`crate::bus::canopen::nmt::SYNC_TIMEOUT_PERIODS`]).
pub const SYNC_TIMEOUT_PERIODS: u64 = crate::bus::canopen::nmt::SYNC_TIMEOUT_PERIODS;

/// Missed deadlines from which a cycle is a stall: one more than the default
/// `max_lost_cycles`, so the channel reports it (900012) unless the machine allows more.
pub const STALL_MISSED: u64 = crate::params::DEFAULT_MAX_LOST_CYCLES as u64 + 1;

/// The synchronous window 0x1007 the master configures, as a fraction of the period: half,
/// or more when a cycle's frames need more ([`sync_window`]). It must hold SYNC, every TPDO
/// and every RPDO of a cycle (on a 1 Mbit/s bus a data frame of 8 bytes takes at most 135 µs,
/// so half of 4 ms holds 14 of them); the rest is left to SDO, heartbeat and EMCY traffic.
pub const SYNC_WINDOW_DIVISOR: u64 = 2;

/// Half the period in µs (at least 1): the synchronous window of a cycle whose frames fit it.
pub fn sync_window_us(period: Nanos) -> u32 {
    let us = period.0 / 1000 / SYNC_WINDOW_DIVISOR;
    u32::try_from(us.max(1)).unwrap_or(u32::MAX)
}

/// 0x1007 synchronous window length for `period` when the SYNC and the PDOs of one cycle take
/// `frames` on the wire at worst ([`super::load::BusLoad::wire_time`]): half the period, or
/// `frames` rounded up to whole µs when longer, at most the period — the window must hold
/// them, or a node may drop the TPDOs past it and the master stops waiting there.
pub fn sync_window(period: Nanos, frames: Nanos) -> Nanos {
    let half = u64::from(sync_window_us(period));
    let us = half
        .max(frames.0.div_ceil(1000))
        .min((period.0 / 1000).max(1));
    Nanos::from_micros(us)
}

/// The RPDO event-timer the master configures (0x1400 + k sub-index 5, ms, deadline
/// monitoring in the node): [`SYNC_TIMEOUT_PERIODS`] cycles, rounded up to
/// whole ms, at least 1, at most 65535 — the same tolerance as the nodes' SYNC watch.
pub fn rpdo_event_timer_ms(period: Nanos) -> u16 {
    let ns = period.0.saturating_mul(SYNC_TIMEOUT_PERIODS);
    u16::try_from(ns.div_ceil(1_000_000).max(1)).unwrap_or(u16::MAX)
}

/// 0x1006 communication cycle period for `period` (µs).
pub fn cycle_period_us(period: Nanos) -> u32 {
    u32::try_from((period.0 / 1000).max(1)).unwrap_or(u32::MAX)
}

/// The stall rule (module documentation): `Some(Stalled)` when `wake` missed
/// [`STALL_MISSED`] deadlines or more; `gap_ns` is the SYNC gap around it, if known.
pub fn stall(wake: &Wake, period: Nanos, gap_ns: Option<u64>) -> Option<LinkError> {
    if wake.missed < STALL_MISSED {
        return None;
    }
    let ns = gap_ns.unwrap_or_else(|| (wake.missed + 1).saturating_mul(period.0));
    Some(LinkError::Stalled {
        missed: wake.missed,
        ms: ns as f64 / 1e6,
    })
}

/// The SYNC producer's clock and the statistics of a paced link.
pub(super) struct Pacing {
    clock: CycleClock,
    window_ns: u64,
    /// The next deadline of the grid, once the first SYNC went out.
    next: Option<u64>,
    /// When the last SYNC went out (monotonic ns).
    last_sync: Option<u64>,
    /// The gap before the last SYNC, ns.
    last_gap: u64,
    /// A stall seen in a SYNC-only cycle (during an SDO transfer), reported by the next
    /// exchange.
    pending_stall: Option<LinkError>,
    /// When the last exchange returned to the machine (monotonic ns; diagnostics).
    pub(super) returned: Option<u64>,
}

impl std::fmt::Debug for Pacing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pacing")
            .field("period", &self.clock.period())
            .field("window_ns", &self.window_ns)
            .finish_non_exhaustive()
    }
}

impl Pacing {
    /// A SYNC producer with period `period` and synchronous window `window`
    /// ([`sync_window`]).
    pub(super) fn new(period: Nanos, window: Nanos) -> Self {
        Pacing {
            clock: CycleClock::new(period),
            window_ns: window.0,
            next: None,
            last_sync: None,
            last_gap: 0,
            pending_stall: None,
            returned: None,
        }
    }

    pub(super) fn period(&self) -> Nanos {
        self.clock.period()
    }

    /// The synchronous window, ns.
    pub(super) fn window_ns(&self) -> u64 {
        self.window_ns
    }

    pub(super) fn stats(&self) -> &CycleStats {
        self.clock.stats()
    }

    pub(super) fn stats_mut(&mut self) -> &mut CycleStats {
        self.clock.stats_mut()
    }

    /// Write one CSV row per cycle to `out`.
    pub(super) fn log_to(&mut self, name: &str, out: Box<dyn Write + Send>) {
        self.clock.stats_mut().log_to(name, out);
    }

    /// Wait for the next deadline and send SYNC; `before_sync` runs between the two (taking
    /// what arrived meanwhile). Returns the wake-up, when the SYNC went out, and the longer of
    /// the last two SYNC gaps (a master held up inside the wait sends one SYNC late, and the
    /// next tick counts the deadlines it missed).
    pub(super) fn sync(
        &mut self,
        bus: &mut Transport,
        before_sync: &mut dyn FnMut(&mut Transport) -> Result<(), LinkError>,
    ) -> Result<(Wake, u64, Option<u64>), LinkError> {
        let wake = self.clock.tick();
        self.next = Some(wake.deadline + self.clock.period().0);
        before_sync(bus)?;
        bus.send(&nmt::sync())?;
        let sent = monotonic_ns();
        let gap = self.last_sync.map(|t| sent.saturating_sub(t));
        self.last_sync = Some(sent);
        let longest = gap.map(|g| g.max(self.last_gap));
        self.last_gap = gap.unwrap_or(0);
        Ok((wake, sent, longest))
    }

    /// Nanoseconds until the next deadline (0: due); `None` before the first SYNC.
    pub(super) fn until_due(&self) -> Option<u64> {
        self.next.map(|n| n.saturating_sub(monotonic_ns()))
    }

    /// Between exchanges (an SDO transfer waiting for its answer): if a deadline is due, send
    /// a SYNC on the grid and record it as a SYNC-only cycle.
    pub(super) fn keep_alive(&mut self, bus: &mut Transport) -> Result<(), LinkError> {
        if self.until_due() != Some(0) {
            return Ok(());
        }
        let (wake, sent, gap) = self.sync(bus, &mut |_| Ok(()))?;
        if let Some(e) = stall(&wake, self.period(), gap) {
            self.pending_stall.get_or_insert(e);
        }
        self.clock.stats_mut().record(CycleRecord {
            deadline: wake.deadline,
            sent,
            done: sent,
            missed: wake.missed,
            lost: false,
            dc_diff: None,
        });
        Ok(())
    }

    /// A stall seen by [`keep_alive`](Self::keep_alive) since the last exchange.
    pub(super) fn take_pending_stall(&mut self) -> Option<LinkError> {
        self.pending_stall.take()
    }
}

/// Why `canopen-emu` has no cycle log.
pub(super) const NO_CYCLE_LOG: &str = "--cycle-log: canopen-emu runs on virtual time (no \
     wall-clock cycle to log); the paced CAN links are canopen-udp[:GROUP:PORT] and socketcan:IF";

impl super::CanopenLink {
    /// One paced cycle (see [`paced`]): sleep to the deadline, take what arrived, SYNC,
    /// collect the TPDOs within the synchronous window, record the cycle; a stall is reported
    /// after the exchange.
    pub(super) fn paced_cycle(
        &mut self,
        pacing: &mut Pacing,
        n: u64,
        now: Nanos,
        images: &mut [ProcessImage],
    ) -> Result<(), LinkError> {
        // How long the machine kept the link between two exchanges (diagnostics).
        let away_us = pacing
            .returned
            .map_or(0, |r| monotonic_ns().saturating_sub(r) / 1000);
        let mut stale = Vec::new();
        let (wake, sent, gap) = pacing.sync(&mut self.bus, &mut |bus| {
            stale = bus.receive_all(Duration::ZERO)?;
            Ok(())
        })?;
        // Heartbeats and EMCY count; a TPDO that came before this SYNC belongs to an earlier
        // one and is dropped.
        let stale = self.note(stale, now);
        // Wait within the synchronous window; past it (the master itself was held up) take
        // only what is queued already; past the next deadline at most a few more frames (a
        // flood cannot hold the cycle).
        let window_end = sent + pacing.window_ns();
        let hard_end = sent + pacing.period().0;
        let mut seen = vec![false; self.tpdo_cobs.len()];
        let mut missing = seen.len();
        let mut got = Vec::new();
        let mut done = sent;
        let mut overtime = 4 * seen.len() + 16;
        while missing > 0 {
            let t = monotonic_ns();
            if t >= hard_end {
                if overtime == 0 {
                    break;
                }
                overtime -= 1;
            }
            let wait = Duration::from_nanos(window_end.saturating_sub(t));
            let Some(f) = self.bus.recv(wait)? else {
                break;
            };
            if !f.extended && !f.rtr && !f.error {
                if let Some(k) = self.tpdo_cobs.iter().position(|&c| c == f.id) {
                    done = monotonic_ns();
                    if !seen[k] {
                        seen[k] = true;
                        missing -= 1;
                    }
                }
            }
            // Bounded: the bus delivers at most what fits in the window.
            got.push(f);
        }
        let result = stale
            .and_then(|_| self.note(got, now))
            .and_then(|mut got| self.finish_exchange(n, now, &mut got, images));
        if wake.missed > 0 || result.is_err() {
            tracing::debug!(target: "fieldprobe::link::canopen", exchange = n,
                missed = wake.missed, late_us = wake.woke.saturating_sub(wake.deadline) / 1000,
                gap_us = gap.unwrap_or(0) / 1000, tpdos_missing = missing, away_us,
                "paced cycle: {}", result.as_ref().err().map_or("ok".to_string(), |e| e.to_string()));
        }
        pacing.stats_mut().record(CycleRecord {
            deadline: wake.deadline,
            sent,
            done,
            missed: wake.missed,
            lost: result.is_err(),
            dc_diff: None,
        });
        pacing.returned = Some(monotonic_ns());
        if let Some(e) = stall(&wake, pacing.period(), gap).or_else(|| pacing.take_pending_stall())
        {
            return Err(e);
        }
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wake(missed: u64) -> Wake {
        Wake {
            deadline: 0,
            woke: 0,
            missed,
        }
    }

    #[test]
    fn up_to_three_missed_deadlines_are_overruns_four_are_a_stall() {
        let p = Nanos::from_micros(4000);
        assert!(stall(&wake(0), p, Some(4_000_000)).is_none());
        assert!(stall(&wake(1), p, Some(8_100_000)).is_none());
        assert!(stall(&wake(3), p, Some(16_100_000)).is_none());
        // SIGSTOP for 300 ms at 4 ms: 74 deadlines skipped, SYNC gap 300 ms.
        match stall(&wake(74), p, Some(300_000_000)) {
            Some(LinkError::Stalled { missed, ms }) => {
                assert_eq!(missed, 74);
                assert!((ms - 300.0).abs() < 1e-9);
            }
            e => panic!("{e:?}"),
        }
        // Without a previous SYNC the gap is estimated from the grid: (4 + 1) × 4 ms.
        match stall(&wake(4), p, None) {
            Some(LinkError::Stalled { missed: 4, ms }) => assert!((ms - 20.0).abs() < 1e-9),
            e => panic!("{e:?}"),
        }
    }

    #[test]
    fn window_is_half_the_period_in_microseconds() {
        assert_eq!(sync_window_us(Nanos::from_micros(4000)), 2000);
        assert_eq!(cycle_period_us(Nanos::from_micros(4000)), 4000);
        assert_eq!(sync_window_us(Nanos::from_micros(1)), 1);
        // A cycle whose frames take longer than half of it: the window holds them.
        let p = Nanos::from_micros(4000);
        assert_eq!(sync_window(p, Nanos(1_840_000)), Nanos::from_micros(2000));
        assert_eq!(sync_window(p, Nanos(3_100_500)), Nanos::from_micros(3101));
        assert_eq!(sync_window(p, Nanos(9_000_000)), p);
    }
}
