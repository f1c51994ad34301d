//! **Internal** (used by fieldprobe's links and binary; may change in any release).
//!
//! Real-time cycles on the links that leave the process (`ethercat:IF`, `canopen-udp`,
//! `socketcan:IF`): one exchange per period on absolute deadlines, the usual real-time knobs of
//! EtherCAT masters, and the statistics of every cycle. The in-process links (`sim`,
//! `ethercat-emu`, `canopen-emu`) run on virtual time and use none of this.
//!
//! - [`RtOptions`]: `--rt-priority N` (SCHED_FIFO), `--cpu N` (affinity), `--mlock` (all memory
//!   locked). Each one either takes effect or is an error naming what the system refused and why
//!   — never a silent fallback.
//! - [`CycleClock`]: sleeps with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)` to the next
//!   deadline of a fixed grid (start + k · period, so no drift accumulates) and spins the last
//!   [`SPIN`]; a deadline that has already passed when the cycle asks for it is skipped and
//!   counted (an overrun). An EtherCAT master with distributed clocks re-aligns the grid to
//!   SYNC0 every cycle ([`CycleClock::align`]).
//! - [`CycleStats`]: period error (the time between two consecutive sends − the period:
//!   mean, p50, p99, max), overruns, lost and late frames, DC system-time difference, and
//!   optionally one CSV row per cycle (`--cycle-log FILE.csv`). Memory stays bounded: the
//!   distribution is a histogram of fixed size.

use std::io::Write;
use std::time::Duration;

use crate::units::Nanos;

/// [`CycleClock::track`] moves the grid by the phase error divided by this.
const TRACK_GAIN_DIV: i128 = 8;

/// The last part of a wait that is spun instead of slept (the kernel's wake-up latency).
pub const SPIN: Duration = Duration::from_micros(50);

/// Histogram resolution (ns per bin) and range of the period-error distribution.
const BIN_NS: u64 = 1_000;
const BINS: usize = 20_000;

/// Real-time settings of the process (the cyclic thread is the main thread).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RtOptions {
    /// SCHED_FIFO with this priority (1 ..= 99).
    pub priority: Option<u8>,
    /// Run on this CPU only.
    pub cpu: Option<usize>,
    /// Lock all current and future memory (`mlockall(MCL_CURRENT | MCL_FUTURE)`).
    pub lock_memory: bool,
}

/// A real-time setting the system did not allow; the text names the setting, what the system
/// answered and what would allow it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RtError {
    /// SCHED_FIFO refused.
    #[error("--rt-priority {priority}: {reason}")]
    Priority {
        /// Requested priority.
        priority: u8,
        /// Why.
        reason: String,
    },
    /// Affinity refused.
    #[error("--cpu {cpu}: {reason}")]
    Cpu {
        /// Requested CPU.
        cpu: usize,
        /// Why.
        reason: String,
    },
    /// Memory locking refused.
    #[error("--mlock: {reason}")]
    Lock {
        /// Why.
        reason: String,
    },
}

impl RtOptions {
    /// No option set.
    pub fn is_empty(&self) -> bool {
        self.priority.is_none() && self.cpu.is_none() && !self.lock_memory
    }

    /// Refuse what no system could take: a priority outside SCHED_FIFO's 1 ..= 99, a CPU this
    /// machine does not have.
    ///
    /// # Errors
    /// The first such option, with the reason.
    pub fn check(&self) -> Result<(), RtError> {
        if let Some(p) = self.priority {
            if !(1..=99).contains(&p) {
                return Err(RtError::Priority {
                    priority: p,
                    reason: "SCHED_FIFO priorities are 1 ..= 99".into(),
                });
            }
        }
        if let Some(cpu) = self.cpu {
            let online = std::thread::available_parallelism().map_or(1, |n| n.get());
            if cpu >= online {
                return Err(RtError::Cpu {
                    cpu,
                    reason: format!(
                        "no such CPU (this system has {online}: 0 ..= {})",
                        online - 1
                    ),
                });
            }
        }
        Ok(())
    }

    /// Apply every option to the calling thread / process; returns what took effect, in words.
    ///
    /// # Errors
    /// The first option the system refused, with the reason.
    pub fn apply(&self) -> Result<Vec<String>, RtError> {
        let mut done = Vec::new();
        if let Some(cpu) = self.cpu {
            apply_cpu(cpu)?;
            done.push(format!("affinity CPU {cpu}"));
        }
        if self.lock_memory {
            apply_lock()?;
            done.push("memory locked".into());
        }
        if let Some(p) = self.priority {
            apply_priority(p)?;
            done.push(format!("SCHED_FIFO priority {p}"));
        }
        Ok(done)
    }
}

#[cfg(target_os = "linux")]
fn apply_cpu(cpu: usize) -> Result<(), RtError> {
    use nix::sched::{sched_setaffinity, CpuSet};
    use nix::unistd::Pid;
    let online = std::thread::available_parallelism().map_or(1, |n| n.get());
    if cpu >= CpuSet::count() {
        return Err(RtError::Cpu {
            cpu,
            reason: format!(
                "no such CPU (this system has {online}: 0 ..= {})",
                online - 1
            ),
        });
    }
    let mut set = CpuSet::new();
    set.set(cpu).map_err(|e| RtError::Cpu {
        cpu,
        reason: e.to_string(),
    })?;
    sched_setaffinity(Pid::from_raw(0), &set).map_err(|e| RtError::Cpu {
        cpu,
        reason: match e {
            nix::errno::Errno::EINVAL => format!(
                "not among the CPUs this process may use (this system has {online}: 0 ..= {})",
                online - 1
            ),
            nix::errno::Errno::EPERM => "not permitted (needs CAP_SYS_NICE)".into(),
            e => e.desc().to_string(),
        },
    })
}

#[cfg(target_os = "linux")]
fn apply_lock() -> Result<(), RtError> {
    use nix::sys::mman::{mlockall, MlockAllFlags};
    mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|e| RtError::Lock {
        reason: match e {
            nix::errno::Errno::ENOMEM | nix::errno::Errno::EPERM => format!(
                "{} (needs CAP_IPC_LOCK or a large enough RLIMIT_MEMLOCK, `ulimit -l`)",
                e.desc()
            ),
            e => e.desc().to_string(),
        },
    })
}

#[cfg(target_os = "linux")]
fn apply_priority(priority: u8) -> Result<(), RtError> {
    use thread_priority::{
        set_thread_priority_and_policy, thread_native_id, RealtimeThreadSchedulePolicy,
        ThreadPriority, ThreadPriorityValue, ThreadSchedulePolicy,
    };
    let value = ThreadPriorityValue::try_from(priority)
        .ok()
        .filter(|_| (1..=99).contains(&priority))
        .ok_or_else(|| RtError::Priority {
            priority,
            reason: "SCHED_FIFO priorities are 1 ..= 99".into(),
        })?;
    set_thread_priority_and_policy(
        thread_native_id(),
        ThreadPriority::Crossplatform(value),
        ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
    )
    .map_err(|e| RtError::Priority {
        priority,
        reason: match e {
            thread_priority::Error::OS(code) if code == nix::errno::Errno::EPERM as i32 => {
                "not permitted: SCHED_FIFO needs CAP_SYS_NICE (root) or an RLIMIT_RTPRIO of at \
                 least this priority (`ulimit -r`)"
                    .into()
            }
            e => e.to_string(),
        },
    })
}

#[cfg(not(target_os = "linux"))]
fn apply_cpu(cpu: usize) -> Result<(), RtError> {
    Err(RtError::Cpu {
        cpu,
        reason: "only supported on Linux".into(),
    })
}

#[cfg(not(target_os = "linux"))]
fn apply_lock() -> Result<(), RtError> {
    Err(RtError::Lock {
        reason: "only supported on Linux".into(),
    })
}

#[cfg(not(target_os = "linux"))]
fn apply_priority(priority: u8) -> Result<(), RtError> {
    Err(RtError::Priority {
        priority,
        reason: "only supported on Linux".into(),
    })
}

/// Nanoseconds on the monotonic clock (CLOCK_MONOTONIC).
pub fn monotonic_ns() -> u64 {
    #[cfg(target_os = "linux")]
    {
        use nix::time::{clock_gettime, ClockId};
        match clock_gettime(ClockId::CLOCK_MONOTONIC) {
            Ok(t) => (t.tv_sec() as u64)
                .saturating_mul(1_000_000_000)
                .saturating_add(t.tv_nsec() as u64),
            Err(_) => 0,
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        use std::sync::OnceLock;
        static T0: OnceLock<std::time::Instant> = OnceLock::new();
        T0.get_or_init(std::time::Instant::now).elapsed().as_nanos() as u64
    }
}

/// Sleep until `deadline` (monotonic ns): an absolute sleep to [`SPIN`] before it, then a spin.
pub fn sleep_until(deadline: u64) {
    let spin = SPIN.as_nanos() as u64;
    let wake = deadline.saturating_sub(spin);
    if monotonic_ns() < wake {
        #[cfg(target_os = "linux")]
        {
            use nix::sys::time::TimeSpec;
            use nix::time::{clock_nanosleep, ClockId, ClockNanosleepFlags};
            let ts = TimeSpec::new((wake / 1_000_000_000) as i64, (wake % 1_000_000_000) as i64);
            // EINTR: the spin below finishes the wait.
            let _ = clock_nanosleep(
                ClockId::CLOCK_MONOTONIC,
                ClockNanosleepFlags::TIMER_ABSTIME,
                &ts,
            );
        }
        #[cfg(not(target_os = "linux"))]
        std::thread::sleep(Duration::from_nanos(wake - monotonic_ns()));
    }
    while monotonic_ns() < deadline {
        std::hint::spin_loop();
    }
}

/// When a cycle woke.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wake {
    /// The deadline it waited for (monotonic ns).
    pub deadline: u64,
    /// When it woke (monotonic ns).
    pub woke: u64,
    /// Deadlines that had passed before this one was asked for (overruns: cycles without a
    /// frame).
    pub missed: u64,
}

/// The cycle grid of a paced link and its statistics.
#[derive(Debug)]
pub struct CycleClock {
    period: u64,
    next: Option<u64>,
    stats: CycleStats,
}

impl CycleClock {
    /// A grid with `period`; the first deadline is the moment of the first [`tick`](Self::tick).
    pub fn new(period: Nanos) -> Self {
        CycleClock {
            period: period.0.max(1),
            next: None,
            stats: CycleStats::new(period),
        }
    }

    /// The period.
    pub fn period(&self) -> Nanos {
        Nanos(self.period)
    }

    /// Wait for the next deadline. Deadlines that passed while the caller was busy (or stopped)
    /// are skipped and counted as missed: the grid stays where it was.
    pub fn tick(&mut self) -> Wake {
        let now = monotonic_ns();
        let mut deadline = *self.next.get_or_insert(now);
        let mut missed = 0;
        if now > deadline + self.period / 2 {
            missed = (now - deadline) / self.period;
            deadline += missed * self.period;
            if now > deadline + self.period / 2 {
                missed += 1;
                deadline += self.period;
            }
        }
        sleep_until(deadline);
        let mut woke = monotonic_ns();
        // Woken (or resumed after a SIGSTOP) more than half a period late: the slots in
        // between had no frame; this one goes out in the slot it falls into.
        if woke > deadline + self.period / 2 {
            let late = (woke - deadline + self.period / 2) / self.period;
            missed += late;
            deadline += late * self.period;
            woke = woke.max(deadline);
        }
        self.next = Some(deadline + self.period);
        self.stats.overruns += missed;
        Wake {
            deadline,
            woke,
            missed,
        }
    }

    /// Move the next deadline onto the phase of `target` (monotonic ns): an EtherCAT master with
    /// distributed clocks places its cycle at a fixed shift from SYNC0 (ethercrab's
    /// `CycleInfo::next_cycle_wait`, the time from the frame to the next SYNC0 + shift). The
    /// target is a phase, known modulo the period: of the instants `target + k · period` the one
    /// nearest the nominal next deadline is taken, so the grid moves by at most half a period.
    /// A frame that reached the devices late (after the next SYNC0 already) gives a target one
    /// period further on; taken as it is, the master would skip a slot for every late frame.
    pub fn align(&mut self, target: u64) {
        self.shift_by(target, 1);
    }

    /// [`align`](Self::align) by an eighth of the phase error only: the cyclic phase's drift
    /// compensation. The phase each frame measures scatters with the frame's latency (tens of
    /// µs on a loaded machine) while the clocks drift apart by ~0.1 µs per ms; following every
    /// measurement in full would put that scatter into the period. A first-order filter
    /// (time constant 8 cycles) follows the drift and smooths the scatter; the start-up
    /// ([`align`](Self::align)) takes the phase in full.
    pub fn track(&mut self, target: u64) {
        self.shift_by(target, TRACK_GAIN_DIV);
    }

    /// Move the next deadline by the phase error towards `target` divided by `div`.
    fn shift_by(&mut self, target: u64, div: i128) {
        let Some(n) = self.next else {
            return;
        };
        let p = i128::from(self.period);
        let d = i128::from(target) - i128::from(n);
        // d reduced to (-p/2, p/2].
        let mut r = d.rem_euclid(p);
        if r > p / 2 {
            r -= p;
        }
        let next = i128::from(n) + r / div;
        self.next = Some(u64::try_from(next.max(0)).unwrap_or(u64::MAX));
    }

    /// The statistics.
    pub fn stats(&self) -> &CycleStats {
        &self.stats
    }

    /// The statistics, mutable (recording).
    pub fn stats_mut(&mut self) -> &mut CycleStats {
        &mut self.stats
    }
}

/// What one cycle did, for [`CycleStats::record`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct CycleRecord {
    /// Its deadline (monotonic ns).
    pub deadline: u64,
    /// When its frame went out (monotonic ns).
    pub sent: u64,
    /// When the answer was complete (monotonic ns).
    pub done: u64,
    /// Deadlines skipped before it.
    pub missed: u64,
    /// The exchange failed (frame lost, wrong working counter, TPDO missing).
    pub lost: bool,
    /// DC system-time difference read this cycle (0x092C, magnitude in ns), if any.
    pub dc_diff: Option<u32>,
}

/// Statistics of the cycles of a paced link (see the module documentation).
pub struct CycleStats {
    period: u64,
    cycles: u64,
    first_sent: Option<u64>,
    last_sent: Option<u64>,
    /// Deadlines skipped (no frame in that period).
    pub overruns: u64,
    lost: u64,
    late: u64,
    periods: u64,
    error_sum: i128,
    error_max: u64,
    hist: Vec<u32>,
    over_hist: u64,
    dc_max: Option<u32>,
    log: Option<(String, std::io::BufWriter<Box<dyn Write + Send>>)>,
    log_error: Option<String>,
}

impl std::fmt::Debug for CycleStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CycleStats")
            .field("summary", &self.summary())
            .field("log", &self.log.as_ref().map(|(n, _)| n))
            .finish_non_exhaustive()
    }
}

impl CycleStats {
    /// Empty statistics for `period`.
    pub fn new(period: Nanos) -> Self {
        CycleStats {
            period: period.0.max(1),
            cycles: 0,
            first_sent: None,
            last_sent: None,
            overruns: 0,
            lost: 0,
            late: 0,
            periods: 0,
            error_sum: 0,
            error_max: 0,
            hist: vec![0; BINS],
            over_hist: 0,
            dc_max: None,
            log: None,
            log_error: None,
        }
    }

    /// Write one CSV row per cycle to `out` (`name` for error messages), after a header.
    pub fn log_to(&mut self, name: &str, out: Box<dyn Write + Send>) {
        let mut w = std::io::BufWriter::new(out);
        if let Err(e) = writeln!(
            w,
            "cycle,deadline_us,sent_us,period_error_us,round_trip_us,missed,lost,dc_diff_ns"
        ) {
            self.log_error = Some(format!("{name}: {e}"));
        }
        self.log = Some((name.to_string(), w));
    }

    /// Record one cycle.
    pub fn record(&mut self, r: CycleRecord) {
        self.cycles += 1;
        let start = *self.first_sent.get_or_insert(r.sent);
        let mut period_error: Option<i64> = None;
        if let Some(prev) = self.last_sent {
            // Only consecutive cycles measure a period; skipped deadlines are overruns.
            if r.missed == 0 {
                let err = r.sent as i128 - prev as i128 - i128::from(self.period);
                let e = err.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64;
                period_error = Some(e);
                self.periods += 1;
                self.error_sum += err;
                let mag = e.unsigned_abs();
                self.error_max = self.error_max.max(mag);
                match self.hist.get_mut((mag / BIN_NS) as usize) {
                    Some(b) => *b = b.saturating_add(1),
                    None => self.over_hist += 1,
                }
            }
        }
        self.last_sent = Some(r.sent);
        if r.lost {
            self.lost += 1;
        } else if r.done > r.deadline + self.period {
            // The answer came after the next cycle should have started.
            self.late += 1;
        }
        if let Some(d) = r.dc_diff {
            self.dc_max = Some(self.dc_max.map_or(d, |m| m.max(d)));
        }
        if self.log_error.is_none() {
            if let Some((name, w)) = self.log.as_mut() {
                let us = |t: u64| t.saturating_sub(start) as f64 / 1000.0;
                let res = writeln!(
                    w,
                    "{},{:.3},{:.3},{},{:.3},{},{},{}",
                    self.cycles,
                    us(r.deadline),
                    us(r.sent),
                    period_error.map_or(String::new(), |e| format!("{:.3}", e as f64 / 1000.0)),
                    r.done.saturating_sub(r.sent) as f64 / 1000.0,
                    r.missed,
                    u8::from(r.lost),
                    r.dc_diff.map_or(String::new(), |d| d.to_string()),
                );
                if let Err(e) = res {
                    self.log_error = Some(format!("{name}: {e}"));
                }
            }
        }
    }

    /// Flush the CSV log; the first write error, if any, names the file.
    ///
    /// # Errors
    /// A write to the log failed (now or earlier).
    pub fn finish_log(&mut self) -> Result<(), String> {
        if let Some(e) = &self.log_error {
            return Err(e.clone());
        }
        if let Some((name, w)) = self.log.as_mut() {
            if let Err(e) = w.flush() {
                let e = format!("{name}: {e}");
                self.log_error = Some(e.clone());
                return Err(e);
            }
        }
        Ok(())
    }

    /// The `q`-quantile (0 ..= 1) of the |period error| in ns (bin upper edge; the exact
    /// maximum for values beyond the histogram).
    fn quantile(&self, q: f64) -> u64 {
        if self.periods == 0 {
            return 0;
        }
        let rank = ((q * self.periods as f64).ceil() as u64).clamp(1, self.periods);
        let mut seen = 0u64;
        for (i, &n) in self.hist.iter().enumerate() {
            seen += u64::from(n);
            if seen >= rank {
                return ((i as u64 + 1) * BIN_NS).min(self.error_max);
            }
        }
        self.error_max
    }

    /// The summary of every cycle so far.
    pub fn summary(&self) -> CycleSummary {
        let wall = match (self.first_sent, self.last_sent) {
            (Some(a), Some(b)) => b - a,
            _ => 0,
        };
        CycleSummary {
            period_us: self.period as f64 / 1000.0,
            cycles: self.cycles,
            wall_s: wall as f64 * 1e-9,
            period_error_mean_us: if self.periods > 0 {
                (self.error_sum as f64 / self.periods as f64) / 1000.0
            } else {
                0.0
            },
            period_error_p50_us: self.quantile(0.5) as f64 / 1000.0,
            period_error_p99_us: self.quantile(0.99) as f64 / 1000.0,
            period_error_max_us: self.error_max as f64 / 1000.0,
            overruns: self.overruns,
            lost: self.lost,
            late: self.late,
            dc_diff_max_ns: self.dc_max,
        }
    }
}

/// What a paced link reports at the end of a run (stderr line, `--json` `"cycle"`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CycleSummary {
    /// Nominal period, µs.
    pub period_us: f64,
    /// Cycles run.
    pub cycles: u64,
    /// Wall time from the first to the last frame, s.
    pub wall_s: f64,
    /// Mean of (measured period − nominal), µs.
    pub period_error_mean_us: f64,
    /// Median |period error|, µs (1 µs resolution).
    pub period_error_p50_us: f64,
    /// 99th percentile |period error|, µs (1 µs resolution).
    pub period_error_p99_us: f64,
    /// Largest |period error|, µs.
    pub period_error_max_us: f64,
    /// Deadlines skipped: periods without a frame.
    pub overruns: u64,
    /// Exchanges that failed.
    pub lost: u64,
    /// Exchanges whose answer came after the next deadline.
    pub late: u64,
    /// Largest DC system-time difference seen (0x092C), ns; `None` without DC.
    pub dc_diff_max_ns: Option<u32>,
}

impl std::fmt::Display for CycleSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "cycle: {} cycles of {} µs in {:.3} s; period error mean {:+.1} µs, p50 {:.0} µs, p99 {:.0} µs, max {:.1} µs; overruns {}, lost {}, late {}",
            self.cycles,
            self.period_us,
            self.wall_s,
            self.period_error_mean_us,
            self.period_error_p50_us,
            self.period_error_p99_us,
            self.period_error_max_us,
            self.overruns,
            self.lost,
            self.late
        )?;
        if let Some(d) = self.dc_diff_max_ns {
            write!(f, ", DC system-time difference max {d} ns")?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(sent: u64, missed: u64, lost: bool) -> CycleRecord {
        CycleRecord {
            deadline: sent,
            sent,
            done: sent + 10_000,
            missed,
            lost,
            dc_diff: None,
        }
    }

    #[test]
    fn period_errors_and_quantiles_from_the_send_times() {
        let mut s = CycleStats::new(Nanos(1_000_000));
        // Periods: 1 ms exactly ×97, then +3 µs, −5 µs and +120 µs.
        let mut t = 0u64;
        s.record(rec(t, 0, false));
        for _ in 0..97 {
            t += 1_000_000;
            s.record(rec(t, 0, false));
        }
        for d in [1_003_000u64, 995_000, 1_120_000] {
            t += d;
            s.record(rec(t, 0, false));
        }
        let m = s.summary();
        assert_eq!(m.cycles, 101);
        assert_eq!(m.period_error_max_us, 120.0);
        // 100 periods: 97 exact (bin 0: ≤ 1 µs), so the median is in the first bin.
        assert_eq!(m.period_error_p50_us, 1.0);
        // The 99th of 100 sorted |errors| is the 5 µs one: its bin's upper edge, 6 µs.
        assert_eq!(m.period_error_p99_us, 6.0);
        assert!((m.period_error_mean_us - (3.0 - 5.0 + 120.0) / 100.0).abs() < 1e-9);
        assert!((m.wall_s - t as f64 * 1e-9).abs() < 1e-12);
    }

    #[test]
    fn skipped_deadlines_are_overruns_not_periods_and_losses_count() {
        let mut c = CycleClock::new(Nanos(1_000_000));
        c.stats_mut().overruns = 2;
        let s = c.stats_mut();
        s.record(rec(0, 0, false));
        s.record(rec(3_000_000, 2, false));
        s.record(rec(4_000_000, 0, true));
        let m = s.summary();
        assert_eq!((m.overruns, m.lost, m.late), (2, 1, 0));
        assert_eq!(
            m.period_error_max_us, 0.0,
            "only the 3 → 4 ms period measured"
        );
    }

    #[test]
    fn a_failing_log_is_an_error_naming_it() {
        struct Full;
        impl Write for Full {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(std::io::Error::new(
                    std::io::ErrorKind::StorageFull,
                    "disk full",
                ))
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Err(std::io::Error::new(
                    std::io::ErrorKind::StorageFull,
                    "disk full",
                ))
            }
        }
        let mut s = CycleStats::new(Nanos(1_000_000));
        s.log_to("cycles.csv", Box::new(Full));
        for k in 0..10_000 {
            s.record(rec(k * 1_000_000, 0, false));
        }
        let e = s.finish_log().unwrap_err();
        assert!(
            e.starts_with("cycles.csv: ") && e.contains("disk full"),
            "{e}"
        );
    }

    #[test]
    fn aligning_moves_the_grid_to_the_nearest_instance_of_the_phase() {
        let p = 1_000_000u64;
        let mut c = CycleClock::new(Nanos(p));
        c.align(5); // no grid yet: nothing to move
        assert_eq!(c.next, None);
        c.next = Some(10 * p);
        // A target 30 µs early, or a period and 30 µs late (a frame that reached the devices
        // after the next SYNC0): both mean the phase 30 µs before the grid point.
        c.align(10 * p - 30_000);
        assert_eq!(c.next, Some(10 * p - 30_000));
        c.next = Some(10 * p);
        c.align(11 * p - 30_000);
        assert_eq!(c.next, Some(10 * p - 30_000));
        c.next = Some(10 * p);
        c.align(12 * p + 400_000);
        assert_eq!(c.next, Some(10 * p + 400_000));
        // Never more than half a period in either direction.
        c.next = Some(10 * p);
        c.align(10 * p + 600_000);
        assert_eq!(c.next, Some(10 * p - 400_000));
        c.next = Some(10 * p);
        c.align(10 * p + 500_000);
        assert_eq!(c.next, Some(10 * p + 500_000));
        // Tracking takes an eighth of the same phase error.
        c.next = Some(10 * p);
        c.track(11 * p - 80_000);
        assert_eq!(c.next, Some(10 * p - 10_000));
        // A constant phase error is followed to within 1 % in 35 cycles ((7/8)^35 < 1 %).
        let mut grid = 10 * p;
        c.next = Some(grid);
        let target_phase = 200_000u64;
        for _ in 0..35 {
            c.track(grid / p * p + target_phase);
            let n = c.next.unwrap();
            grid = n + p;
            c.next = Some(grid);
        }
        let err = (grid % p) as i64 - target_phase as i64;
        assert!(err.abs() < 2_000, "phase error {err} ns");
    }

    #[test]
    fn the_clock_keeps_an_absolute_grid() {
        // 20 ticks of 2 ms with work of ~0.3 ms in between: the deadlines stay on the grid.
        let mut c = CycleClock::new(Nanos(2_000_000));
        let first = c.tick();
        let mut last = first;
        for _ in 0..20 {
            std::thread::sleep(Duration::from_micros(300));
            last = c.tick();
        }
        assert_eq!(
            (last.deadline - first.deadline) % 2_000_000,
            0,
            "deadlines on the grid"
        );
        // Whatever the machine's load, a deadline is never served early.
        assert!(last.woke >= last.deadline);
    }

    #[test]
    fn refused_options_are_errors_with_reasons() {
        let e = RtOptions {
            priority: Some(0),
            ..Default::default()
        }
        .apply()
        .unwrap_err();
        assert!(e.to_string().contains("1 ..= 99"), "{e}");
        let e = RtOptions {
            cpu: Some(100_000),
            ..Default::default()
        }
        .apply()
        .unwrap_err();
        assert!(
            e.to_string().starts_with("--cpu 100000: no such CPU"),
            "{e}"
        );
    }
}
