//! Emulated ESC: register replay of the ethercrab 0.7.1 init trace
//! (`../shared/notes/trace-ethercrab-0.7.1-init.txt`), WKC rules and AL state machine per
//! `../shared/notes/ethercat.md` §2.1/§2.2/§2.5, mailbox SM semantics, logical addressing over
//! three chained devices, and a fuzz-style robustness check.

use fieldprobe::sim::esc::{
    reg, sii_crc8, Address, AlState, AlStatusCode, Command, EchoApp, Esc, EscChain, EscConfig,
    NullApp,
};

const VENDOR: u32 = 0x0000_0002;
const PRODUCT: u32 = 0x0B30_3052;
const ALIAS: u16 = 0x0123;
const MBX_OUT: u16 = 0x1000;
const MBX_IN: u16 = 0x1080;
const MBX_LEN: u16 = 128;

/// SII image in ETG.2010 layout: config area with CRC, identity, standard mailbox, one
/// SyncManager category, end marker.
fn sii_image(mailbox: bool) -> Vec<u8> {
    let mut w = [0u16; 0x40];
    w[0] = 0x0C08; // PDI control / ESC config
    w[4] = ALIAS;
    w[8] = VENDOR as u16;
    w[9] = (VENDOR >> 16) as u16;
    w[10] = PRODUCT as u16;
    w[11] = (PRODUCT >> 16) as u16;
    w[12] = 1; // revision
    w[14] = 0x1234; // serial
    if mailbox {
        w[0x18] = MBX_OUT;
        w[0x19] = MBX_LEN;
        w[0x1A] = MBX_IN;
        w[0x1B] = MBX_LEN;
        w[0x1C] = 0x0004; // CoE
    }
    w[0x3E] = 15; // (15+1)*128 bytes
    let mut b: Vec<u8> = w.iter().flat_map(|x| x.to_le_bytes()).collect();
    b[14] = sii_crc8(&b[..14]);
    // SyncManager category (41): 4 entries × 8 bytes = 16 words.
    b.extend_from_slice(&41u16.to_le_bytes());
    b.extend_from_slice(&16u16.to_le_bytes());
    for (start, len, ctrl, ty) in [
        (MBX_OUT, MBX_LEN, 0x26u8, 1u8),
        (MBX_IN, MBX_LEN, 0x22, 2),
        (0x1100, 0, 0x64, 3),
        (0x1180, 0, 0x20, 4),
    ] {
        b.extend_from_slice(&start.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&[ctrl, 0, 1, ty]);
    }
    b.extend_from_slice(&0xFFFFu16.to_le_bytes());
    b.resize(2048, 0xFF);
    b
}

fn device(dc: bool, out: u16, inp: u16) -> Esc {
    let mut cfg = EscConfig::from_sii(sii_image(true));
    cfg.dc = dc;
    let mut app = EchoApp::new(out, inp);
    app.loopback = true;
    Esc::new(cfg, Box::new(app))
}

fn chain(n: usize) -> EscChain {
    EscChain::new((0..n).map(|_| device(true, 2, 2)).collect(), 100)
}

/// One datagram through the chain at time `t`; returns (wkc, data after the ring).
fn dg(c: &mut EscChain, cmd: Command, addr: Address, data: &[u8], t: u64) -> (u16, Vec<u8>) {
    let mut d = data.to_vec();
    let (wkc, _) = c.process(cmd, addr, &mut d, t);
    (wkc, d)
}

fn u16le(d: &[u8]) -> u16 {
    u16::from_le_bytes([d[0], d[1]])
}

fn sm_bytes(start: u16, len: u16, ctrl: u8, enable: u8) -> Vec<u8> {
    let mut v = start.to_le_bytes().to_vec();
    v.extend_from_slice(&len.to_le_bytes());
    v.extend_from_slice(&[ctrl, 0, enable, 0]);
    v
}

/// SII read through 0x0502/0x0504/0x0508 like ethercrab's `device_provider.rs`.
fn sii_read(c: &mut EscChain, station: u16, word: u32, chunk: usize) -> Vec<u8> {
    let mut cmd = vec![0x00, 0x01];
    cmd.extend_from_slice(&word.to_le_bytes());
    let (wkc, _) = dg(
        c,
        Command::Fpwr,
        Address::station(station, reg::SII_CONTROL),
        &cmd,
        0,
    );
    assert_eq!(wkc, 1);
    let (wkc, st) = dg(
        c,
        Command::Fprd,
        Address::station(station, reg::SII_CONTROL),
        &[0, 0],
        0,
    );
    assert_eq!(wkc, 1);
    let st = u16le(&st);
    assert_eq!(st & 0x8000, 0, "busy bit 15 clear");
    assert_eq!(st & 0x7800, 0, "no error bits 11..14");
    let (wkc, d) = dg(
        c,
        Command::Fprd,
        Address::station(station, reg::SII_DATA),
        &vec![0; chunk],
        0,
    );
    assert_eq!(wkc, 1);
    d
}

/// Trace entries 1–17 for `n` devices; returns the chain with station addresses 0x1000+i.
fn ethercrab_init_prefix(c: &mut EscChain) {
    let n = c.escs.len() as u16;
    // 1. BRD 0x0000 len 1: WKC = number of SubDevices, data = ESC type (OR).
    let (wkc, d) = dg(c, Command::Brd, Address::broadcast(reg::TYPE), &[0], 0);
    assert_eq!(wkc, n);
    assert_eq!(d[0], 0x11);
    // 2. BWR 0x0120 = 0x0011 (INIT + ack).
    let (wkc, _) = dg(
        c,
        Command::Bwr,
        Address::broadcast(reg::AL_CONTROL),
        &[0x11, 0],
        0,
    );
    assert_eq!(wkc, n);
    // 3./4. Clear FMMU0..15 and SM0..15: only the 8 existing ones count (real ET1100 gives WKC 0
    // for FMMU/SM 8..15).
    for i in 0..16u16 {
        let (wkc, _) = dg(
            c,
            Command::Bwr,
            Address::broadcast(reg::fmmu(i)),
            &[0; 16],
            0,
        );
        assert_eq!(wkc, if i < 8 { n } else { 0 }, "FMMU{i}");
    }
    for i in 0..16u16 {
        let (wkc, _) = dg(c, Command::Bwr, Address::broadcast(reg::sm(i)), &[0; 8], 0);
        assert_eq!(wkc, if i < 8 { n } else { 0 }, "SM{i}");
    }
    // 5./6. DC unit reset.
    for (r, l) in [
        (0x0910u16, 8usize),
        (0x0920, 8),
        (0x0928, 4),
        (0x092C, 4),
        (0x0981, 1),
        (0x0990, 4),
        (0x09A0, 4),
        (0x09A4, 4),
    ] {
        let (wkc, _) = dg(c, Command::Bwr, Address::broadcast(r), &vec![0; l], 0);
        assert_eq!(wkc, n, "BWR {r:#06x}");
    }
    let (wkc, _) = dg(
        c,
        Command::Bwr,
        Address::broadcast(0x0934),
        &[0x00, 0x0C],
        0,
    );
    assert_eq!(wkc, n);
    let (wkc, _) = dg(
        c,
        Command::Bwr,
        Address::broadcast(0x0930),
        &[0x00, 0x10],
        0,
    );
    assert_eq!(wkc, n);
    // 7. APWR 0x0010 = 0x1000 + position.
    for i in 0..n {
        let (wkc, _) = dg(
            c,
            Command::Apwr,
            Address::position(i, reg::STATION_ADDRESS),
            &(0x1000 + i).to_le_bytes(),
            0,
        );
        assert_eq!(wkc, 1);
    }
    for (i, e) in c.escs.iter().enumerate() {
        assert_eq!(e.station_address(), 0x1000 + i as u16);
    }
}

#[test]
fn ethercrab_init_trace_single_device() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    // 8. FPRD 0x0130: INIT, no error.
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::AL_STATUS),
        &[0, 0],
        0,
    );
    assert_eq!((wkc, u16le(&d)), (1, 0x0001));
    // 9. Force ECAT EEPROM access.
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0500),
        &[0x02, 0x00],
        0,
    );
    assert_eq!(wkc, 1);
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0500),
        &[0x00],
        0,
    );
    assert_eq!(wkc, 1);
    // 10. SII interface idle: bit 6 = 8-byte reads (EK1914 returns 0x40 0x00 idle).
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::SII_CONTROL),
        &[0, 0],
        0,
    );
    assert_eq!(u16le(&d), 0x0040);
    // Identity at word 0x0008: vendor u32, product u32.
    let d = sii_read(&mut c, st, 0x0008, 8);
    assert_eq!(u32::from_le_bytes(d[0..4].try_into().unwrap()), VENDOR);
    assert_eq!(u32::from_le_bytes(d[4..8].try_into().unwrap()), PRODUCT);
    // Standard mailbox words 0x18..0x1B.
    let d = sii_read(&mut c, st, 0x0018, 8);
    assert_eq!(u16le(&d[0..2]), MBX_OUT);
    assert_eq!(u16le(&d[2..4]), MBX_LEN);
    assert_eq!(u16le(&d[4..6]), MBX_IN);
    assert_eq!(u16le(&d[6..8]), MBX_LEN);
    // Category walk from word 0x40: SyncManager (41), 16 words.
    let d = sii_read(&mut c, st, 0x0040, 8);
    assert_eq!((u16le(&d[0..2]), u16le(&d[2..4])), (41, 16));
    // 11. Features: DC (bit 2) + 64-bit DC (bit 3).
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::FEATURES),
        &[0, 0],
        0,
    );
    assert_eq!(u16le(&d) & 0x000C, 0x000C);
    // 12. Alias loaded from SII word 4.
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::STATION_ALIAS),
        &[0, 0],
        0,
    );
    assert_eq!(u16le(&d), ALIAS);
    // 13. DL status: port 0 link (bit 4) + communication (bit 9), port 1 open loop closed (bit 10).
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::DL_STATUS),
        &[0, 0],
        0,
    );
    let dl = u16le(&d);
    assert_eq!(dl & 0x0010, 0x0010);
    assert_eq!(dl & 0x0200, 0x0200);
    assert_eq!(dl & 0x0020, 0);
    assert_eq!(dl & 0x0400, 0x0400);
    // 14./15. DC receive time latch.
    let t = 5_000_000u64;
    let (wkc, _) = dg(&mut c, Command::Bwr, Address::broadcast(0x0900), &[0; 4], t);
    assert_eq!(wkc, 1);
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, 0x0918),
        &[0; 8],
        t + 1000,
    );
    assert_eq!(wkc, 1);
    assert_eq!(u64::from_le_bytes(d.try_into().unwrap()), t);
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, 0x0900),
        &[0; 16],
        t + 1000,
    );
    assert_eq!(u32::from_le_bytes(d[0..4].try_into().unwrap()), t as u32);
    // 16. Offset → system time = local + offset.
    let off: u64 = 1_000_000_000;
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0920),
        &off.to_le_bytes(),
        t,
    );
    assert_eq!(wkc, 1);
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0928),
        &[0; 4],
        t,
    );
    assert_eq!(wkc, 1);
    // 17. FRMW 0x0910: the single (reference) device reads.
    let (wkc, d) = dg(
        &mut c,
        Command::Frmw,
        Address::station(st, 0x0910),
        &[0; 8],
        7_000_000,
    );
    assert_eq!(wkc, 1);
    assert_eq!(u64::from_le_bytes(d.try_into().unwrap()), 7_000_000 + off);
    // 19. Mailbox SMs from SII.
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(0)),
        &sm_bytes(MBX_OUT, MBX_LEN, 0x26, 1),
        0,
    );
    assert_eq!(wkc, 1);
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(1)),
        &sm_bytes(MBX_IN, MBX_LEN, 0x22, 1),
        0,
    );
    assert_eq!(wkc, 1);
    // 20. PDI EEPROM mode, request PRE-OP, back to ECAT mode.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0500),
        &[0x01],
        0,
    );
    let (wkc, d) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x02, 0],
        0,
    );
    assert_eq!(wkc, 1);
    assert_eq!(d, vec![0x02, 0], "write data echoed unchanged");
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, reg::AL_STATUS),
        &[0, 0],
        0,
    );
    assert_eq!(u16le(&d), 0x0002);
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0500),
        &[0x00],
        0,
    );
    // 21. BRD 0x0130: OR of all states = PRE-OP.
    let (wkc, d) = dg(
        &mut c,
        Command::Brd,
        Address::broadcast(reg::AL_STATUS),
        &[0, 0],
        0,
    );
    assert_eq!((wkc, u16le(&d)), (1, 0x0002));
    assert_eq!(c.escs[0].al_state(), AlState::PreOp);
}

fn to_preop(c: &mut EscChain, st: u16) {
    dg(
        c,
        Command::Fpwr,
        Address::station(st, reg::sm(0)),
        &sm_bytes(MBX_OUT, MBX_LEN, 0x26, 1),
        0,
    );
    dg(
        c,
        Command::Fpwr,
        Address::station(st, reg::sm(1)),
        &sm_bytes(MBX_IN, MBX_LEN, 0x22, 1),
        0,
    );
    dg(
        c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x02, 0],
        0,
    );
}

fn al(c: &mut EscChain, st: u16) -> (u16, u16) {
    let (wkc, d) = dg(
        c,
        Command::Fprd,
        Address::station(st, reg::AL_STATUS),
        &[0; 6],
        0,
    );
    assert_eq!(wkc, 1);
    (u16le(&d[0..2]), u16le(&d[4..6]))
}

#[test]
fn wrong_mailbox_sm_refused_with_0x0016_and_ack_clears() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    // SM0 length 64 instead of the SII's 128.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(0)),
        &sm_bytes(MBX_OUT, 64, 0x26, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(1)),
        &sm_bytes(MBX_IN, MBX_LEN, 0x22, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x02, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0016));
    assert_eq!(
        c.escs[0].al_status_code(),
        AlStatusCode::INVALID_MAILBOX_CONFIG
    );
    // Request without acknowledge is ignored while the error is indicated.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x02, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0016));
    // Acknowledge (INIT | 0x10) clears the error.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x11, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0001, 0x0000));
    // SM1 with the wrong direction (control 0x26 = write) is refused too.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(0)),
        &sm_bytes(MBX_OUT, MBX_LEN, 0x26, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(1)),
        &sm_bytes(MBX_IN, MBX_LEN, 0x26, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x12, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0016));
    // Correct config + ack in the same write → PRE-OP.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(1)),
        &sm_bytes(MBX_IN, MBX_LEN, 0x22, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x12, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0002, 0x0000));
}

#[test]
fn al_state_machine_codes() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    // INIT → OP directly: invalid state change 0x0011.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x08, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0011));
    // Unknown state 5 (with ack): 0x0012.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x15, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0012));
    // BOOT not supported by this device: 0x0013.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x13, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0011, 0x0013));
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x11, 0],
        0,
    );
    to_preop(&mut c, st);
    assert_eq!(al(&mut c, st), (0x0002, 0));
    // PRE-OP → SAFE-OP without process-data SMs: outputs (2 bytes expected) → 0x001D.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x04, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0012, 0x001D));
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x12, 0],
        0,
    );
    // SM2 right, SM3 wrong length → 0x001E.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(2)),
        &sm_bytes(0x1100, 2, 0x64, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(3)),
        &sm_bytes(0x1180, 4, 0x20, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x04, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0012, 0x001E));
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(3)),
        &sm_bytes(0x1180, 2, 0x20, 1),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x14, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0004, 0));
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x08, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0008, 0));
    assert_eq!(c.escs[0].al_state(), AlState::Op);
    // Any state → INIT is always allowed.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x01, 0],
        0,
    );
    assert_eq!(al(&mut c, st), (0x0001, 0));
}

#[test]
fn read_only_registers_are_write_protected() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    for (r, len) in [
        (reg::TYPE, 8usize),
        (reg::AL_STATUS, 2),
        (reg::AL_STATUS_CODE, 2),
        (reg::DL_STATUS, 2),
        (reg::STATION_ALIAS, 2),
    ] {
        let before = c.escs[0].peek(r, len);
        let (wkc, _) = dg(
            &mut c,
            Command::Fpwr,
            Address::station(st, r),
            &vec![0xA5; len],
            0,
        );
        assert_eq!(wkc, 1, "write to existing register is counted");
        assert_eq!(
            c.escs[0].peek(r, len),
            before,
            "register {r:#06x} unchanged"
        );
    }
    // SM status byte (+5) and PDI control (+7) are read-only, the rest of the SM is writable.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(2)),
        &[0x00, 0x11, 0x02, 0x00, 0x64, 0xFF, 0x00, 0xFF],
        0,
    );
    let sm2 = c.escs[0].peek(reg::sm(2), 8);
    assert_eq!(&sm2[..5], &[0x00, 0x11, 0x02, 0x00, 0x64]);
    assert_eq!(sm2[5], 0x00);
    // SII control: busy/error bits cannot be written.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::SII_CONTROL),
        &[0x00, 0xF8],
        0,
    );
    assert_eq!(c.escs[0].peek_u16(reg::SII_CONTROL) & 0xF800, 0);
}

#[test]
fn sii_four_byte_interface_and_write() {
    let mut cfg = EscConfig::from_sii(sii_image(false));
    cfg.sii_read_8 = false;
    let mut c = EscChain::new(vec![Esc::new(cfg, Box::new(NullApp))], 0);
    dg(
        &mut c,
        Command::Apwr,
        Address::position(0, reg::STATION_ADDRESS),
        &[0x01, 0x10],
        0,
    );
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(0x1001, reg::SII_CONTROL),
        &[0, 0],
        0,
    );
    assert_eq!(u16le(&d) & 0x0040, 0, "4-byte reads");
    let d = sii_read(&mut c, 0x1001, 0x0008, 8);
    assert_eq!(u32::from_le_bytes(d[0..4].try_into().unwrap()), VENDOR);
    assert_eq!(&d[4..8], &[0, 0, 0, 0], "only 4 bytes delivered");
    // Write without write enable → error bit 14; with enable → stored.
    let st = 0x1001;
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::SII_DATA),
        &[0x34, 0x12],
        0,
    );
    let mut cmd = vec![0x00, 0x02];
    cmd.extend_from_slice(&4u32.to_le_bytes());
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::SII_CONTROL),
        &cmd,
        0,
    );
    assert_ne!(c.escs[0].peek_u16(reg::SII_CONTROL) & 0x4000, 0);
    cmd[0] = 0x01;
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::SII_CONTROL),
        &cmd,
        0,
    );
    assert_eq!(c.escs[0].peek_u16(reg::SII_CONTROL) & 0x4000, 0);
    assert_eq!(&c.escs[0].sii()[8..10], &[0x34, 0x12]);
}

#[test]
fn mailbox_sm_full_flag_echo_and_repeat() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    to_preop(&mut c, st);
    let status = |c: &mut EscChain, sm: u16| {
        let (wkc, d) = dg(
            c,
            Command::Fprd,
            Address::station(st, reg::sm_status(sm)),
            &[0],
            0,
        );
        assert_eq!(wkc, 1);
        d[0]
    };
    assert_eq!(status(&mut c, 1) & 0x08, 0);
    // Reading the empty read mailbox is refused (WKC 0).
    let (wkc, _) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, MBX_IN),
        &[0; 128],
        0,
    );
    assert_eq!(wkc, 0);
    // Partial write: not complete, no reply.
    let mut msg = vec![0u8; 128];
    msg[..8].copy_from_slice(&[10, 0, 0, 0, 0, 0x13, 1, 2]);
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, MBX_OUT),
        &msg[..64],
        0,
    );
    assert_eq!(wkc, 1);
    assert_eq!(status(&mut c, 1) & 0x08, 0);
    // Full-length write completes the mailbox; the echo app answers into SM1.
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, MBX_OUT),
        &msg,
        0,
    );
    assert_eq!(wkc, 1);
    assert_eq!(
        status(&mut c, 0) & 0x08,
        0,
        "write mailbox consumed by the PDI"
    );
    assert_eq!(status(&mut c, 1) & 0x08, 0x08, "read mailbox full");
    // ECAT event request bit 4+1 mirrors SM1; visible in the IRQ field once unmasked.
    assert_eq!(c.irq() & 0x0020, 0);
    dg(
        &mut c,
        Command::Bwr,
        Address::broadcast(reg::ECAT_EVENT_MASK),
        &[0x20, 0],
        0,
    );
    assert_eq!(c.irq() & 0x0020, 0x0020);
    // Writes into the read mailbox are refused.
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, MBX_IN),
        &[0; 4],
        0,
    );
    assert_eq!(wkc, 0);
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, MBX_IN),
        &[0; 128],
        0,
    );
    assert_eq!(wkc, 1);
    assert_eq!(d, msg);
    assert_eq!(
        status(&mut c, 1) & 0x08,
        0,
        "emptied by reading the last byte"
    );
    // Repeat: toggle SM1 activate bit 1 → last reply again, PDI control bit 1 follows.
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::sm(1) + 6),
        &[0x03],
        0,
    );
    assert_eq!(wkc, 1);
    assert_eq!(status(&mut c, 1) & 0x08, 0x08);
    assert_eq!(c.escs[0].peek_u8(reg::sm(1) + 7) & 0x02, 0x02);
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, MBX_IN),
        &[0; 128],
        0,
    );
    assert_eq!((wkc, d), (1, msg));
    // Device-initiated message (e.g. EMCY).
    c.escs[0].push_mailbox(vec![0xEE; 16]);
    assert_eq!(status(&mut c, 1) & 0x08, 0x08);
    // Back to INIT: mailbox SMs deactivated, flag cleared.
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::AL_CONTROL),
        &[0x01, 0],
        0,
    );
    assert_eq!(status(&mut c, 1) & 0x08, 0);
}

#[test]
fn three_devices_addressing_and_dc_counting() {
    let mut c = EscChain::new(
        vec![device(true, 2, 2), device(true, 2, 2), device(false, 2, 2)],
        100,
    );
    let (wkc, _) = dg(&mut c, Command::Brd, Address::broadcast(reg::TYPE), &[0], 0);
    assert_eq!(wkc, 3);
    for i in 0..3u16 {
        dg(
            &mut c,
            Command::Apwr,
            Address::position(i, reg::STATION_ADDRESS),
            &(0x1000 + i).to_le_bytes(),
            0,
        );
    }
    for i in 0..3u16 {
        let (wkc, d) = dg(
            &mut c,
            Command::Aprd,
            Address::position(i, reg::STATION_ADDRESS),
            &[0, 0],
            0,
        );
        assert_eq!((wkc, u16le(&d)), (1, 0x1000 + i));
        let (wkc, _) = dg(
            &mut c,
            Command::Fprd,
            Address::station(0x1000 + i, reg::TYPE),
            &[0],
            0,
        );
        assert_eq!(wkc, 1);
    }
    // ADP comes back incremented by every device.
    let (_, a) = c.process(Command::Aprd, Address::position(0, 0), &mut [0], 0);
    assert_eq!(a, Address::Physical { adp: 3, ado: 0 });
    // Position 3 does not exist.
    let (wkc, _) = dg(
        &mut c,
        Command::Aprd,
        Address::position(3, reg::TYPE),
        &[0],
        0,
    );
    assert_eq!(wkc, 0);
    // APRW: read +1, write +2.
    let (wkc, d) = dg(
        &mut c,
        Command::Aprw,
        Address::position(1, reg::STATION_ADDRESS),
        &[0x22, 0x20],
        0,
    );
    assert_eq!((wkc, u16le(&d)), (3, 0x1001));
    assert_eq!(c.escs[1].station_address(), 0x2022);
    // BWR 0x0900 counts only DC devices (ethercrab `.with_wkc(#DC)`).
    let (wkc, _) = dg(
        &mut c,
        Command::Bwr,
        Address::broadcast(0x0900),
        &[0; 4],
        1_000_000,
    );
    assert_eq!(wkc, 2);
    // Receive times: port 1 of device 0 sees the frame return after 2 hops × 2 × 100 ns.
    let p0 = c.escs[0].peek_u32(0x0900);
    let p1 = c.escs[0].peek_u32(0x0904);
    assert_eq!(p1 - p0, 400);
    // FPRD 0x0918 of the non-DC device: WKC 0.
    let (wkc, _) = dg(
        &mut c,
        Command::Fprd,
        Address::station(0x1002, 0x0918),
        &[0; 8],
        0,
    );
    assert_eq!(wkc, 0);
    // FRMW 0x0910 from the reference: reference reads (+1), the other DC device writes (+1),
    // the non-DC device does not count → 2 (replay-dc.pcapng).
    let (wkc, _) = dg(
        &mut c,
        Command::Frmw,
        Address::station(0x1000, 0x0910),
        &[0; 8],
        0,
    );
    assert_eq!(wkc, 2);
    // ARMW: position 0 reads, others write.
    let (wkc, _) = dg(
        &mut c,
        Command::Armw,
        Address::position(0, 0x0910),
        &[0; 8],
        0,
    );
    assert_eq!(wkc, 2);
    // BRW on a plain register: +3 per device.
    let (wkc, _) = dg(
        &mut c,
        Command::Brw,
        Address::broadcast(reg::ECAT_EVENT_MASK),
        &[0x0F, 0],
        0,
    );
    assert_eq!(wkc, 9);
    assert!(c
        .escs
        .iter()
        .all(|e| e.peek_u16(reg::ECAT_EVENT_MASK) == 0x000F));
}

/// Three devices in OP with SM2/SM3 (2 bytes each) mapped by FMMU0/1 at logical 4i.
fn op_chain() -> EscChain {
    let mut c = chain(3);
    ethercrab_init_prefix(&mut c);
    for i in 0..3u16 {
        let st = 0x1000 + i;
        to_preop(&mut c, st);
        dg(
            &mut c,
            Command::Fpwr,
            Address::station(st, reg::sm(2)),
            &sm_bytes(0x1100, 2, 0x64, 1),
            0,
        );
        dg(
            &mut c,
            Command::Fpwr,
            Address::station(st, reg::sm(3)),
            &sm_bytes(0x1180, 2, 0x20, 1),
            0,
        );
        // FMMU0: outputs, logical 4i..4i+2 → 0x1100, write; FMMU1: inputs 4i+2.. ← 0x1180, read.
        let fmmu = |log: u32, phys: u16, ty: u8| {
            let mut f = log.to_le_bytes().to_vec();
            f.extend_from_slice(&2u16.to_le_bytes());
            f.extend_from_slice(&[0, 7]);
            f.extend_from_slice(&phys.to_le_bytes());
            f.extend_from_slice(&[0, ty, 1, 0, 0, 0]);
            f
        };
        let (wkc, _) = dg(
            &mut c,
            Command::Fpwr,
            Address::station(st, reg::fmmu(0)),
            &fmmu(4 * u32::from(i), 0x1100, 2),
            0,
        );
        assert_eq!(wkc, 1);
        dg(
            &mut c,
            Command::Fpwr,
            Address::station(st, reg::fmmu(1)),
            &fmmu(4 * u32::from(i) + 2, 0x1180, 1),
            0,
        );
    }
    let (wkc, _) = dg(
        &mut c,
        Command::Bwr,
        Address::broadcast(reg::AL_CONTROL),
        &[0x04, 0],
        0,
    );
    assert_eq!(wkc, 3);
    let (wkc, d) = dg(
        &mut c,
        Command::Brd,
        Address::broadcast(reg::AL_STATUS),
        &[0, 0],
        0,
    );
    assert_eq!((wkc, u16le(&d)), (3, 0x0004));
    dg(
        &mut c,
        Command::Bwr,
        Address::broadcast(reg::AL_CONTROL),
        &[0x08, 0],
        0,
    );
    assert!(c.escs.iter().all(|e| e.al_state() == AlState::Op));

    c
}

#[test]
fn lrw_through_fmmus_three_devices() {
    let mut c = op_chain();
    let out = [0x11, 0x12, 0, 0, 0x21, 0x22, 0, 0, 0x31, 0x32, 0, 0];
    // Cycle 1: inputs reflect the outputs before this datagram (none yet → !0 = 0xFF).
    let (wkc, d) = dg(&mut c, Command::Lrw, Address::Logical(0), &out, 0);
    assert_eq!(wkc, 9, "LRW: +1 read +2 write per device");
    for i in 0..3 {
        assert_eq!(c.escs[i].peek(0x1100, 2), out[4 * i..4 * i + 2].to_vec());
        assert_eq!(&d[4 * i + 2..4 * i + 4], &[0xFF, 0xFF]);
        assert_eq!(
            &d[4 * i..4 * i + 2],
            &out[4 * i..4 * i + 2],
            "output bytes unchanged"
        );
    }
    // Cycle 2: loopback app returns !outputs of cycle 1.
    let (wkc, d) = dg(&mut c, Command::Lrw, Address::Logical(0), &out, 1_000_000);
    assert_eq!(wkc, 9);
    for i in 0..3 {
        assert_eq!(d[4 * i + 2], !out[4 * i]);
        assert_eq!(d[4 * i + 3], !out[4 * i + 1]);
    }
    let (wkc, _) = dg(&mut c, Command::Lrd, Address::Logical(0), &[0; 12], 0);
    assert_eq!(wkc, 3);
    let (wkc, _) = dg(&mut c, Command::Lwr, Address::Logical(0), &out, 0);
    assert_eq!(wkc, 3);
    // Only device 1's window.
    let (wkc, _) = dg(&mut c, Command::Lrw, Address::Logical(4), &[0; 4], 0);
    assert_eq!(wkc, 3);
    // Outside every FMMU.
    let (wkc, _) = dg(&mut c, Command::Lrw, Address::Logical(0x1000), &[0; 4], 0);
    assert_eq!(wkc, 0);
    // Bit-granular: FMMU with stop bit 3 on the last byte only writes its low nibble.
    let st = 0x1000;
    let mut f = 0x100u32.to_le_bytes().to_vec();
    f.extend_from_slice(&1u16.to_le_bytes());
    f.extend_from_slice(&[0, 3]);
    f.extend_from_slice(&0x1200u16.to_le_bytes());
    f.extend_from_slice(&[0, 2, 1, 0, 0, 0]);
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, reg::fmmu(2)),
        &f,
        0,
    );
    let (wkc, _) = dg(&mut c, Command::Lwr, Address::Logical(0x100), &[0xFF], 0);
    assert_eq!(wkc, 1);
    assert_eq!(c.escs[0].peek_u8(0x1200), 0x0F);
}

fn fuzz(c: &mut EscChain, seed: u64, rounds: u64) {
    let mut s: u64 = seed;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let hot = [
        0x0000u16, 0x0010, 0x0120, 0x0130, 0x0500, 0x0502, 0x0508, 0x0600, 0x0610, 0x0800, 0x0806,
        0x0808, 0x080E, 0x0810, 0x0900, 0x0910, 0x0981, 0x1000, 0x1080, 0x1100, 0x1180, 0xFFF0,
    ];
    for t in 0..rounds {
        let r = next();
        let cmd = (r % 16) as u8;
        let ado = if r & 0x100 != 0 {
            hot[(r >> 9) as usize % hot.len()]
        } else {
            (r >> 16) as u16
        };
        let adp = match (r >> 40) % 4 {
            0 => 0,
            1 => 0u16.wrapping_sub(((r >> 44) % 4) as u16),
            2 => 0x1000 + ((r >> 44) % 3) as u16,
            _ => (r >> 44) as u16,
        };
        let len = if r & 0x200 != 0 {
            ((r >> 32) % 2048) as usize
        } else {
            ((r >> 32) % 17) as usize
        };
        let mut data: Vec<u8> = (0..len).map(|_| next() as u8).collect();
        let raw = if Command::from_u8(cmd).is_some_and(|c| c.is_logical()) {
            if r & 0x400 != 0 {
                (r >> 20) as u32
            } else {
                (r >> 20) as u32 % 0x20
            }
        } else {
            u32::from(adp) | (u32::from(ado) << 16)
        };
        let mut wkc = 0u16;
        c.process_raw(cmd, raw, &mut data, &mut wkc, t * 1000);
        assert_eq!(data.len(), len);
    }
}

#[test]
fn random_datagrams_never_panic() {
    let mut c = EscChain::new(
        vec![device(true, 2, 2), device(false, 0, 0), device(true, 4, 4)],
        50,
    );
    fuzz(&mut c, 0x9E37_79B9_7F4A_7C15, 30_000);
    // From a fully configured OP ring (mailboxes, SMs, FMMUs live).
    for seed in [1u64, 0xDEAD_BEEF, 0x1234_5678_9ABC_DEF0] {
        let mut c = op_chain();
        fuzz(&mut c, seed, 10_000);
    }
}

#[test]
fn process_data_watchdog_drops_to_safeop_with_0x001b() {
    let mut c = op_chain();
    // Default watchdog: 1000 × (2498 + 2) × 40 ns = 100 ms.
    assert_eq!(c.escs[0].pd_watchdog_ns(), 100_000_000);
    let out = [1u8; 12];
    dg(&mut c, Command::Lrw, Address::Logical(0), &out, 0);
    for e in &mut c.escs {
        e.tick(50_000_000);
        assert_eq!(e.al_state(), AlState::Op);
    }
    // Device 0 keeps getting outputs, the others do not.
    dg(
        &mut c,
        Command::Lwr,
        Address::Logical(0),
        &out[..2],
        90_000_000,
    );
    for e in &mut c.escs {
        e.tick(150_000_000);
    }
    assert_eq!(c.escs[0].al_state(), AlState::Op);
    for e in &c.escs[1..] {
        assert_eq!(e.al_state(), AlState::SafeOp);
        assert_eq!(e.al_status(), 0x0014);
        assert_eq!(e.al_status_code(), AlStatusCode::SYNC_MANAGER_WATCHDOG);
        assert_eq!(e.peek_u8(reg::WD_STATUS_PD) & 0x01, 0);
    }
}

#[test]
fn dc_sync0_activation_like_configure_dc_sync() {
    let mut c = chain(1);
    ethercrab_init_prefix(&mut c);
    let st = 0x1000;
    let period = 1_000_000u64;
    let (_, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(st, 0x0910),
        &[0; 8],
        2_345_678,
    );
    let t0 = u64::from_le_bytes(d.try_into().unwrap());
    assert_eq!(t0, 2_345_678);
    let start = (t0 + 100_000) / period * period + period;
    let (wkc, _) = dg(&mut c, Command::Fpwr, Address::station(st, 0x0981), &[0], 0);
    assert_eq!(wkc, 1);
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0990),
        &start.to_le_bytes(),
        0,
    );
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x09A0),
        &period.to_le_bytes(),
        0,
    );
    assert_eq!(c.escs[0].next_sync0(2_400_000), None);
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(st, 0x0981),
        &[0x03],
        0,
    );
    assert_eq!(c.escs[0].peek_u8(0x0984) & 0x01, 0x01, "SYNC0 activated");
    assert_eq!(c.escs[0].next_sync0(2_400_000), Some(3_000_000));
    assert_eq!(c.escs[0].next_sync0(4_500_000), Some(5_000_000));
}

/// The extra registers of `trace-soem-init.txt` (pysoem 1.1.13).
#[test]
fn soem_init_trace_specifics() {
    let mut c = chain(2);
    let n = 2;
    for (r, l) in [
        (0x0103u16, 1usize),
        (0x0101, 1),
        (0x0200, 2),
        (0x0300, 8),
        (0x0600, 48),
        (0x0800, 32),
        (0x0981, 1),
        (0x0910, 4),
        (0x0930, 2),
        (0x0934, 2),
        (0x0500, 1),
    ] {
        let (wkc, _) = dg(&mut c, Command::Bwr, Address::broadcast(r), &vec![0; l], 0);
        assert_eq!(wkc, n, "BWR {r:#06x} len {l}");
    }
    let (wkc, d) = dg(&mut c, Command::Brd, Address::broadcast(0x0000), &[0, 0], 0);
    assert_eq!((wkc, d), (2, vec![0x11, 0x00]));
    // APRD 0x0140: PDI control / ESC config loaded from SII word 0.
    let (wkc, d) = dg(
        &mut c,
        Command::Aprd,
        Address::position(1, reg::PDI_CONTROL),
        &[0, 0],
        0,
    );
    assert_eq!((wkc, u16le(&d)), (1, 0x0C08));
    for i in 0..2u16 {
        dg(
            &mut c,
            Command::Apwr,
            Address::position(i, 0x0010),
            &(0x1001 + i).to_le_bytes(),
            0,
        );
        let (wkc, _) = dg(
            &mut c,
            Command::Apwr,
            Address::position(i, 0x0100),
            &[0, 0],
            0,
        );
        assert_eq!(wkc, 1);
    }
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(0x1002, 0x0007),
        &[0, 0],
        0,
    );
    assert_eq!((wkc, d[0]), (1, 0x0F));
    // SM0 + SM1 in one 16-byte datagram, then PRE-OP.
    let mut sms = sm_bytes(MBX_OUT, MBX_LEN, 0x26, 1);
    sms.extend(sm_bytes(MBX_IN, MBX_LEN, 0x22, 1));
    let (wkc, _) = dg(
        &mut c,
        Command::Fpwr,
        Address::station(0x1002, 0x0800),
        &sms,
        0,
    );
    assert_eq!(wkc, 1);
    dg(
        &mut c,
        Command::Fpwr,
        Address::station(0x1002, reg::AL_CONTROL),
        &[0x02, 0],
        0,
    );
    // FPRD 0x0130 len 6: status + reserved + code.
    let (wkc, d) = dg(
        &mut c,
        Command::Fprd,
        Address::station(0x1002, 0x0130),
        &[0; 6],
        0,
    );
    assert_eq!((wkc, d), (1, vec![0x02, 0, 0, 0, 0, 0]));
    // Station alias addressing only once DL control bit 24 (0x0103 bit 0) is set.
    let (wkc, _) = dg(
        &mut c,
        Command::Fprd,
        Address::station(ALIAS, 0x0000),
        &[0],
        0,
    );
    assert_eq!(wkc, 0);
    dg(
        &mut c,
        Command::Apwr,
        Address::position(0, 0x0103),
        &[0x01],
        0,
    );
    let (wkc, _) = dg(
        &mut c,
        Command::Fprd,
        Address::station(ALIAS, 0x0000),
        &[0],
        0,
    );
    assert_eq!(wkc, 1);
}

#[test]
fn command_and_address_codec_roundtrip() {
    for code in 0u8..=0xFF {
        match Command::from_u8(code) {
            Some(c) => assert_eq!(c.code(), code),
            None => assert!(code > 0x0E),
        }
    }
    let a = Address::from_raw(Command::Fprd, 0x0130_1001);
    assert_eq!(a, Address::station(0x1001, 0x0130));
    assert_eq!(a.to_raw(), 0x0130_1001);
    assert_eq!(
        Address::from_raw(Command::Lrw, 0x0001_0000),
        Address::Logical(0x0001_0000)
    );
    // process_raw: APRD position 2 of 3 → ADP comes back as 1 (0xFFFE + 3).
    let mut c = chain(3);
    let mut wkc = 0;
    let raw = c.process_raw(
        0x01,
        Address::position(2, 0).to_raw(),
        &mut [0],
        &mut wkc,
        0,
    );
    assert_eq!((wkc, raw & 0xFFFF), (1, 1));
    // Reserved command codes pass untouched.
    let mut d = [0xAAu8; 2];
    let raw = c.process_raw(0x0F, 0x1234_5678, &mut d, &mut wkc, 0);
    assert_eq!((wkc, raw, d), (1, 0x1234_5678, [0xAA; 2]));
    // FPRW: read +1, write +2.
    dg(
        &mut c,
        Command::Apwr,
        Address::position(1, 0x0010),
        &[0x07, 0x00],
        0,
    );
    let (wkc, d) = dg(
        &mut c,
        Command::Fprw,
        Address::station(7, 0x0010),
        &[0x08, 0x00],
        0,
    );
    assert_eq!((wkc, d), (3, vec![0x07, 0x00]));
    assert_eq!(c.escs[1].station_address(), 8);
}

/// [`op_chain`] with ethercrab's process-image layout (notes §2.2): every device's inputs first
/// (device i at logical 2i), then every device's outputs (device i at 6 + 2i).
fn op_chain_inputs_first() -> EscChain {
    let mut c = op_chain();
    for i in 0..3u16 {
        let fmmu = |log: u32, phys: u16, ty: u8| {
            let mut f = log.to_le_bytes().to_vec();
            f.extend_from_slice(&2u16.to_le_bytes());
            f.extend_from_slice(&[0, 7]);
            f.extend_from_slice(&phys.to_le_bytes());
            f.extend_from_slice(&[0, ty, 1, 0, 0, 0]);
            f
        };
        let st = 0x1000 + i;
        let out = fmmu(6 + 2 * u32::from(i), 0x1100, 2);
        let inp = fmmu(2 * u32::from(i), 0x1180, 1);
        for (n, f) in [(0, out), (1, inp)] {
            let (wkc, _) = dg(
                &mut c,
                Command::Fpwr,
                Address::station(st, reg::fmmu(n)),
                &f,
                0,
            );
            assert_eq!(wkc, 1);
        }
    }
    c
}

/// Working counter an LRW over logical `[a, b)` of [`op_chain_inputs_first`] must return:
/// +1 per device whose input window it touches, +2 per device whose output window it touches
/// (ESC rule, notes §2.1), computed here from the layout, not from the emulator.
fn split_wkc(a: usize, b: usize) -> u16 {
    let touches = |s: usize| a < s + 2 && s < b;
    (0..3)
        .map(|i| u16::from(touches(2 * i)) + 2 * u16::from(touches(6 + 2 * i)))
        .sum()
}

/// A master that splits the image over several LRW datagrams (ethercrab does, one per frame,
/// when the image is longer than a frame): at every split point, and in three parts, the
/// devices get the same outputs and the master reads the same inputs as with one LRW, and
/// each part's working counter follows the ESC rule for the windows it covers.
#[test]
fn lrw_split_at_every_byte_equals_one_lrw() {
    let out = [0x11u8, 0x12, 0x21, 0x22, 0x31, 0x32];
    let image = |o: &[u8]| {
        let mut v = vec![0u8; 6];
        v.extend_from_slice(o);
        v
    };
    let cycles = [image(&out), image(&[1, 2, 3, 4, 5, 6])];
    let mut reference = op_chain_inputs_first();
    let want: Vec<(u16, Vec<u8>)> = cycles
        .iter()
        .map(|img| dg(&mut reference, Command::Lrw, Address::Logical(0), img, 0))
        .collect();
    assert_eq!(want[0].0, 9);
    // Cycle 2 reads the loopback of cycle 1's outputs.
    let inverted: Vec<u8> = out.iter().map(|b| !b).collect();
    assert_eq!(&want[1].1[..6], &inverted[..]);
    let mut splits: Vec<Vec<usize>> = (1..12).map(|k| vec![0, k, 12]).collect();
    splits.extend((1..11).map(|k| vec![0, k, k + 1, 12]));
    for cuts in splits {
        let mut c = op_chain_inputs_first();
        for (img, (want_wkc, want_data)) in cycles.iter().zip(&want) {
            let mut data = Vec::new();
            for w in cuts.windows(2) {
                let (a, b) = (w[0], w[1]);
                let (wkc, d) = dg(
                    &mut c,
                    Command::Lrw,
                    Address::Logical(a as u32),
                    &img[a..b],
                    0,
                );
                assert_eq!(wkc, split_wkc(a, b), "cuts {cuts:?}: part {a}..{b}");
                data.extend_from_slice(&d);
            }
            // The parts' counters do not add up to the whole one's where a cut falls inside a
            // device's window (that device counts in both parts): each part is checked alone.
            assert_eq!(*want_wkc, split_wkc(0, 12));
            assert_eq!(&data, want_data, "cuts {cuts:?}");
        }
        for i in 0..3 {
            assert_eq!(
                c.escs[i].peek(0x1100, 2),
                vec![2 * i as u8 + 1, 2 * i as u8 + 2]
            );
        }
    }
}
