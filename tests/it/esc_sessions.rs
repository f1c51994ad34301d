//! The emulated ESC serves session after session, and nothing a master writes grows it without
//! bound (issue 15).
//!
//! * Mailbox counter (ETG.1000.4 §5.6, notes `ethercat.md` §2.4): a master numbers its requests
//!   1..7; a request repeating the previous counter is a retry and gets no new answer. A new
//!   master starts at 1 after INIT, so the device must forget the previous session's counter
//!   when it enters INIT.
//! * Mailbox handshake (ETG.1000.4 §6.7.2): a write into a full write mailbox is refused
//!   (WKC 0); the firmware keeps a request there while its reply queue is full, so replies
//!   nobody reads cannot pile up.
//! * Fragmented SoE writes are collected only up to the longest SERCOS element (64 KiB);
//!   CoE downloads announcing more are aborted with 0x05040005 (CiA 301 "out of memory").
//!
//! Requests are built byte by byte from the spec layout (6-byte mailbox header: length u16,
//! address u16, channel/priority u8, type | counter << 4), independently of the server code.

use fieldprobe::drive::catalogue;
use fieldprobe::drive::model::ds402::Ds402Model;
use fieldprobe::drive::model::sercos::SercosModel;
use fieldprobe::sim::esc::coe::{ds402_objects, CoeServer};
use fieldprobe::sim::esc::soe::{sercos_idns, SoeServer};
use fieldprobe::sim::esc::{
    reg, sii_crc8, Address, Command, Esc, EscApplication, EscChain, EscConfig,
};

const MBX: usize = 64;
const OUT: u16 = 0x1000;
const IN: u16 = 0x1080;
/// 1 M, as in the reproducers.
const MILLION: usize = 1_000_000;

fn coe_server() -> CoeServer {
    let model = Ds402Model::new(&catalogue::builtin("cia402-generic").unwrap());
    CoeServer::new(Box::new(model), ds402_objects("session test drive"), MBX)
}

fn soe_server() -> SoeServer {
    let model = SercosModel::new(&catalogue::builtin("sercos-ax5000").unwrap()).unwrap();
    SoeServer::new(Box::new(model), sercos_idns(), MBX)
}

/// Mailbox message padded to the mailbox size (a master writes the whole SM0).
fn mbx(ty: u8, counter: u8, body: &[u8]) -> Vec<u8> {
    let mut v = vec![body.len() as u8, (body.len() >> 8) as u8, 0, 0, 0];
    v.push(ty | (counter << 4));
    v.extend_from_slice(body);
    v.resize(v.len().max(MBX), 0);
    v
}

/// CoE SDO upload request of `index:0` (CoE header 0x2000 = SDO request; command 0x40).
fn sdo_upload(counter: u8, index: u16) -> Vec<u8> {
    let b = [
        0x00,
        0x20,
        0x40,
        index as u8,
        (index >> 8) as u8,
        0,
        0,
        0,
        0,
        0,
    ];
    mbx(3, counter, &b)
}

/// One ESC with SM0/SM1 mailbox at OUT/IN (SII words 0x18..0x1C), `app` behind it.
struct Bench {
    chain: EscChain,
}

impl Bench {
    fn new(app: Box<dyn EscApplication>) -> Self {
        let mut w = [0u16; 0x40];
        w[0x18] = OUT;
        w[0x19] = MBX as u16;
        w[0x1A] = IN;
        w[0x1B] = MBX as u16;
        w[0x1C] = 0x0004 | 0x0020; // CoE | SoE
        let mut sii: Vec<u8> = w.iter().flat_map(|x| x.to_le_bytes()).collect();
        sii[14] = sii_crc8(&sii[..14]);
        sii.resize(256, 0xFF);
        let esc = Esc::new(EscConfig::from_sii(sii), app);
        let mut b = Bench {
            chain: EscChain::new(vec![esc], 100),
        };
        b.session_start();
        b
    }

    fn dg(&mut self, cmd: Command, ado: u16, data: &[u8]) -> (u16, Vec<u8>) {
        let mut d = data.to_vec();
        let (wkc, _) = self.chain.process(cmd, Address::station(0, ado), &mut d, 0);
        (wkc, d)
    }

    fn al_state(&mut self) -> u8 {
        self.dg(Command::Fprd, reg::AL_STATUS, &[0; 2]).1[0] & 0x0F
    }

    /// What a master does at start: INIT (with error acknowledge), mailbox SMs, PRE-OP.
    fn session_start(&mut self) {
        self.dg(Command::Fpwr, reg::AL_CONTROL, &[0x11, 0]);
        assert_eq!(self.al_state(), 0x01, "INIT");
        let sm = |start: u16, ctrl: u8| {
            let mut v = start.to_le_bytes().to_vec();
            v.extend_from_slice(&(MBX as u16).to_le_bytes());
            v.extend_from_slice(&[ctrl, 0, 1, 0]);
            v
        };
        assert_eq!(self.dg(Command::Fpwr, reg::sm(0), &sm(OUT, 0x26)).0, 1);
        assert_eq!(self.dg(Command::Fpwr, reg::sm(1), &sm(IN, 0x22)).0, 1);
        self.dg(Command::Fpwr, reg::AL_CONTROL, &[0x02, 0]);
        assert_eq!(self.al_state(), 0x02, "PRE-OP");
    }

    /// Write a request into SM0; the working counter (0 = refused, mailbox full).
    fn write(&mut self, msg: &[u8]) -> u16 {
        self.dg(Command::Fpwr, OUT, msg).0
    }

    /// Read SM1: `Some(content)` if the read mailbox was full (WKC 1).
    fn read(&mut self) -> Option<Vec<u8>> {
        let (wkc, d) = self.dg(Command::Fprd, IN, &[0; MBX]);
        (wkc == 1).then_some(d)
    }

    fn esc(&self) -> &Esc {
        &self.chain.escs[0]
    }
}

/// Counter nibble of a reply's mailbox header.
fn counter_of(reply: &[u8]) -> u8 {
    reply[5] >> 4
}

/// A master reads one object with counter 1 and goes away; a second master (INIT, PRE-OP,
/// counter 1 again) must get its answer, not be ignored as a repeat.
#[test]
fn a_new_master_after_init_is_answered_from_counter_1() {
    let mut b = Bench::new(Box::new(coe_server()));
    assert_eq!(b.write(&sdo_upload(1, 0x1000)), 1);
    let r = b.read().expect("reply to the first master");
    // SDO response (0x3000), expedited 4 bytes (0x43), 0x1000:00 = 0x00020192 (CiA 402 servo).
    assert_eq!(
        &r[6..16],
        &[0x00, 0x30, 0x43, 0x00, 0x10, 0x00, 0x92, 0x01, 0x02, 0x00]
    );
    // Within the session a repeat (same counter) gets no new reply (ETG.1000.4 repeat rule).
    assert_eq!(b.write(&sdo_upload(1, 0x1000)), 1);
    assert!(
        b.read().is_none(),
        "a repeated request is not answered again"
    );

    // Second master.
    b.session_start();
    assert_eq!(b.write(&sdo_upload(1, 0x1000)), 1);
    let r = b
        .read()
        .expect("the new master's first request is answered");
    assert_eq!(&r[8..10], &[0x43, 0x00]);
    assert_eq!(&r[12..16], &[0x92, 0x01, 0x02, 0x00]);
    assert_eq!(counter_of(&r), 1, "the device's counter restarts too");
}

/// The same for an SoE device (read S-0-0169, opcode 1, element value 0x40).
#[test]
fn a_new_soe_master_after_init_is_answered_from_counter_1() {
    let read_169 = |counter| mbx(5, counter, &[0x01, 0x40, 169, 0]);
    let mut b = Bench::new(Box::new(soe_server()));
    assert_eq!(b.write(&read_169(1)), 1);
    let r = b.read().expect("reply");
    // Read response (opcode 2), value element, IDN 169.
    assert_eq!(&r[6..10], &[0x02, 0x40, 169, 0]);
    b.session_start();
    assert_eq!(b.write(&read_169(1)), 1);
    let r = b
        .read()
        .expect("the new master's first request is answered");
    assert_eq!(&r[6..10], &[0x02, 0x40, 169, 0]);
}

/// 1 M requests, no reply read: the device takes requests only while it has room for the
/// replies (one in SM1 plus a few queued), then the write mailbox stays full and every further
/// write is refused with WKC 0 — as a real ESC with one buffer per direction. The queue stays
/// bounded, and the replies that were queued come out in order once the master reads.
#[test]
fn unread_replies_do_not_pile_up() {
    let mut b = Bench::new(Box::new(coe_server()));
    let mut accepted = 0usize;
    let mut max_queue = 0usize;
    for i in 0..MILLION {
        let counter = (i % 7) as u8 + 1;
        accepted += usize::from(b.write(&sdo_upload(counter, 0x1000)));
        max_queue = max_queue.max(b.esc().mailbox_queue_len());
    }
    println!(
        "accepted {accepted}, max queue {max_queue}, held {}",
        b.esc().mailbox_held()
    );
    // A real ESC holds at most one request in SM0 and one reply in SM1; the emulated firmware
    // may queue a handful of replies between them. Far from 1 M either way.
    assert!(max_queue <= 8, "queue {max_queue}");
    assert!(accepted <= 12, "accepted {accepted} writes");
    assert_eq!(
        b.esc().mailbox_dropped(),
        0,
        "nothing dropped: requests were refused"
    );
    // The master now reads: every accepted request is answered, with counters 1, 2, 3, …
    let mut replies = 0usize;
    while let Some(r) = b.read() {
        replies += 1;
        assert_eq!(usize::from(counter_of(&r)), (replies - 1) % 7 + 1);
        assert_eq!(&r[12..16], &[0x92, 0x01, 0x02, 0x00]);
        assert!(replies <= accepted, "more replies than requests");
    }
    assert_eq!(
        replies, accepted,
        "the held request is answered after the reads"
    );
    // And the mailbox works normally afterwards.
    assert_eq!(b.write(&sdo_upload(1, 0x1000)), 1);
    assert!(b.read().is_some());
}

/// Device-initiated messages (EMCY) nobody reads: bounded, oldest dropped and counted.
#[test]
fn unread_device_messages_are_bounded() {
    let mut b = Bench::new(Box::new(coe_server()));
    let esc = &mut b.chain.escs[0];
    for i in 0..MILLION {
        esc.push_mailbox(mbx(
            3,
            (i % 7) as u8 + 1,
            &[0x00, 0x10, 0, 0, 0, 0, 0, 0, 0, 0],
        ));
    }
    let q = esc.mailbox_queue_len();
    assert!(q <= 64, "queue {q}");
    // One message sits in SM1, `q` wait, the rest were dropped.
    assert_eq!(esc.mailbox_dropped() as usize, MILLION - 1 - q);
}

/// SoE write request fragment: opcode 3 with the incomplete bit (0x08), element value, the
/// IDN field = fragments left.
fn soe_fragment(counter: u8, left: u16, data: &[u8]) -> Vec<u8> {
    let mut body = vec![0x03 | 0x08, 0x40, left as u8, (left >> 8) as u8];
    body.extend_from_slice(data);
    mbx(5, counter, &body)
}

/// 1 M "incomplete" write fragments: the server collects at most 64 KiB, then answers the
/// write with the SERCOS error 0x7003 "data transmitted too long" and starts over.
#[test]
fn endless_soe_write_fragments_are_refused_not_collected() {
    const CHUNK: usize = 50;
    // The longest SERCOS element: current + maximum length (2 × u16) + 65,532 data bytes.
    const LIMIT: usize = 4 + 65_532;
    let mut s = soe_server();
    let data = [0xA5u8; CHUNK];
    let mut max_len = 0usize;
    let mut errors = Vec::new();
    for i in 0..MILLION {
        let counter = (i % 7) as u8 + 1;
        if let Some(r) = s.handle(&soe_fragment(counter, 1000, &data)) {
            errors.push(i);
            // Write response (opcode 4) with the error bit (0x10), error code 0x7003.
            assert_eq!(r[6] & 0x17, 0x14, "{:02x?}", &r[..16]);
            assert_eq!(&r[10..12], &0x7003u16.to_le_bytes());
        }
        max_len = max_len.max(s.write_fragments_len());
    }
    assert!(max_len <= LIMIT, "collected {max_len} bytes");
    // The first refusal comes with the first fragment that does not fit any more.
    let fit = LIMIT / CHUNK;
    assert_eq!(errors.first(), Some(&fit));
    assert!(errors.len() >= MILLION / (fit + 1) - 1);
}

/// A CoE download announcing more than the server takes is aborted at once with 0x05040005
/// (out of memory); nothing is collected.
#[test]
fn huge_coe_download_is_aborted_at_initiate() {
    let mut s = coe_server();
    // Initiate download, normal (not expedited), size indicated (0x21), 0x1008:00, size 1 GiB.
    let mut body = vec![0x00, 0x20, 0x21, 0x08, 0x10, 0x00];
    body.extend_from_slice(&(1u32 << 30).to_le_bytes());
    let r = s.handle(&mbx(3, 1, &body)).expect("answer");
    // SDO abort (0x80) of 0x1008:00 with 0x05040005.
    assert_eq!(
        &r[6..16],
        &[0x00, 0x20, 0x80, 0x08, 0x10, 0x00, 0x05, 0x00, 0x04, 0x05]
    );
    assert_eq!(s.download_len(), 0);
}
