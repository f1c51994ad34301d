//! The frames of one process-data cycle and the time they take on the wire.
//!
//! [`CyclePlan::ethercrab`] lays out the frames ethercrab 0.7.1 sends per cycle
//! (`SubDeviceGroup::tx_rx` / `tx_rx_dc`, `subdevice_group/mod.rs`; notes `ethercat.md` §2):
//! with DC the first frame starts with `FRMW 0x0910` (8 bytes, the reference clock's system
//! time); then the process image goes out as one `LRW` per frame, each filling the rest of its
//! frame; the room left in the frame after the last part takes the `FPRD 0x0130` AL status
//! checks (one per SubDevice, 2 bytes each), further frames the remaining checks. ethercrab sends
//! one frame and waits for it to come back before it builds the next.
//!
//! [`CyclePlan::wire_time`] is the time that takes at 100 Mbit/s (80 ns per byte, IEEE 802.3
//! 100BASE-TX): every frame with its Ethernet overhead (preamble and start delimiter 8 bytes,
//! FCS 4, inter-frame gap 12; at least the 64-byte minimum frame), plus, per frame, the time
//! the frame needs through the devices and back ([`DEVICE_DELAY_NS`] per device).

use std::fmt;

/// Nanoseconds per byte at 100 Mbit/s.
pub const NS_PER_BYTE: u64 = 80;
/// Preamble (7) and start frame delimiter (1), IEEE 802.3 §3.1.
pub const PREAMBLE_SFD: usize = 8;
/// Frame check sequence.
pub const FCS: usize = 4;
/// Inter-frame gap: 96 bit times.
pub const INTER_FRAME_GAP: usize = 12;
/// Shortest Ethernet frame without FCS (shorter ones are padded).
pub const MIN_FRAME: usize = 60;
/// Ethernet header (14) + EtherCAT frame header (2).
pub const FRAME_HEADERS: usize = 16;
/// Datagram header (10) + working counter (2).
pub const DATAGRAM_OVERHEAD: usize = 12;
/// `FRMW 0x0910`, 8 bytes of system time.
pub const DC_DATAGRAM: usize = DATAGRAM_OVERHEAD + 8;
/// `FPRD 0x0130`, 2 bytes of AL status.
pub const STATE_CHECK_DATAGRAM: usize = DATAGRAM_OVERHEAD + 2;
/// ethercrab pushes at most this many state checks into one frame (`push_state_checks`).
const MAX_CHECKS_PER_FRAME: usize = 129;

/// The time one frame needs through one device and back, ns: 1 µs.
///
/// Beckhoff, *EtherCAT Slave Controller — Technology* (Section I), §9.4 "Communication
/// timing": the delay time of the EtherCAT devices to transfer data is "approx. 1 µs with
/// 100BASE-TX, plus line delay of approx. 5 ns per m"; the EK1101 coupler's technical data give
/// "propagation delay 1 µs typ." (infosys `ek110x_ek15xx/8735943691.html`). E-bus terminals
/// (EL…) forward faster (no PHYs), so for a line of terminals the figure is on the safe side;
/// cable runs (5 ns per m) are not counted.
pub const DEVICE_DELAY_NS: u64 = 1_000;

/// The time an Ethernet frame of `frame_len` bytes (without FCS) takes on the wire at 100
/// Mbit/s: padded to [`MIN_FRAME`], with preamble, FCS and inter-frame gap.
pub fn frame_wire_ns(frame_len: usize) -> u64 {
    let bytes = frame_len.max(MIN_FRAME) + PREAMBLE_SFD + FCS + INTER_FRAME_GAP;
    (bytes as u64).saturating_mul(NS_PER_BYTE)
}

/// One frame of a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PlannedFrame {
    /// It starts with the DC `FRMW`.
    pub dc: bool,
    /// The part of the process image it carries: (logical start, bytes).
    pub lrw: Option<(u32, usize)>,
    /// AL status checks in it.
    pub state_checks: usize,
    /// Datagram bytes (the EtherCAT payload).
    pub payload: usize,
}

impl PlannedFrame {
    /// The Ethernet frame without FCS, padded to the minimum.
    pub fn frame_len(&self) -> usize {
        (FRAME_HEADERS + self.payload).max(MIN_FRAME)
    }

    /// Bytes on the wire: the frame, preamble, FCS and inter-frame gap.
    pub fn wire_bytes(&self) -> usize {
        self.frame_len() + PREAMBLE_SFD + FCS + INTER_FRAME_GAP
    }
}

/// The frames of one cycle (see the module documentation).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct CyclePlan {
    /// The frames in the order they are sent.
    pub frames: Vec<PlannedFrame>,
    /// SubDevices on the segment.
    pub devices: usize,
}

impl CyclePlan {
    /// The frames ethercrab 0.7.1 sends per cycle for a process image of `pdi_len` bytes at
    /// logical `pdi_start`, `devices` SubDevices, with (`dc`) or without DC, in frames of
    /// `payload_capacity` datagram bytes.
    pub fn ethercrab(
        pdi_start: u32,
        pdi_len: usize,
        devices: usize,
        dc: bool,
        payload_capacity: usize,
    ) -> CyclePlan {
        let mut frames = Vec::new();
        let (mut sent, mut checks) = (0usize, 0usize);
        loop {
            let mut f = PlannedFrame {
                dc: dc && frames.is_empty(),
                lrw: None,
                state_checks: 0,
                payload: 0,
            };
            if f.dc {
                f.payload += DC_DATAGRAM;
            }
            let rest = pdi_len - sent;
            let room = payload_capacity
                .saturating_sub(f.payload)
                .saturating_sub(DATAGRAM_OVERHEAD);
            if rest > 0 && room > 0 {
                let n = rest.min(room);
                // Logical addresses are 32 bits; an image is far smaller.
                f.lrw = Some((pdi_start.wrapping_add(sent as u32), n));
                f.payload += DATAGRAM_OVERHEAD + n;
                sent += n;
            }
            while checks < devices
                && f.payload + STATE_CHECK_DATAGRAM <= payload_capacity
                && f.state_checks < MAX_CHECKS_PER_FRAME
            {
                f.payload += STATE_CHECK_DATAGRAM;
                f.state_checks += 1;
                checks += 1;
            }
            if f.payload == 0 {
                break;
            }
            frames.push(f);
            if sent == pdi_len && checks >= devices {
                break;
            }
            if f.lrw.is_none() && f.state_checks == 0 {
                // A frame that takes nothing but the DC datagram (no room): nothing more fits.
                break;
            }
        }
        CyclePlan { frames, devices }
    }

    /// The process-data datagrams in order: (index of the frame, logical start, bytes).
    pub fn lrw_datagrams(&self) -> impl Iterator<Item = (usize, u32, usize)> + '_ {
        self.frames
            .iter()
            .enumerate()
            .filter_map(|(i, f)| f.lrw.map(|(a, n)| (i, a, n)))
    }

    /// Number of process-data datagrams.
    pub fn lrw_count(&self) -> usize {
        self.frames.iter().filter(|f| f.lrw.is_some()).count()
    }

    /// The wire time of the cycle at 100 Mbit/s (module documentation).
    pub fn wire_time(&self) -> WireTime {
        let bytes: usize = self.frames.iter().map(PlannedFrame::wire_bytes).sum();
        let frames = self.frames.len();
        let transmit_ns = bytes as u64 * NS_PER_BYTE;
        let forwarding_ns = frames as u64 * self.devices as u64 * DEVICE_DELAY_NS;
        WireTime {
            frames,
            devices: self.devices,
            bytes,
            transmit_ns,
            forwarding_ns,
        }
    }
}

/// The wire time of one cycle ([`CyclePlan::wire_time`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WireTime {
    /// Frames per cycle.
    pub frames: usize,
    /// SubDevices each frame passes.
    pub devices: usize,
    /// Bytes on the wire, Ethernet overhead included.
    pub bytes: usize,
    /// Transmission of those bytes at 100 Mbit/s, ns.
    pub transmit_ns: u64,
    /// Frames × devices × [`DEVICE_DELAY_NS`], ns.
    pub forwarding_ns: u64,
}

impl WireTime {
    /// Transmission and forwarding, ns.
    pub fn total_ns(&self) -> u64 {
        self.transmit_ns + self.forwarding_ns
    }

    /// The shortest cycle time the wire carries, whole µs.
    pub fn shortest_cycle_us(&self) -> u64 {
        self.total_ns().div_ceil(1000)
    }
}

impl fmt::Display for WireTime {
    /// `612.3 µs (3 frames, 4152 bytes at 100 Mbit/s = 332.2 µs, 3 × 97 devices × 1 µs
    /// forwarding = 291.0 µs)`
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:.1} µs ({} frame{}, {} bytes at 100 Mbit/s incl. preamble, FCS and inter-frame gap = {:.1} µs, {} × {} device{} × {} µs forwarding = {:.1} µs)",
            self.total_ns() as f64 / 1000.0,
            self.frames,
            if self.frames == 1 { "" } else { "s" },
            self.bytes,
            self.transmit_ns as f64 / 1000.0,
            self.frames,
            self.devices,
            if self.devices == 1 { "" } else { "s" },
            DEVICE_DELAY_NS as f64 / 1000.0,
            self.forwarding_ns as f64 / 1000.0,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CAP: usize = 1498;

    #[test]
    fn small_image_fits_one_frame_with_the_checks() {
        // 4 devices, 120 bytes, DC: FRMW 20 + LRW 132 + 4 × 14.
        let p = CyclePlan::ethercrab(0, 120, 4, true, CAP);
        assert_eq!(p.frames.len(), 1);
        assert_eq!(
            p.frames[0],
            PlannedFrame {
                dc: true,
                lrw: Some((0, 120)),
                state_checks: 4,
                payload: 20 + 132 + 56
            }
        );
        // 16 + 208 = 224 bytes + 24 overhead = 248 bytes × 80 ns; 1 × 4 µs forwarding.
        let w = p.wire_time();
        assert_eq!(
            (w.bytes, w.transmit_ns, w.forwarding_ns),
            (248, 19_840, 4_000)
        );
        // A tiny frame is padded to the minimum.
        let p = CyclePlan::ethercrab(0, 0, 1, false, CAP);
        assert_eq!(p.frames[0].frame_len(), 60);
        assert_eq!(p.wire_time().bytes, 84);
    }

    #[test]
    fn large_image_fills_frames_then_the_checks_follow() {
        // 2568 bytes, 97 devices, DC.
        let p = CyclePlan::ethercrab(0, 2568, 97, true, CAP);
        let lrw: Vec<_> = p.lrw_datagrams().collect();
        assert_eq!(lrw, vec![(0, 0, 1466), (1, 1466, 1102)]);
        // Frame 1: 12 + 1102 = 1114 bytes, 384 left = 27 checks; the other 70 in frame 2.
        assert_eq!(p.frames[1].state_checks, 27);
        assert_eq!(p.frames[2].state_checks, 70);
        assert_eq!(p.frames.len(), 3);
        assert!(p.frames.iter().all(|f| f.payload <= CAP));
        let checks: usize = p.frames.iter().map(|f| f.state_checks).sum();
        assert_eq!(checks, 97);
        // Without DC the first part is 20 bytes longer.
        let p = CyclePlan::ethercrab(0, 2568, 97, false, CAP);
        assert_eq!(p.lrw_datagrams().next(), Some((0, 0, 1486)));
    }

    #[test]
    fn every_image_length_is_covered_once() {
        for len in (0..5000).step_by(7) {
            for devices in [0, 1, 97, 200] {
                let p = CyclePlan::ethercrab(0x100, len, devices, true, CAP);
                let mut next = 0x100u32;
                for (_, a, n) in p.lrw_datagrams() {
                    assert_eq!(a, next);
                    next += n as u32;
                }
                assert_eq!(next - 0x100, len as u32);
                assert_eq!(
                    p.frames.iter().map(|f| f.state_checks).sum::<usize>(),
                    devices
                );
            }
        }
    }
}
