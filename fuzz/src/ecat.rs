//! EtherCAT harnesses: the emulated segment of the `ethercat-emu` link (coupler, CiA 402
//! servo with CoE, SERCOS drive with SoE) brought to PRE-OP, and an ethercrab MainDevice
//! pumped in the calling thread against a scripted hostile device (for the CoE / SoE clients).

use std::cell::RefCell;
use std::future::Future;
use std::sync::Arc;
use std::task::{Context, Poll, Waker};

use ethercrab::{MainDevice, MainDeviceConfig, PduRx, PduStorage, PduTx, Timeouts};
use fieldprobe::bus::ethercat::wire::{
    self, physical_address, Command, Frame, FrameBuilder, MailboxHeader, MailboxType,
};
use fieldprobe::drive::catalogue;
use fieldprobe::link::ethercat::{emulated_segment, EthercatSpec};
use fieldprobe::sim::esc::segment::Segment;
use fieldprobe::sim::esc::{reg, AlState, MailboxConfig};
use fieldprobe::units::Nanos;

/// Ring position of the CoE servo (0 is the coupler).
pub const COE_POS: usize = 1;
/// Ring position of the SoE drive.
pub const SOE_POS: usize = 2;

/// Configured station address of ring position `pos`.
pub fn station(pos: usize) -> u16 {
    0x1001 + pos as u16
}

/// The segment `fieldprobe run --link ethercat-emu` plays for a CiA 402 and a SERCOS axis.
pub fn segment() -> Segment {
    let drives = ["cia402-generic", "sercos-ax5000"]
        .iter()
        .map(|n| Arc::new(catalogue::builtin(n).expect("built-in drive")))
        .collect();
    let spec = EthercatSpec {
        drives,
        cycle: Nanos(1_000_000),
        pcap: None,
        ..EthercatSpec::default()
    };
    emulated_segment(&spec).expect("emulated segment")
}

/// One datagram through the segment; returns (WKC, data after the ring), or `None` when the
/// segment refused the frame.
pub fn datagram(
    seg: &mut Segment,
    cmd: Command,
    address: u32,
    data: &[u8],
    now: u64,
) -> Option<(u16, Vec<u8>)> {
    let mut b = FrameBuilder::new([0xFF; 6], [0x02, 0, 0, 0, 0, 0x01]);
    b.push_command(cmd, 0x42, address, data).ok()?;
    let mut frame = b.build();
    seg.process_frame(&mut frame, now).ok()?;
    let f = Frame::parse(&frame).ok()?;
    let dg = f.datagrams().next()?;
    Some((dg.wkc, dg.data.to_vec()))
}

/// SyncManager register block (0x0800 + 8n): start, length, control, status, activate, PDI.
pub fn sm_bytes(start: u16, len: u16, control: u8) -> [u8; 8] {
    let s = start.to_le_bytes();
    let l = len.to_le_bytes();
    [s[0], s[1], l[0], l[1], control, 0, 1, 0]
}

/// Station addresses, mailbox SMs per the SII, AL control PRE-OP for every device; returns
/// each position's mailbox configuration. Panics if a device does not reach PRE-OP (the
/// harness would be broken, not the code under test).
pub fn bring_up(seg: &mut Segment) -> Vec<Option<MailboxConfig>> {
    let n = seg.len();
    let mut mbx = Vec::new();
    for pos in 0..n {
        let adp = 0u16.wrapping_sub(pos as u16);
        datagram(
            seg,
            Command::Apwr,
            physical_address(adp, reg::STATION_ADDRESS),
            &station(pos).to_le_bytes(),
            0,
        )
        .expect("station address");
        let cfg = seg.esc(pos).expect("device").config().mailbox;
        let st = station(pos);
        if let Some(m) = cfg {
            for (i, (start, len, ctrl)) in [
                (m.rx_offset, m.rx_size, 0x26),
                (m.tx_offset, m.tx_size, 0x22),
            ]
            .into_iter()
            .enumerate()
            {
                datagram(
                    seg,
                    Command::Fpwr,
                    physical_address(st, 0x0800 + 8 * i as u16),
                    &sm_bytes(start, len, ctrl),
                    0,
                )
                .expect("SM config");
            }
        }
        datagram(
            seg,
            Command::Fpwr,
            physical_address(st, reg::AL_CONTROL),
            &[0x02, 0],
            0,
        )
        .expect("AL control");
        assert_eq!(
            seg.esc(pos).expect("device").al_state(),
            AlState::PreOp,
            "device {pos} did not reach PRE-OP"
        );
        mbx.push(cfg);
    }
    mbx
}

/// A mailbox message: header (type, counter) + body, padded to `size`.
pub fn mailbox_message(ty: MailboxType, counter: u8, body: &[u8], size: usize) -> Vec<u8> {
    let hdr = MailboxHeader {
        length: body.len() as u16,
        address: 0,
        channel: 0,
        priority: 0,
        mailbox_type: ty,
        counter,
    };
    let mut m = hdr.encode().to_vec();
    m.extend_from_slice(body);
    m.resize(size.max(m.len()), 0);
    m
}

// ------------------------------------------------------------------------------------------
// ethercrab against a scripted device

const MAX_FRAMES: usize = 16;
const MAX_PDU_DATA: usize = PduStorage::element_size(1100);

static STORAGE: PduStorage<MAX_FRAMES, MAX_PDU_DATA> = PduStorage::new();

thread_local! {
    static MD: std::cell::Cell<Option<&'static MainDevice<'static>>> = const { std::cell::Cell::new(None) };
    static PDU_LOOP: RefCell<Option<(PduTx<'static>, PduRx<'static>)>> = const { RefCell::new(None) };
}

/// The process's ethercrab MainDevice (created on first use; no SubDevices are initialised,
/// only raw commands are used). Its frames travel only through [`run`].
pub fn main_device() -> &'static MainDevice<'static> {
    if let Some(md) = MD.with(|m| m.get()) {
        return md;
    }
    let (tx, rx, pdu_loop) = STORAGE.try_split().expect("PDU storage splits once");
    let md: &'static MainDevice<'static> = Box::leak(Box::new(MainDevice::new(
        pdu_loop,
        Timeouts::default(),
        MainDeviceConfig::default(),
    )));
    PDU_LOOP.with(|l| *l.borrow_mut() = Some((tx, rx)));
    MD.with(|m| m.set(Some(md)));
    md
}

/// What a scripted device answers to one datagram: the read data are written into `data`,
/// the returned WKC is set.
pub trait Responder {
    /// Answer datagram `cmd` at `ado` of station `adp`.
    fn respond(&mut self, cmd: Command, adp: u16, ado: u16, data: &mut [u8]) -> u16;
}

/// Run `fut` (which uses [`main_device`]) to completion in this thread, carrying every frame it
/// sends to `device` and back. Returns `None` when the future stalls (pending with nothing to
/// send for `max_idle` polls in a row) or exceeds `max_frames` frames.
pub fn run<F: Future>(
    fut: F,
    device: &mut dyn Responder,
    max_frames: usize,
) -> Result<F::Output, &'static str> {
    main_device();
    let mut fut = Box::pin(fut);
    let waker = Waker::noop();
    let mut cx = Context::from_waker(waker);
    let mut frames = 0usize;
    let mut idle = 0u32;
    PDU_LOOP.with(|l| {
        let mut l = l.borrow_mut();
        let (tx, rx) = l.as_mut().expect("PDU loop");
        loop {
            if let Poll::Ready(v) = fut.as_mut().poll(&mut cx) {
                return Ok(v);
            }
            let mut sent = false;
            while let Some(frame) = tx.next_sendable_frame() {
                sent = true;
                frames += 1;
                if frames > max_frames {
                    return Err("too many frames");
                }
                let mut buf = Vec::with_capacity(1514);
                frame
                    .send_blocking(|b| {
                        buf.extend_from_slice(b);
                        Ok(b.len())
                    })
                    .map_err(|_| "send_blocking")?;
                let _ = wire::for_each_datagram_mut(&mut buf, |mut dg| {
                    let cmd = dg.command();
                    let (adp, ado) = (dg.adp(), dg.ado());
                    let wkc = device.respond(cmd, adp, ado, dg.data_mut());
                    dg.set_wkc(wkc);
                });
                wire::mark_processed(&mut buf);
                let _ = rx.receive_frame(&buf);
            }
            if sent {
                idle = 0;
            } else {
                idle += 1;
                if idle > 100_000 {
                    return Err("stalled");
                }
                std::thread::yield_now();
            }
        }
    })
}

/// A device whose read mailbox holds whatever the fuzz script says: every datagram to its
/// station is answered (WKC 1 unless the script says otherwise), SM0 is always free, and SM1
/// is full while a reply is pending (after each mailbox write, and again when the script says
/// "more") or when the script asks for an unsolicited message. Once the script is used up the
/// read mailbox holds a mailbox error reply, so every client wait ends without a clock.
#[derive(Debug)]
pub struct HostileMailbox<'a> {
    script: crate::Bytes<'a>,
    station: u16,
    mbx_out: (u16, u16),
    mbx_in: (u16, u16),
    pending: bool,
    /// Mailbox writes seen (requests of the client).
    pub writes: usize,
}

impl<'a> HostileMailbox<'a> {
    /// Device at `station` with write mailbox `mbx_out` and read mailbox `mbx_in` (start,
    /// length), answering from `script`.
    pub fn new(
        script: crate::Bytes<'a>,
        station: u16,
        mbx_out: (u16, u16),
        mbx_in: (u16, u16),
    ) -> Self {
        Self {
            script,
            station,
            mbx_out,
            mbx_in,
            pending: false,
            writes: 0,
        }
    }

    /// Script bytes left.
    pub fn left(&self) -> usize {
        self.script.len()
    }

    /// The next read-mailbox content and its WKC.
    fn next_message(&mut self) -> (Vec<u8>, u16) {
        let size = usize::from(self.mbx_in.1);
        if self.script.is_empty() {
            self.pending = false;
            // Mailbox error reply (ETG.1000.4 §5.6: type 0, service 1, detail 0x0002 "invalid
            // header") — ends every client wait.
            return (
                mailbox_message(MailboxType::Error, 1, &[0x01, 0x00, 0x02, 0x00], size),
                1,
            );
        }
        let f = self.script.u8();
        self.pending = f & 0x80 != 0;
        let wkc = u16::from(f & 0x40 == 0);
        let counter = (f >> 3) & 7;
        let msg = match f & 7 {
            // Raw bytes as the whole mailbox.
            0 => {
                let n = usize::from(self.script.u16()) % (size + 1);
                let mut m = self.script.take(n).to_vec();
                m.resize(size, 0);
                m
            }
            // CoE: header number/service from the script, then an SDO body.
            1 | 2 => {
                let mut body = vec![self.script.u8(), 0x30]; // SDO response service (3)
                if f & 7 == 2 {
                    body[1] = self.script.u8();
                }
                body.extend_from_slice(self.script.chunk());
                mailbox_message(MailboxType::Coe, counter, &body, size)
            }
            // CoE emergency.
            3 => {
                let mut body = vec![0x00, 0x10];
                body.extend_from_slice(self.script.take(8));
                mailbox_message(MailboxType::Coe, counter, &body, size)
            }
            // SoE: header (op code, flags, element, IDN) then data.
            4 | 5 => {
                let body = self.script.chunk().to_vec();
                mailbox_message(MailboxType::Soe, counter, &body, size)
            }
            // Another type with a body.
            6 => {
                let ty = MailboxType::from(self.script.u8() & 0x0F);
                let body = self.script.chunk().to_vec();
                mailbox_message(ty, counter, &body, size)
            }
            // A header whose length field lies.
            _ => {
                let mut m = mailbox_message(MailboxType::Coe, counter, self.script.chunk(), size);
                let l = self.script.u16().to_le_bytes();
                m[0] = l[0];
                m[1] = l[1];
                m
            }
        };
        (msg, wkc)
    }
}

/// SM0 / SM1 status registers (0x0805 / 0x080D), bit 3 = mailbox full.
const SM0_STATUS: u16 = 0x0805;
const SM1_STATUS: u16 = 0x080D;

impl Responder for HostileMailbox<'_> {
    fn respond(&mut self, cmd: Command, adp: u16, ado: u16, data: &mut [u8]) -> u16 {
        if adp != self.station {
            return 0;
        }
        match cmd {
            Command::Fprd if ado == SM0_STATUS => {
                data.fill(0);
                1
            }
            Command::Fprd if ado == SM1_STATUS => {
                let full = self.pending || self.script.is_empty() || self.script.u8() & 1 == 1;
                data.fill(0);
                if let Some(b) = data.first_mut() {
                    *b = if full { 0x08 } else { 0 };
                }
                1
            }
            Command::Fprd if ado == self.mbx_in.0 => {
                let (m, wkc) = self.next_message();
                let n = data.len().min(m.len());
                data[..n].copy_from_slice(&m[..n]);
                wkc
            }
            Command::Fpwr if ado == self.mbx_out.0 => {
                self.writes += 1;
                self.pending = true;
                1
            }
            _ => 1,
        }
    }
}
