//! EtherCAT frames into the emulated segment of the `ethercat-emu` link / `sim ethercat`
//! (coupler, CiA 402 servo with a CoE server, SERCOS drive with an SoE server), brought to
//! PRE-OP first so the mailboxes are live. The script mixes raw frames, mailbox messages
//! (CoE / SoE / anything, valid headers or not), read-mailbox fetches, register reads and
//! writes (AL control, SMs, FMMUs, DC), and time steps with SYNC0.
//! Must hold: no panic; a processed frame keeps its length; a fetched reply carries a mailbox
//! header whose length fits the read mailbox.
#![no_main]
use fieldprobe::bus::ethercat::wire::{physical_address, Command, MailboxHeader, MailboxType};
use fieldprobe::sim::esc::segment::Segment;
use fieldprobe_fuzz::ecat::{bring_up, datagram, mailbox_message, segment, station};
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

/// A freshly built segment brought to PRE-OP.
fn fresh() -> (Segment, Vec<Option<fieldprobe::sim::esc::MailboxConfig>>) {
    let mut seg = segment();
    let mbx = bring_up(&mut seg);
    (seg, mbx)
}

fuzz_target!(|data: &[u8]| {
    let (mut seg, mbx) = fresh();
    let n = seg.len();
    let mut b = Bytes::new(data);
    let mut now: u64 = 1_000_000;
    let mut steps = 0;
    while !b.is_empty() && steps < 2048 {
        steps += 1;
        let op = b.u8();
        let pos = usize::from(b.u8()) % n;
        let st = station(pos);
        match op % 8 {
            // A raw frame.
            0 => {
                let len = usize::from(b.u16()) % 1600;
                let mut frame = b.take(len).to_vec();
                let before = frame.len();
                let _ = seg.process_frame(&mut frame, now);
                assert_eq!(frame.len(), before, "frame length changed");
            }
            // A mailbox message with a valid header (CoE, SoE or any type).
            1 | 2 => {
                let Some(m) = mbx[pos] else { continue };
                let ty = match op >> 6 {
                    0 => MailboxType::Coe,
                    1 => MailboxType::Soe,
                    _ => MailboxType::from(b.u8() & 0x0F),
                };
                let counter = b.u8() & 7;
                let body = b.take_len16(usize::from(m.rx_size)).to_vec();
                let msg = mailbox_message(ty, counter, &body, usize::from(m.rx_size));
                let _ = datagram(
                    &mut seg,
                    Command::Fpwr,
                    physical_address(st, m.rx_offset),
                    &msg,
                    now,
                );
            }
            // Raw bytes into the write mailbox (any length).
            3 => {
                let Some(m) = mbx[pos] else { continue };
                let msg = b.take_len16(1400).to_vec();
                let _ = datagram(
                    &mut seg,
                    Command::Fpwr,
                    physical_address(st, m.rx_offset),
                    &msg,
                    now,
                );
            }
            // Fetch the read mailbox.
            4 => {
                let Some(m) = mbx[pos] else { continue };
                let size = usize::from(m.tx_size);
                if let Some((wkc, reply)) = datagram(
                    &mut seg,
                    Command::Fprd,
                    physical_address(st, m.tx_offset),
                    &vec![0; size],
                    now,
                ) {
                    if wkc == 1 {
                        if let Ok((h, _)) = MailboxHeader::parse(&reply) {
                            assert!(
                                usize::from(h.length) + MailboxHeader::LEN <= size,
                                "device {pos} replied with length {} in a {size}-byte mailbox",
                                h.length
                            );
                        }
                    }
                }
            }
            // Register write (AL control, SM, FMMU, DC, ...).
            5 => {
                let ado = b.u16();
                let d = b.chunk().to_vec();
                let _ = datagram(&mut seg, Command::Fpwr, physical_address(st, ado), &d, now);
            }
            // Any datagram: command, address, data.
            6 => {
                let cmd = Command::from(b.u8() % 16);
                let addr = b.u32();
                let d = b.chunk().to_vec();
                let _ = datagram(&mut seg, cmd, addr, &d, now);
            }
            // Time passes; SYNC0 (the link runs it after every exchange).
            _ => {
                now += u64::from(b.u16()) * 1000;
                seg.sync0(fieldprobe::units::Nanos(now));
            }
        }
    }
});
