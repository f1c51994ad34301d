//! An emulated EtherCAT segment: an [`EscChain`] behind a frame-level entry point.
//!
//! [`Segment::process_frame`] does to an Ethernet frame what the ring of devices does on the
//! wire: every datagram passes all devices in ring order (address field updated, data read or
//! written in place, working counter incremented per the ESC rules of [`super::Esc::process`]),
//! the datagram IRQ field is ORed with the devices' event requests, and the source MAC gets its
//! U/L bit set (`frame[6] |= 0x02`) like the first device does, so a master recognises the frame
//! as returned (notes `ethercat.md` §1.1, §2.1).

use super::{Esc, EscChain};
use crate::bus::ethercat::wire::{self, WireError};

/// An emulated segment: devices in ring order plus a frame-level entry point.
#[derive(Debug)]
pub struct Segment {
    /// The devices, position 0 (nearest the master) first.
    pub chain: EscChain,
    /// Number of frames processed so far.
    pub frames: u64,
    /// Number of datagrams processed so far.
    pub datagrams: u64,
}

impl Segment {
    /// Segment of `escs` in a line, `hop_delay_ns` forwarding delay between neighbours.
    pub fn new(escs: Vec<Esc>, hop_delay_ns: u64) -> Self {
        Self::from_chain(EscChain::new(escs, hop_delay_ns))
    }

    /// Segment around an existing chain.
    pub fn from_chain(chain: EscChain) -> Self {
        Self {
            chain,
            frames: 0,
            datagrams: 0,
        }
    }

    /// Number of devices.
    pub fn len(&self) -> usize {
        self.chain.escs.len()
    }

    /// `true` if the segment has no devices.
    pub fn is_empty(&self) -> bool {
        self.chain.escs.is_empty()
    }

    /// Device at ring position `pos`.
    pub fn esc(&self, pos: usize) -> Option<&Esc> {
        self.chain.escs.get(pos)
    }

    /// Device at ring position `pos`, mutable.
    pub fn esc_mut(&mut self, pos: usize) -> Option<&mut Esc> {
        self.chain.escs.get_mut(pos)
    }

    /// Run every datagram of the Ethernet frame `frame` through the devices in place and mark
    /// the frame processed (U/L bit of the source MAC). `now_ns` is the simulation time the
    /// frame reaches the first device.
    ///
    /// An invalid frame (not EtherCAT, truncated, inconsistent lengths) is left unchanged and
    /// reported as an error — a real segment would drop it.
    pub fn process_frame(&mut self, frame: &mut [u8], now_ns: u64) -> Result<(), WireError> {
        let chain = &mut self.chain;
        let count = wire::for_each_datagram_mut(frame, |mut dg| {
            let cmd = dg.command().code();
            let raw_addr = dg.address();
            let mut wkc = dg.wkc();
            let new_addr = chain.process_raw(cmd, raw_addr, dg.data_mut(), &mut wkc, now_ns);
            dg.set_address(new_addr);
            dg.set_wkc(wkc);
            let irq = dg.irq() | chain.irq();
            dg.set_irq(irq);
        })?;
        wire::mark_processed(frame);
        self.frames += 1;
        self.datagrams += count as u64;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::ethercat::wire::{physical_address, Command, Frame, FrameBuilder};
    use crate::sim::esc::{EscConfig, NullApp};

    const SRC: [u8; 6] = [0x10; 6];

    fn segment(n: usize) -> Segment {
        let escs = (0..n)
            .map(|_| Esc::new(EscConfig::default(), Box::new(NullApp)))
            .collect();
        Segment::new(escs, 100)
    }

    fn frame(dgs: &[(Command, u32, Vec<u8>)]) -> Vec<u8> {
        let mut b = FrameBuilder::new([0xFF; 6], SRC);
        for (i, (c, a, d)) in dgs.iter().enumerate() {
            b.push_command(*c, i as u8, *a, d).unwrap();
        }
        b.build()
    }

    fn wkcs(f: &[u8]) -> Vec<u16> {
        Frame::parse(f)
            .unwrap()
            .datagrams()
            .map(|d| d.wkc)
            .collect()
    }

    #[test]
    fn brd_type_counts_all_devices_and_marks_frame() {
        let mut seg = segment(3);
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![3]);
        let p = Frame::parse(&f).unwrap();
        let dg = p.datagrams().next().unwrap();
        assert_eq!(dg.data, &[0x11]); // ET1100 type ORed
        assert_eq!(dg.adp(), 3); // ADP incremented by every device
        assert_eq!(f[6], 0x12);
        assert_eq!(seg.frames, 1);
        assert_eq!(seg.datagrams, 1);
    }

    #[test]
    fn several_datagrams_in_one_frame() {
        let mut seg = segment(3);
        // APWR station address of position 1, then FPRD it back, then BWR AL control.
        let mut f = frame(&[
            (
                Command::Apwr,
                physical_address(0u16.wrapping_sub(1), 0x0010),
                vec![0x01, 0x10],
            ),
            (Command::Fprd, physical_address(0x1001, 0x0010), vec![0, 0]),
            (Command::Bwr, physical_address(0, 0x0120), vec![0x11, 0x00]),
            (Command::Fprd, physical_address(0x4242, 0x0010), vec![0, 0]),
        ]);
        seg.process_frame(&mut f, 1_000).unwrap();
        assert_eq!(wkcs(&f), vec![1, 1, 3, 0]);
        let p = Frame::parse(&f).unwrap();
        let dgs: Vec<_> = p.datagrams().collect();
        assert_eq!(dgs[1].data, &[0x01, 0x10]);
        assert_eq!(seg.esc(1).unwrap().station_address(), 0x1001);
        assert_eq!(seg.esc(0).unwrap().station_address(), 0);
        assert_eq!(seg.datagrams, 4);
    }

    #[test]
    fn existing_wkc_is_added_to() {
        let mut seg = segment(2);
        let mut b = FrameBuilder::new([0xFF; 6], SRC);
        let mut dg = wire::Datagram::new(Command::Brd, 0, 0, &[0]);
        dg.wkc = 5;
        b.push(&dg).unwrap();
        let mut f = b.build();
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![7]);
    }

    #[test]
    fn invalid_frame_is_rejected_unchanged() {
        let mut seg = segment(1);
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        f[12] = 0x08;
        f[13] = 0x00; // IPv4 EtherType
        let before = f.clone();
        assert!(seg.process_frame(&mut f, 0).is_err());
        assert_eq!(f, before);
        assert_eq!(seg.frames, 0);
        let mut short = vec![0u8; 10];
        assert!(seg.process_frame(&mut short, 0).is_err());
    }

    #[test]
    fn empty_segment_passes_frames() {
        let mut seg = segment(0);
        assert!(seg.is_empty());
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![0]);
    }
}
