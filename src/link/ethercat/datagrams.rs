//! Each process-data datagram of a cycle checked on its own: its working counter against the
//! one the devices' FMMUs call for, and a lost one named.
//!
//! ethercrab 0.7.1 splits a process image longer than a frame into one `LRW` per frame and
//! reports only the sum of their working counters. The link sees every frame go out and come
//! back ([`DatagramLog`], fed from the wire end), so it checks each `LRW` alone against
//! [`LogicalMap::expected_wkc`]: an ESC counts a logical datagram +1 if it read through a
//! read FMMU and +2 (LRW; LWR +1) if it wrote through a write FMMU that the datagram's address
//! range touches (ETG.1000.4 working-counter rules, notes `ethercat.md` §2.1). A device whose
//! window a cut falls into counts in both parts, so the sum of the parts is not the counter of
//! one whole-image `LRW`.

use std::fmt;

use crate::bus::ethercat::wire::{Command, Frame};

/// One FMMU's window in the logical address space.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FmmuWindow {
    /// Ring position of the device.
    pub device: usize,
    /// First logical byte.
    pub start: u32,
    /// Bytes.
    pub len: u32,
    /// Read FMMU (type bit 0: the device's inputs go to the master).
    pub read: bool,
    /// Write FMMU (type bit 1: outputs from the master).
    pub write: bool,
}

impl FmmuWindow {
    /// The window of an FMMU register block (0x0600 + 16 n, ETG.1000.4 table "FMMU"): logical
    /// start u32, length u16, physical start u16 at 8, type at 11 (bit 0 read, bit 1 write),
    /// activate bit 0 at 12. `None` for an inactive or empty FMMU.
    pub fn from_registers(device: usize, b: &[u8; 16]) -> Option<FmmuWindow> {
        let len = u16::from_le_bytes([b[4], b[5]]);
        if b[12] & 0x01 == 0 || len == 0 || b[11] & 0x03 == 0 {
            return None;
        }
        Some(FmmuWindow {
            device,
            start: u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
            len: u32::from(len),
            read: b[11] & 0x01 != 0,
            write: b[11] & 0x02 != 0,
        })
    }

    fn touches(&self, start: u32, len: usize) -> bool {
        let (a, b) = (u64::from(start), u64::from(start) + len as u64);
        let (s, e) = (
            u64::from(self.start),
            u64::from(self.start) + u64::from(self.len),
        );
        a < e && s < b
    }
}

/// The FMMU windows of every device of the segment.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LogicalMap {
    windows: Vec<FmmuWindow>,
}

impl LogicalMap {
    /// The map of these windows (any order).
    pub fn new(mut windows: Vec<FmmuWindow>) -> LogicalMap {
        windows.sort_by_key(|w| (w.device, w.start));
        LogicalMap { windows }
    }

    /// The lowest logical address of any window (the start of the process image).
    pub fn start(&self) -> Option<u32> {
        self.windows.iter().map(|w| w.start).min()
    }

    /// Working counter of a logical datagram `command` over `[start, start + len)`: per device
    /// +1 for a read FMMU it touches (LRD, LRW), +1 (LWR) or +2 (LRW) for a write FMMU.
    pub fn expected_wkc(&self, command: Command, start: u32, len: usize) -> u16 {
        let (reads, write_count) = match command {
            Command::Lrd => (true, 0),
            Command::Lwr => (false, 1),
            Command::Lrw => (true, 2),
            _ => return 0,
        };
        let mut wkc = 0u16;
        let mut i = 0;
        while i < self.windows.len() {
            let device = self.windows[i].device;
            let (mut r, mut w) = (false, false);
            while i < self.windows.len() && self.windows[i].device == device {
                let win = &self.windows[i];
                if win.touches(start, len) {
                    r |= win.read && reads;
                    w |= win.write && write_count > 0;
                }
                i += 1;
            }
            wkc = wkc
                .wrapping_add(u16::from(r))
                .wrapping_add(if w { write_count } else { 0 });
        }
        wkc
    }

    /// The devices a datagram over `[start, start + len)` touches, for messages.
    pub fn devices_in(&self, start: u32, len: usize) -> DeviceList {
        let mut v: Vec<usize> = self
            .windows
            .iter()
            .filter(|w| w.touches(start, len))
            .map(|w| w.device)
            .collect();
        v.dedup();
        DeviceList(v)
    }
}

/// Ring positions, shown as ranges: `devices 0–31, 40`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceList(pub Vec<usize>);

impl fmt::Display for DeviceList {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_empty() {
            return f.write_str("no device");
        }
        f.write_str(if self.0.len() == 1 {
            "device "
        } else {
            "devices "
        })?;
        let mut i = 0;
        let mut first = true;
        while i < self.0.len() {
            let mut j = i;
            while j + 1 < self.0.len() && self.0[j + 1] == self.0[j] + 1 {
                j += 1;
            }
            if !first {
                f.write_str(", ")?;
            }
            first = false;
            if j > i {
                write!(f, "{}–{}", self.0[i], self.0[j])?;
            } else {
                write!(f, "{}", self.0[i])?;
            }
            i = j + 1;
        }
        Ok(())
    }
}

/// One logical datagram seen on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LogicalDatagram {
    /// Datagram index (the master's PDU index, echoed by the devices).
    pub index: u8,
    /// LRD, LWR or LRW.
    pub command: Command,
    /// Logical start.
    pub start: u32,
    /// Data bytes.
    pub len: usize,
    /// Working counter (0 on the way out).
    pub wkc: u16,
}

/// Datagrams kept per cycle and direction; a cycle's image needs one per frame.
const LOG_CAPACITY: usize = 64;

/// The logical datagrams of the current cycle, as sent and as returned (filled by the wire end
/// while [`DatagramLog::start`] is in force; no allocation per cycle).
#[derive(Debug, Clone)]
pub struct DatagramLog {
    on: bool,
    sent: Vec<LogicalDatagram>,
    back: Vec<LogicalDatagram>,
}

impl Default for DatagramLog {
    fn default() -> Self {
        DatagramLog {
            on: false,
            sent: Vec::with_capacity(LOG_CAPACITY),
            back: Vec::with_capacity(LOG_CAPACITY),
        }
    }
}

impl DatagramLog {
    /// Start recording a cycle (clears the previous one).
    pub fn start(&mut self) {
        self.on = true;
        self.sent.clear();
        self.back.clear();
    }

    /// Stop recording.
    pub fn stop(&mut self) {
        self.on = false;
    }

    /// A frame went out (`returned` false) or came back: keep its logical datagrams.
    pub fn record(&mut self, frame: &[u8], returned: bool) {
        if !self.on {
            return;
        }
        let Ok(f) = Frame::parse(frame) else {
            return;
        };
        let list = if returned {
            &mut self.back
        } else {
            &mut self.sent
        };
        for d in f.datagrams() {
            if matches!(d.command, Command::Lrd | Command::Lwr | Command::Lrw)
                && list.len() < LOG_CAPACITY
            {
                list.push(LogicalDatagram {
                    index: d.index,
                    command: d.command,
                    start: d.address,
                    len: d.data.len(),
                    wkc: d.wkc,
                });
            }
        }
    }

    /// The datagrams sent this cycle.
    pub fn sent(&self) -> &[LogicalDatagram] {
        &self.sent
    }

    /// The datagrams that came back this cycle.
    pub fn returned(&self) -> &[LogicalDatagram] {
        &self.back
    }

    /// Check every datagram sent this cycle: it came back with the working counter of
    /// `expected(command, start, len)`. `planned` is the number of process-data datagrams a
    /// cycle has (those not sent after a loss count as not sent). The first fault, named.
    pub fn check(
        &self,
        planned: usize,
        expected: impl Fn(Command, u32, usize) -> u16,
    ) -> Result<(), DatagramFault> {
        let n = planned.max(self.sent.len());
        for (k, s) in self.sent.iter().enumerate() {
            let back = self
                .back
                .iter()
                .find(|b| b.index == s.index && b.start == s.start && b.len == s.len);
            let kind = match back {
                None => FaultKind::Lost,
                Some(b) => {
                    let want = expected(s.command, s.start, s.len);
                    if b.wkc == want {
                        continue;
                    }
                    FaultKind::Wkc {
                        got: b.wkc,
                        expected: want,
                    }
                }
            };
            return Err(DatagramFault {
                number: k + 1,
                of: n,
                datagram: *s,
                kind,
                devices: DeviceList(Vec::new()),
            });
        }
        if self.sent.len() < planned {
            return Err(DatagramFault {
                number: self.sent.len() + 1,
                of: n,
                datagram: LogicalDatagram {
                    index: 0,
                    command: Command::Lrw,
                    start: 0,
                    len: 0,
                    wkc: 0,
                },
                kind: FaultKind::NotSent,
                devices: DeviceList(Vec::new()),
            });
        }
        Ok(())
    }
}

/// What went wrong with a datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// It went out and did not come back.
    Lost,
    /// It came back with another working counter.
    Wkc {
        /// Returned.
        got: u16,
        /// What the devices' FMMUs call for.
        expected: u16,
    },
    /// It was not sent (the cycle ended before).
    NotSent,
}

/// A process-data datagram of a cycle that failed ([`DatagramLog::check`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DatagramFault {
    /// 1-based number of the datagram in the cycle.
    pub number: usize,
    /// Process-data datagrams per cycle.
    pub of: usize,
    /// The datagram as sent.
    pub datagram: LogicalDatagram,
    /// What happened.
    pub kind: FaultKind,
    /// The devices whose FMMU windows it covers (filled by the caller, which has the map).
    pub devices: DeviceList,
}

impl fmt::Display for DatagramFault {
    /// `LRW datagram 2 of 3 (logical 0x000005BA..0x00000A07, 1102 bytes, devices 40–96):
    /// working counter 121, expected 122`
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let d = &self.datagram;
        if self.kind == FaultKind::NotSent {
            return write!(
                f,
                "process-data datagram {} of {}: not sent (the cycle ended before)",
                self.number, self.of
            );
        }
        let end = u64::from(d.start) + d.len as u64;
        write!(
            f,
            "{} datagram {} of {} (logical {:#010x}..{:#010x}, {} bytes, {})",
            d.command.name(),
            self.number,
            self.of,
            d.start,
            end,
            d.len,
            self.devices
        )?;
        match self.kind {
            FaultKind::Lost => f.write_str(": lost, its frame did not come back"),
            FaultKind::Wkc { got, expected } => {
                write!(f, ": working counter {got}, expected {expected}")
            }
            FaultKind::NotSent => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::ethercat::wire::{Datagram, FrameBuilder};

    /// Two devices: inputs 0..4 / 4..8, outputs 8..10 / 10..12 (ethercrab's layout).
    fn map() -> LogicalMap {
        let w = |device, start, len, read| FmmuWindow {
            device,
            start,
            len,
            read,
            write: !read,
        };
        LogicalMap::new(vec![
            w(1, 10, 2, false),
            w(0, 0, 4, true),
            w(1, 4, 4, true),
            w(0, 8, 2, false),
        ])
    }

    #[test]
    fn expected_wkc_per_part() {
        let m = map();
        assert_eq!(m.expected_wkc(Command::Lrw, 0, 12), 6);
        assert_eq!(m.expected_wkc(Command::Lrw, 0, 4), 1);
        assert_eq!(
            m.expected_wkc(Command::Lrw, 3, 2),
            2,
            "a cut inside both inputs"
        );
        assert_eq!(
            m.expected_wkc(Command::Lrw, 4, 5),
            3,
            "inputs of 1, outputs of 0"
        );
        assert_eq!(m.expected_wkc(Command::Lrw, 9, 3), 4);
        assert_eq!(m.expected_wkc(Command::Lrd, 0, 12), 2);
        assert_eq!(m.expected_wkc(Command::Lwr, 0, 12), 2);
        assert_eq!(m.expected_wkc(Command::Lrw, 12, 100), 0);
        assert_eq!(m.expected_wkc(Command::Fprd, 0, 12), 0);
        assert_eq!(m.devices_in(3, 6).to_string(), "devices 0–1");
        assert_eq!(m.devices_in(10, 2).to_string(), "device 1");
        assert_eq!(
            DeviceList(vec![0, 1, 2, 5, 7, 8]).to_string(),
            "devices 0–2, 5, 7–8"
        );
    }

    #[test]
    fn fmmu_registers() {
        let mut b = [0u8; 16];
        b[..4].copy_from_slice(&0x40u32.to_le_bytes());
        b[4] = 6;
        b[11] = 1;
        b[12] = 1;
        let w = FmmuWindow::from_registers(3, &b).unwrap();
        assert_eq!(
            (w.device, w.start, w.len, w.read, w.write),
            (3, 0x40, 6, true, false)
        );
        b[12] = 0;
        assert!(FmmuWindow::from_registers(3, &b).is_none());
    }

    fn frame(dgs: &[(u8, u32, usize, u16)]) -> Vec<u8> {
        let mut b = FrameBuilder::new([0xFF; 6], [0x10; 6]);
        let data = vec![0u8; 2000];
        for (idx, a, n, wkc) in dgs {
            let mut d = Datagram::new(Command::Lrw, *idx, *a, &data[..*n]);
            d.wkc = *wkc;
            b.push(&d).unwrap();
        }
        b.build()
    }

    #[test]
    fn log_names_lost_and_miscounted_parts() {
        let m = map();
        let want = |c, a, n| m.expected_wkc(c, a, n);
        let mut log = DatagramLog::default();
        log.record(&frame(&[(1, 0, 6, 0)]), false);
        assert!(log.sent().is_empty(), "not recording");
        log.start();
        log.record(&frame(&[(1, 0, 6, 0)]), false);
        log.record(&frame(&[(1, 0, 6, 2)]), true);
        log.record(&frame(&[(2, 6, 6, 0)]), false);
        // Part 2: the inputs of device 1 (+1), the outputs of both (+2 each).
        log.record(&frame(&[(2, 6, 6, 5)]), true);
        assert_eq!(log.check(2, want), Ok(()));
        // The second part one short.
        log.start();
        log.record(&frame(&[(3, 0, 6, 0)]), false);
        log.record(&frame(&[(3, 0, 6, 2)]), true);
        log.record(&frame(&[(4, 6, 6, 0)]), false);
        log.record(&frame(&[(4, 6, 6, 4)]), true);
        let e = log.check(2, want).unwrap_err();
        assert_eq!((e.number, e.of), (2, 2));
        assert_eq!(
            e.kind,
            FaultKind::Wkc {
                got: 4,
                expected: 5
            }
        );
        // The first part lost: the second was never sent.
        log.start();
        log.record(&frame(&[(5, 0, 6, 0)]), false);
        let mut e = log.check(2, want).unwrap_err();
        assert_eq!((e.number, e.of, e.kind), (1, 2, FaultKind::Lost));
        e.devices = m.devices_in(e.datagram.start, e.datagram.len);
        assert_eq!(
            e.to_string(),
            "LRW datagram 1 of 2 (logical 0x00000000..0x00000006, 6 bytes, devices 0–1): lost, its frame did not come back"
        );
        // A stale reply of another cycle (other index) does not count.
        log.start();
        log.record(&frame(&[(7, 0, 6, 0)]), false);
        log.record(&frame(&[(5, 0, 6, 2)]), true);
        assert_eq!(log.check(1, want).unwrap_err().kind, FaultKind::Lost);
        // Nothing sent at all.
        log.start();
        assert_eq!(log.check(2, want).unwrap_err().kind, FaultKind::NotSent);
    }
}
