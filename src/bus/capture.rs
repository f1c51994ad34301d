//! Timestamps of frame captures (`--pcap`, `--candump`): the wall-clock time of the run.
//!
//! A capture is read with the tools of the field (Wireshark / tshark, `candump -r`,
//! `canplayer`), which show absolute times: every frame carries its time since the Unix
//! epoch. [`CaptureClock`] takes the wall clock (`SystemTime::now()`) once, when the capture
//! opens, as its base; each frame's time is that base plus an offset:
//!
//! - on a link that leaves the process (`ethercat:IFACE`, `socketcan:IF`, `canopen-udp`) the
//!   real monotonic time since the capture opened ([`CaptureClock::now_ns`]), so the frame
//!   spacing is what the wire saw and a step of the wall clock (NTP) during the run does not
//!   reorder frames;
//! - on an in-process link (`ethercat-emu`, `canopen-emu`), which runs on virtual time, the
//!   link's virtual time since the capture opened ([`CaptureClock::at_ns`]): the capture then
//!   shows the true cycle spacing of the emulated bus (one machine cycle from SYNC to SYNC,
//!   the frames' own wire times), not how fast this machine computed it. Such a capture is
//!   dated at the start of the run and lasts as long as the run's virtual time, which may be
//!   longer or shorter than the wall-clock time the run took.

use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// The time base of one capture (module documentation).
#[derive(Debug, Clone, Copy)]
pub struct CaptureClock {
    /// Wall clock when the capture opened, ns since the Unix epoch.
    base_ns: u64,
    /// The same moment on the monotonic clock.
    opened: Instant,
}

impl CaptureClock {
    /// A capture that opens now.
    pub fn start() -> CaptureClock {
        let base_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        CaptureClock {
            base_ns,
            opened: Instant::now(),
        }
    }

    /// The wall-clock time the capture opened, ns since the Unix epoch.
    pub fn base_ns(&self) -> u64 {
        self.base_ns
    }

    /// A frame of a real link, now: the base plus the monotonic time since the capture opened
    /// (ns since the Unix epoch).
    pub fn now_ns(&self) -> u64 {
        let elapsed = u64::try_from(self.opened.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.base_ns.saturating_add(elapsed)
    }

    /// A frame of an in-process link at `since_open` ns of its virtual time after the capture
    /// opened: the base plus that (ns since the Unix epoch).
    pub fn at_ns(&self, since_open: u64) -> u64 {
        self.base_ns.saturating_add(since_open)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base_is_the_wall_clock_and_offsets_add() {
        let before = SystemTime::now().duration_since(UNIX_EPOCH).unwrap();
        let c = CaptureClock::start();
        let after = SystemTime::now().duration_since(UNIX_EPOCH).unwrap();
        assert!(c.base_ns() >= before.as_nanos() as u64 && c.base_ns() <= after.as_nanos() as u64);
        assert_eq!(c.at_ns(1_000_000), c.base_ns() + 1_000_000);
        assert!(c.now_ns() >= c.base_ns());
        assert_eq!(c.at_ns(u64::MAX), u64::MAX);
    }
}
