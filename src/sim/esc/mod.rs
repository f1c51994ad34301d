//! Emulated EtherCAT SubDevice controller (ESC): register file, datagram processing with the
//! working-counter rules, AL state machine.
//!
//! The model is independent of any frame codec: [`Esc::process`] takes the fields of one
//! datagram (command, address, data, working counter) as the datagram passes this device, and
//! [`EscChain`] passes it through several devices in ring order. Spec source:
//! ETG.1000.4 (datagram semantics, registers, AL state machine) and what ethercrab 0.7.1 and
//! SOEM send during their start-up.
//!
//! Working-counter rules implemented (per ESC the datagram passes):
//! * physical read (APRD/FPRD/BRD) +1, physical write (APWR/FPWR/BWR) +1, read-write
//!   (APRW/FPRW/BRW) +1 for the read and +2 for the write (= +3);
//! * ARMW/FRMW: the addressed device reads (+1), every other device writes (+1);
//! * LRD +1 / LWR +1 / LRW +1 (read FMMU matched) +2 (write FMMU matched) per device;
//! * an access that touches no existing register (FMMU/SM beyond the configured count, the DC
//!   unit of a device without DC, memory beyond the RAM) does not count — so `BWR 0x0900`
//!   counts only DC-capable devices and `FPRD 0x0918` of a non-DC device gives WKC 0;
//! * an access refused by a mailbox sync manager (write into a full write mailbox, read of an
//!   empty read mailbox) does not count.
//!
//! Limitations (documented, deliberate): FMMU bit-granular mapping applies the logical start/stop
//! bit masks to the first/last byte but assumes the physical start bit equals the logical one
//! (no bit shifting); buffered (3-buffer) sync managers are modelled as a single buffer; the
//! DC control loop only records the difference (0x092C) and does not slew the local clock;
//! DL control loop/forwarding bits and the physical read/write offset (0x0108) are stored but
//! have no effect;
//! latch units are register storage only, the PDI watchdog is not modelled.
//!
//! Time-driven behaviour (sans-IO: the caller passes the time and asks for the next deadline):
//! * SYNC0 ([`dc::Sync0Unit`]): writing 0x0981 arms it from 0x0990 / 0x09A0;
//!   [`Esc::sync0_due_at`] says when the next pulse is due on the caller's clock,
//!   [`Esc::fire_sync0`] generates it and counts a sync error when no process data reached the
//!   device in OP since the previous pulse ([`Esc::sync_errors`]).
//! * Sync-manager (process-data) watchdog: [`Esc::watchdog_deadline`] and [`Esc::tick`] (0x0400,
//!   0x0420, 0x0440, 0x0442; expiry in OP → SAFE-OP with AL status code 0x001B and the
//!   application's outputs in their safe state, [`EscApplication::outputs_invalid`]).
//! * What happened is reported as [`EscEvent`]s ([`Esc::take_events`]).

pub mod app;
mod clock;
pub mod coe;
pub mod dc;
pub mod device;
pub mod pdo_rules;
pub mod raw;
pub mod sdo_info;
pub mod segment;
pub mod soe;
pub mod terminal;
pub mod types;
pub mod vendor;

use std::collections::VecDeque;

pub use app::{EchoApp, EscApplication, NullApp, ProcessDataSizes};
pub use clock::EscEvent;
pub use types::{reg, Address, AlState, AlStatusCode, Command};

/// Read-mailbox messages queued behind the one in the read mailbox at which the emulated
/// firmware stops taking requests: a real ESC has one buffer per mailbox direction, and its
/// firmware leaves a request in the write mailbox (SM0 full; the ESC refuses further master
/// writes with WKC 0, ETG.1000.4 §6.7.2 mailbox handshake) until it can place the reply. A
/// fragmented SoE reply or an EMCY before an SDO reply may queue a few messages, so the
/// threshold is a little above one.
pub const MAILBOX_HOLD_AT: usize = 4;

/// Hard bound of the read-mailbox queue: device-initiated messages (EMCY, fragments) beyond it
/// drop the oldest queued message (counted, [`Esc::mailbox_dropped`]).
pub const MAILBOX_QUEUE_MAX: usize = 64;

/// Standard mailbox configuration (SII words 0x0018..0x001B).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MailboxConfig {
    /// Receive (master → device, SM0) mailbox start address.
    pub rx_offset: u16,
    /// Receive mailbox size.
    pub rx_size: u16,
    /// Send (device → master, SM1) mailbox start address.
    pub tx_offset: u16,
    /// Send mailbox size.
    pub tx_size: u16,
}

/// Static configuration of one emulated ESC.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EscConfig {
    /// 0x0000 ESC type (0x11 = ET1100).
    pub esc_type: u8,
    /// 0x0001 revision.
    pub revision: u8,
    /// 0x0002 build.
    pub build: u16,
    /// 0x0004 number of FMMUs (≤ 16).
    pub fmmu_count: u8,
    /// 0x0005 number of sync managers (≤ 16).
    pub sm_count: u8,
    /// 0x0006 process RAM size in KiB (process RAM starts at 0x1000; total memory ≤ 64 KiB).
    pub ram_kib: u8,
    /// 0x0007 port descriptor (2 bits per port: 0 n/a, 1 unused, 2 EBUS, 3 MII).
    pub port_descriptor: u8,
    /// Distributed clocks unit present (sets feature bits 2/3/8 of 0x0008).
    pub dc: bool,
    /// SII interface reads 8 bytes per command (0x0502 bit 6), else 4.
    pub sii_read_8: bool,
    /// Standard mailbox expected on SM0/SM1 (checked on INIT → PRE-OP); `None` = no mailbox.
    pub mailbox: Option<MailboxConfig>,
    /// BOOT state supported.
    pub bootstrap: bool,
    /// Sync manager carrying the outputs (checked on PRE-OP → SAFE-OP); `u8::MAX`: none.
    pub output_sm: u8,
    /// Sync manager carrying the inputs; `u8::MAX`: none.
    pub input_sm: u8,
    /// SII EEPROM image (bytes, word 0 first).
    pub sii: Vec<u8>,
}

impl Default for EscConfig {
    fn default() -> Self {
        Self {
            esc_type: 0x11,
            revision: 0x00,
            build: 0x0002,
            fmmu_count: 8,
            sm_count: 8,
            ram_kib: 8,
            port_descriptor: 0x0F,
            dc: true,
            sii_read_8: true,
            mailbox: None,
            bootstrap: false,
            output_sm: 2,
            input_sm: 3,
            sii: Vec::new(),
        }
    }
}

impl EscConfig {
    /// Configuration derived from an SII image: standard mailbox from words 0x18..0x1B (if both
    /// sizes are non-zero; process data on SM2/SM3, else on SM0/SM1), BOOT if the bootstrap
    /// mailbox sizes (words 0x15/0x17) are non-zero.
    pub fn from_sii(sii: Vec<u8>) -> Self {
        let w = |i: usize| -> u16 {
            let lo = sii.get(2 * i).copied().unwrap_or(0);
            let hi = sii.get(2 * i + 1).copied().unwrap_or(0);
            u16::from_le_bytes([lo, hi])
        };
        let mbx = MailboxConfig {
            rx_offset: w(0x18),
            rx_size: w(0x19),
            tx_offset: w(0x1A),
            tx_size: w(0x1B),
        };
        let has_mbx = mbx.rx_size != 0 && mbx.tx_size != 0 && mbx.rx_size != 0xFFFF;
        let bootstrap = w(0x15) != 0 && w(0x17) != 0 && w(0x15) != 0xFFFF;
        // Process-data SMs: from the SII SyncManager category types when it has them, else
        // the usual layout (2/3 behind a mailbox, 0/1 without). A device with only inputs
        // (e.g. a timestamp terminal) has no output SM: u8::MAX.
        let typed = crate::esi::sii::decode_ignoring_checksum(&sii)
            .ok()
            .and_then(|c| {
                c.categories.iter().find_map(|cat| match cat {
                    crate::esi::sii::Category::SyncManagers(v) => {
                        Some(v.iter().map(|sm| sm.sm_type).collect::<Vec<u8>>())
                    }
                    _ => None,
                })
            })
            .filter(|t| t.iter().any(|&t| t != 0));
        let find = |ty: u8| {
            typed
                .as_ref()
                .and_then(|t| t.iter().position(|&x| x == ty))
                .map(|p| p as u8)
        };
        let (output_sm, input_sm) = match &typed {
            Some(_) => (
                find(crate::esi::sii::sm_type::OUTPUTS).unwrap_or(u8::MAX),
                find(crate::esi::sii::sm_type::INPUTS).unwrap_or(u8::MAX),
            ),
            None if has_mbx => (2, 3),
            None => (0, 1),
        };
        Self {
            mailbox: has_mbx.then_some(mbx),
            bootstrap,
            output_sm,
            input_sm,
            sii,
            ..Self::default()
        }
    }
}

/// Kind of access one device performs for one datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Op {
    Read,
    ReadOr,
    Write,
    ReadWrite,
    ReadOrWrite,
}

impl Op {
    fn reads(self) -> bool {
        !matches!(self, Op::Write)
    }
    fn writes(self) -> bool {
        matches!(self, Op::Write | Op::ReadWrite | Op::ReadOrWrite)
    }
    fn ors(self) -> bool {
        matches!(self, Op::ReadOr | Op::ReadOrWrite)
    }
}

/// Decoded sync manager register block.
#[derive(Debug, Clone, Copy)]
struct Sm {
    start: usize,
    len: usize,
    control: u8,
}

impl Sm {
    fn is_mailbox(&self) -> bool {
        self.control & 0x03 == 0x02
    }
    fn ecat_writes(&self) -> bool {
        (self.control >> 2) & 0x03 == 0x01
    }
    fn end(&self) -> usize {
        self.start + self.len
    }
    fn overlaps(&self, start: usize, len: usize) -> bool {
        start < self.end() && self.start < start + len
    }
    fn covers_last(&self, start: usize, len: usize) -> bool {
        self.len > 0 && start < self.end() && self.end() <= start + len
    }
}

/// One emulated EtherCAT SubDevice controller.
pub struct Esc {
    cfg: EscConfig,
    mem: Vec<u8>,
    state: AlState,
    app: Box<dyn EscApplication>,
    mbx_queue: VecDeque<Vec<u8>>,
    mailbox_dropped: u64,
    mailbox_held: u64,
    last_reply: Option<Vec<u8>>,
    port_linked: [bool; 4],
    port_return_ns: [u64; 4],
    local_clock_offset_ns: u64,
    /// Simulation time of the last output SM write or of the OP entry (process-data watchdog).
    last_output_ns: Option<u64>,
    sync0: dc::Sync0Unit,
    /// Process data reached an output SM in OP since the previous SYNC0.
    outputs_since_sync0: bool,
    /// The device was in OP at the previous SYNC0.
    op_at_last_sync0: bool,
    sync_errors: u64,
    events: Vec<EscEvent>,
    /// Reused buffer of the logical datagrams' write bytes.
    scratch: Vec<u8>,
    /// [`Self::watchdog_guarded`], computed once per sync-manager configuration.
    wd_guarded: std::cell::Cell<Option<bool>>,
}

/// Which bits of each byte of an FMMU segment are mapped: the FMMU's start bit on its first
/// byte, its stop bit on its last, every bit in between.
#[derive(Debug, Clone, Copy, Default)]
struct ByteMasks {
    first: u8,
    last: u8,
    len: usize,
}

impl ByteMasks {
    /// Mask of byte `i` of the segment.
    fn at(&self, i: usize) -> u8 {
        let mut m = 0xFF;
        if i == 0 {
            m &= self.first;
        }
        if i + 1 == self.len {
            m &= self.last;
        }
        m
    }
}

/// One FMMU's part of a logical datagram at one device.
#[derive(Debug, Clone, Copy, Default)]
struct LogicalSegment {
    /// Offset in the datagram's data.
    off: usize,
    /// Physical address of its first byte.
    phys: usize,
    masks: ByteMasks,
    /// Write FMMU (else read).
    write: bool,
}

impl std::fmt::Debug for Esc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Esc")
            .field("station", &self.station_address())
            .field("state", &self.state)
            .field("al_status_code", &self.al_status_code())
            .finish_non_exhaustive()
    }
}

fn range_overlaps(start: usize, len: usize, reg: u16, reg_len: usize) -> bool {
    let r = usize::from(reg);
    start < r + reg_len && r < start + len.max(1)
}

/// CRC-8 (poly 0x07, init 0xFF) of the SII configuration area (bytes 0..14), as in ETG.2010
/// (the one implementation, [`crate::esi::sii::crc8`]).
pub use crate::esi::sii::crc8 as sii_crc8;

impl Esc {
    /// New ESC in INIT, registers loaded from the SII image (words 0..4), port 0 linked.
    pub fn new(cfg: EscConfig, app: Box<dyn EscApplication>) -> Self {
        let mem_len = (0x1000 + usize::from(cfg.ram_kib) * 1024).min(0x1_0000);
        let mut esc = Self {
            mem: vec![0; mem_len],
            state: AlState::Init,
            app,
            mbx_queue: VecDeque::new(),
            mailbox_dropped: 0,
            mailbox_held: 0,
            last_reply: None,
            port_linked: [true, false, false, false],
            port_return_ns: [0; 4],
            local_clock_offset_ns: 0,
            last_output_ns: None,
            sync0: dc::Sync0Unit::default(),
            outputs_since_sync0: false,
            op_at_last_sync0: false,
            sync_errors: 0,
            events: Vec::new(),
            scratch: Vec::new(),
            wd_guarded: std::cell::Cell::new(None),
            cfg,
        };
        esc.power_on();
        esc
    }

    fn power_on(&mut self) {
        let c = self.cfg.clone();
        self.mem[0x0000] = c.esc_type;
        self.mem[0x0001] = c.revision;
        self.put(reg::BUILD, &c.build.to_le_bytes());
        self.mem[0x0004] = c.fmmu_count.min(16);
        self.mem[0x0005] = c.sm_count.min(16);
        self.mem[0x0006] = c.ram_kib;
        self.mem[0x0007] = c.port_descriptor;
        // bit 2 DC, bit 3 64-bit DC, bit 8 enhanced DC SYNC activation; bits 4..7 link
        // detection / FCS handling as on EL2828 (0x01FC).
        let features: u16 = if c.dc { 0x01FC } else { 0x00F0 };
        self.put(reg::FEATURES, &features.to_le_bytes());
        self.mem[usize::from(reg::AL_STATUS)] = AlState::Init.bits();
        self.put(reg::WD_DIVIDER, &0x09C2u16.to_le_bytes());
        self.put(reg::WD_TIME_PDI, &1000u16.to_le_bytes());
        self.put(reg::WD_TIME_PD, &1000u16.to_le_bytes());
        self.mem[usize::from(reg::WD_STATUS_PD)] = 0x01;
        self.mem[usize::from(reg::SII_CONTROL)] =
            if c.sii_read_8 { 0x40 } else { 0x00 } | if c.sii.len() > 2048 { 0x80 } else { 0 };
        self.sii_reload();
        self.update_dl_status();
        self.update_sm_pdi_control();
    }

    /// Load the registers the ESC takes from the SII configuration area; returns false (and
    /// sets the checksum error bit 0x0502.11) if the CRC in word 7 does not match.
    fn sii_reload(&mut self) -> bool {
        let w = |sii: &[u8], i: usize| -> [u8; 2] {
            [
                sii.get(2 * i).copied().unwrap_or(0),
                sii.get(2 * i + 1).copied().unwrap_or(0),
            ]
        };
        let sii = self.cfg.sii.clone();
        self.put(reg::PDI_CONTROL, &w(&sii, 0));
        self.put(reg::PDI_CONFIG, &w(&sii, 1));
        self.put(reg::DC_PULSE_LENGTH, &w(&sii, 2));
        self.put(0x0152, &w(&sii, 3));
        self.put(reg::STATION_ALIAS, &w(&sii, 4));
        let ok = sii.len() >= 16 && sii_crc8(&sii[..14]) == sii[14];
        let c = usize::from(reg::SII_CONTROL) + 1;
        if ok {
            self.mem[c] &= !0x08;
        } else {
            self.mem[c] |= 0x08;
        }
        ok
    }

    fn put(&mut self, addr: u16, bytes: &[u8]) {
        let a = usize::from(addr);
        self.mem[a..a + bytes.len()].copy_from_slice(bytes);
    }

    // ---------------------------------------------------------------- public inspection API

    /// Configuration this ESC was built with.
    pub fn config(&self) -> &EscConfig {
        &self.cfg
    }

    /// Raw memory bytes (no side effects); out-of-range bytes read as 0.
    pub fn peek(&self, addr: u16, len: usize) -> Vec<u8> {
        (0..len)
            .map(|i| self.mem.get(usize::from(addr) + i).copied().unwrap_or(0))
            .collect()
    }

    /// `N` raw bytes from `addr` without allocating; out-of-range bytes read as 0.
    fn peek_array<const N: usize>(&self, addr: u16) -> [u8; N] {
        let mut b = [0u8; N];
        let start = usize::from(addr);
        if let Some(src) = self.mem.get(start..(start + N).min(self.mem.len())) {
            b[..src.len()].copy_from_slice(src);
        }
        b
    }

    /// Raw u8 register.
    pub fn peek_u8(&self, addr: u16) -> u8 {
        self.peek_array::<1>(addr)[0]
    }

    /// Raw little-endian u16 register.
    pub fn peek_u16(&self, addr: u16) -> u16 {
        u16::from_le_bytes(self.peek_array(addr))
    }

    /// Raw little-endian u32 register.
    pub fn peek_u32(&self, addr: u16) -> u32 {
        u32::from_le_bytes(self.peek_array(addr))
    }

    /// Raw little-endian u64 register.
    pub fn peek_u64(&self, addr: u16) -> u64 {
        u64::from_le_bytes(self.peek_array(addr))
    }

    /// A sync manager register or the AL state may have changed: forget what was derived from
    /// them.
    fn sm_config_changed(&self) {
        self.wd_guarded.set(None);
    }

    /// Write memory from the PDI side (no ECAT write protection, no side effects).
    pub fn poke(&mut self, addr: u16, bytes: &[u8]) {
        self.sm_config_changed();
        for (i, b) in bytes.iter().enumerate() {
            if let Some(m) = self.mem.get_mut(usize::from(addr) + i) {
                *m = *b;
            }
        }
    }

    /// Current AL state.
    pub fn al_state(&self) -> AlState {
        self.state
    }

    /// AL status register 0x0130 (state | 0x10 error).
    pub fn al_status(&self) -> u16 {
        self.peek_u16(reg::AL_STATUS)
    }

    /// AL status code register 0x0134.
    pub fn al_status_code(&self) -> AlStatusCode {
        AlStatusCode(self.peek_u16(reg::AL_STATUS_CODE))
    }

    /// Configured station address 0x0010.
    pub fn station_address(&self) -> u16 {
        self.peek_u16(reg::STATION_ADDRESS)
    }

    /// The SII image (including writes by the master).
    pub fn sii(&self) -> &[u8] {
        &self.cfg.sii
    }

    /// The application behind the PDI.
    pub fn app(&self) -> &dyn EscApplication {
        self.app.as_ref()
    }

    /// The application behind the PDI, mutable.
    pub fn app_mut(&mut self) -> &mut dyn EscApplication {
        self.app.as_mut()
    }

    /// Set the link state of `port` (1..3) and the time a frame leaving through it needs to
    /// come back (used for the DC receive time latches). Port 0 is always linked.
    pub fn set_port_link(&mut self, port: usize, linked: bool, return_delay_ns: u64) {
        if (1..4).contains(&port) {
            self.port_linked[port] = linked;
            self.port_return_ns[port] = return_delay_ns;
            self.update_dl_status();
        }
    }

    /// Offset of this device's free-running local clock against the simulation clock.
    pub fn set_local_clock_offset(&mut self, ns: u64) {
        self.local_clock_offset_ns = ns;
    }

    /// Local DC time at simulation time `now_ns`.
    pub fn local_time(&self, now_ns: u64) -> u64 {
        now_ns.wrapping_add(self.local_clock_offset_ns)
    }

    /// DC system time (local time + offset 0x0920) at simulation time `now_ns`.
    pub fn system_time(&self, now_ns: u64) -> u64 {
        self.local_time(now_ns)
            .wrapping_add(self.peek_u64(reg::DC_SYSTEM_TIME_OFFSET))
    }

    /// ECAT event request (0x0210) masked with the ECAT event mask (0x0200): the bits this
    /// device ORs into the IRQ field of every datagram it forwards.
    pub fn irq(&self) -> u16 {
        self.peek_u16(reg::ECAT_EVENT_REQUEST) & self.peek_u16(reg::ECAT_EVENT_MASK)
    }

    /// Queue a device-initiated mailbox message (e.g. CoE emergency) for the read mailbox.
    pub fn push_mailbox(&mut self, msg: Vec<u8>) {
        self.enqueue_mailbox([msg]);
    }

    /// Move the application's device-initiated messages ([`EscApplication::take_outgoing`])
    /// into the read-mailbox queue.
    pub fn poll_app_mailbox(&mut self) {
        let msgs = self.app.take_outgoing();
        if !msgs.is_empty() {
            self.enqueue_mailbox(msgs);
        }
    }

    /// Application-initiated error: go to `state` (if lower than the current one) and set the
    /// error indication with `code` (e.g. SM watchdog → SAFE-OP + 0x001B).
    pub fn raise_al_error(&mut self, state: AlState, code: AlStatusCode) {
        if state < self.state {
            self.enter_state(state);
        }
        self.set_error(code);
    }

    /// Process-data watchdog time in ns: 0x0420 × (0x0400 + 2) × 40 ns (0 = disabled).
    pub fn pd_watchdog_ns(&self) -> u64 {
        let div = u64::from(self.peek_u16(reg::WD_DIVIDER)) + 2;
        u64::from(self.peek_u16(reg::WD_TIME_PD)) * div * 40
    }

    // ---------------------------------------------------------------- datagram processing

    /// Process one datagram as it passes this device.
    ///
    /// `addr` is updated like the ESC does on the wire (ADP incremented for auto-increment and
    /// broadcast commands), `data` is read/written in place, `wkc` is incremented per the ESC
    /// rules (see the module docs). `now_ns` is the simulation time the frame reaches this
    /// device. Never panics for any input.
    pub fn process(
        &mut self,
        cmd: Command,
        addr: &mut Address,
        data: &mut [u8],
        wkc: &mut u16,
        now_ns: u64,
    ) {
        match (cmd, *addr) {
            (Command::Nop, _) => {}
            (Command::Lrd | Command::Lwr | Command::Lrw, Address::Logical(la)) => {
                self.logical(cmd, la, data, wkc, now_ns)
            }
            (_, Address::Physical { adp, ado }) if !cmd.is_logical() => {
                let station_match = self.matches_station(adp);
                let (addressed, next_adp) = match cmd {
                    Command::Aprd | Command::Apwr | Command::Aprw | Command::Armw => {
                        (adp == 0, adp.wrapping_add(1))
                    }
                    Command::Brd | Command::Bwr | Command::Brw => (true, adp.wrapping_add(1)),
                    _ => (station_match, adp),
                };
                *addr = Address::Physical { adp: next_adp, ado };
                let op = match cmd {
                    Command::Aprd | Command::Fprd if addressed => Some(Op::Read),
                    Command::Apwr | Command::Fpwr | Command::Bwr if addressed => Some(Op::Write),
                    Command::Aprw | Command::Fprw if addressed => Some(Op::ReadWrite),
                    Command::Brd => Some(Op::ReadOr),
                    Command::Brw => Some(Op::ReadOrWrite),
                    Command::Armw | Command::Frmw => {
                        Some(if addressed { Op::Read } else { Op::Write })
                    }
                    _ => None,
                };
                if let Some(op) = op {
                    let (r, w) = self.phys_access(usize::from(ado), data, op, None, now_ns);
                    let mut inc = 0u16;
                    if r {
                        inc += 1;
                    }
                    if w {
                        inc += if op.reads() { 2 } else { 1 };
                    }
                    *wkc = wkc.wrapping_add(inc);
                }
            }
            _ => {}
        }
    }

    fn matches_station(&self, adp: u16) -> bool {
        if adp == self.station_address() {
            return true;
        }
        // DL control bit 24: station alias enabled.
        let alias_enabled = self.mem[usize::from(reg::DL_CONTROL) + 3] & 0x01 != 0;
        alias_enabled && adp == self.peek_u16(reg::STATION_ALIAS)
    }

    fn logical(&mut self, cmd: Command, la: u32, data: &mut [u8], wkc: &mut u16, now: u64) {
        let reads = matches!(cmd, Command::Lrd | Command::Lrw);
        let writes = matches!(cmd, Command::Lwr | Command::Lrw);
        let dg_start = u64::from(la);
        let dg_end = dg_start + data.len() as u64;
        // At most two segments (read, write) per FMMU; kept on the stack (no allocation on the
        // process-data path).
        let mut segs = [LogicalSegment::default(); 32];
        let mut nsegs = 0;
        for n in 0..u16::from(self.mem[0x0004].min(16)) {
            let b: [u8; 16] = self.peek_array(reg::fmmu(n));
            if b[12] & 0x01 == 0 {
                continue;
            }
            let log = u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
            let flen = u64::from(u16::from_le_bytes([b[4], b[5]]));
            let (start_bit, stop_bit) = (b[6] & 7, b[7] & 7);
            let phys = usize::from(u16::from_le_bytes([b[8], b[9]]));
            let ty = b[11];
            let (s, e) = (log.max(dg_start), (log + flen).min(dg_end));
            if flen == 0 || s >= e {
                continue;
            }
            let count = (e - s) as usize;
            let fm_off = (s - log) as usize;
            // The FMMU's start / stop bits apply to its first / last byte only.
            let masks = ByteMasks {
                first: if fm_off == 0 { 0xFF << start_bit } else { 0xFF },
                last: if s + count as u64 == log + flen {
                    0xFF >> (7 - stop_bit)
                } else {
                    0xFF
                },
                len: count,
            };
            let seg = LogicalSegment {
                off: (s - dg_start) as usize,
                phys: phys + fm_off,
                masks,
                write: false,
            };
            if ty & 0x02 != 0 && writes && nsegs < segs.len() {
                segs[nsegs] = LogicalSegment { write: true, ..seg };
                nsegs += 1;
            }
            if ty & 0x01 != 0 && reads && nsegs < segs.len() {
                segs[nsegs] = seg;
                nsegs += 1;
            }
        }
        let segs = &segs[..nsegs];
        if segs.is_empty() {
            return;
        }
        // The bytes the writes take, as they arrived (a read through another FMMU may overwrite
        // them in the datagram first), in a buffer the device keeps.
        let mut incoming = std::mem::take(&mut self.scratch);
        incoming.clear();
        for seg in segs.iter().filter(|s| s.write) {
            incoming.extend_from_slice(&data[seg.off..seg.off + seg.masks.len]);
        }
        let (mut read_hit, mut write_hit) = (false, false);
        // Reads first: the datagram sees the memory as it was when it arrived (the PDI does not
        // run between the bytes of one datagram), then the outputs are written.
        for seg in segs.iter().filter(|s| !s.write) {
            let (r, _) = self.phys_access(
                seg.phys,
                &mut data[seg.off..seg.off + seg.masks.len],
                Op::Read,
                Some(seg.masks),
                now,
            );
            read_hit |= r;
        }
        let mut at = 0;
        for seg in segs.iter().filter(|s| s.write) {
            let buf = &mut incoming[at..at + seg.masks.len];
            at += seg.masks.len;
            let (_, w) = self.phys_access(seg.phys, buf, Op::Write, Some(seg.masks), now);
            write_hit |= w;
        }
        self.scratch = incoming;
        let mut inc = 0u16;
        if read_hit {
            inc += 1;
        }
        if write_hit {
            inc += if cmd == Command::Lrw { 2 } else { 1 };
        }
        *wkc = wkc.wrapping_add(inc);
    }

    fn byte_exists(&self, a: usize) -> bool {
        if a >= self.mem.len() {
            return false;
        }
        match a {
            0x0600..=0x06FF => (a - 0x0600) / 16 < usize::from(self.mem[0x0004]),
            0x0800..=0x087F => (a - 0x0800) / 8 < usize::from(self.mem[0x0005]),
            0x0900..=0x09FF => self.cfg.dc,
            _ => true,
        }
    }

    /// ECAT-writable bits of byte `a` (side-effect-only registers report 0).
    fn writable_mask(&self, a: usize) -> u8 {
        if !self.byte_exists(a) {
            return 0;
        }
        match a {
            0x0010..=0x0011 | 0x0100..=0x0103 | 0x0108..=0x0109 | 0x0120..=0x0121 => 0xFF,
            0x0200..=0x0201 => 0xFF,
            0x0400..=0x0401 | 0x0410..=0x0411 | 0x0420..=0x0421 => 0xFF,
            0x0500 => 0x01,
            0x0502 => 0x01,
            0x0503 => 0x07,
            0x0504..=0x050F => 0xFF,
            0x0600..=0x06FF => 0xFF,
            0x0800..=0x087F => match (a - 0x0800) % 8 {
                0..=4 => 0xFF,
                6 => 0x03,
                _ => 0,
            },
            0x0920..=0x092B | 0x0930..=0x0931 | 0x0934..=0x0935 => 0xFF,
            0x0980..=0x0981 | 0x0990..=0x0997 | 0x09A0..=0x09A9 => 0xFF,
            a if a >= 0x1000 => 0xFF,
            _ => 0,
        }
    }

    fn active_sm(&self, n: usize) -> Option<Sm> {
        if n >= usize::from(self.mem[0x0005].min(16)) {
            return None;
        }
        let base = 0x0800 + 8 * n;
        let b = &self.mem[base..base + 8];
        let sm = Sm {
            start: usize::from(u16::from_le_bytes([b[0], b[1]])),
            len: usize::from(u16::from_le_bytes([b[2], b[3]])),
            control: b[4],
        };
        (b[6] & 0x01 != 0 && b[7] & 0x01 == 0 && sm.len > 0).then_some(sm)
    }

    fn sm_full(&self, n: usize) -> bool {
        self.mem[0x0805 + 8 * n] & 0x08 != 0
    }

    fn set_sm_full(&mut self, n: usize, full: bool) {
        let a = 0x0805 + 8 * n;
        if full {
            self.mem[a] |= 0x08;
        } else {
            self.mem[a] &= !0x08;
        }
        // ECAT event request bits 4.. mirror the SM status (read mailbox full → master IRQ).
        if n < 8 {
            let ev = usize::from(reg::ECAT_EVENT_REQUEST) + (4 + n) / 8;
            let bit = 1u8 << ((4 + n) % 8);
            if full {
                self.mem[ev] |= bit;
            } else {
                self.mem[ev] &= !bit;
            }
        }
    }

    fn sm_count(&self) -> usize {
        usize::from(self.mem[0x0005].min(16))
    }

    /// One device's physical access to `[start, start+len)`; returns (read counted, write
    /// counted).
    fn phys_access(
        &mut self,
        start: usize,
        data: &mut [u8],
        op: Op,
        masks: Option<ByteMasks>,
        now: u64,
    ) -> (bool, bool) {
        let len = data.len();
        if !(start..start + len.max(1)).any(|a| self.byte_exists(a)) {
            return (false, false);
        }
        let (mut r_ok, mut w_ok) = (op.reads(), op.writes());
        // Sync manager gating.
        for n in 0..self.sm_count() {
            let Some(sm) = self.active_sm(n) else {
                continue;
            };
            if !sm.overlaps(start, len.max(1)) {
                continue;
            }
            if self.mailbox_sm(n, &sm) {
                if sm.ecat_writes() {
                    r_ok = false;
                    if self.sm_full(n) {
                        w_ok = false;
                    }
                } else {
                    w_ok = false;
                    if !self.sm_full(n) {
                        r_ok = false;
                    }
                }
            } else if !sm.ecat_writes() {
                w_ok = false;
            }
        }
        // A read-write access keeps the bytes to write before the read replaces them.
        let incoming = (w_ok && r_ok).then(|| data.to_vec());
        if r_ok {
            self.refresh_before_read(start, len, now);
            for (i, d) in data.iter_mut().enumerate() {
                let a = start + i;
                let v = if self.byte_exists(a) { self.mem[a] } else { 0 };
                if op.ors() {
                    *d |= v;
                } else {
                    let m = masks.map_or(0xFF, |m| m.at(i));
                    *d = (*d & !m) | (v & m);
                }
            }
            self.after_read(start, len);
        }
        if w_ok {
            let inc: &[u8] = incoming.as_deref().unwrap_or(data);
            let mut old_act = [0u8; 16];
            for (n, o) in old_act.iter_mut().enumerate().take(self.sm_count()) {
                *o = self.mem[0x0806 + 8 * n];
            }
            for (i, b) in inc.iter().enumerate() {
                let a = start + i;
                let m = self.writable_mask(a) & masks.map_or(0xFF, |m| m.at(i));
                if m != 0 {
                    self.mem[a] = (self.mem[a] & !m) | (b & m);
                }
            }
            self.after_write(start, inc, &old_act[..self.sm_count()], now);
        }
        (r_ok, w_ok)
    }

    fn refresh_before_read(&mut self, start: usize, len: usize, now: u64) {
        if self.cfg.dc && range_overlaps(start, len, reg::DC_SYSTEM_TIME, 8) {
            let t = self.system_time(now);
            self.put(reg::DC_SYSTEM_TIME, &t.to_le_bytes());
        }
        if self.cfg.dc && range_overlaps(start, len, reg::DC_START_TIME, 8) {
            // Read back: the system time of the next SYNC0 pulse (while SYNC0 runs).
            if let Some(next) = self.sync0.next_pulse() {
                self.put(reg::DC_START_TIME, &next.to_le_bytes());
            }
        }
        if matches!(self.state, AlState::SafeOp | AlState::Op) {
            for n in 0..self.sm_count() {
                let Some(sm) = self.active_sm(n) else {
                    continue;
                };
                if self.mailbox_sm(n, &sm)
                    || sm.ecat_writes()
                    || !(start..start + len).contains(&sm.start)
                {
                    continue;
                }
                let end = sm.end().min(self.mem.len());
                if sm.start >= end {
                    continue;
                }
                self.app.inputs(n as u8, &mut self.mem[sm.start..end]);
            }
        }
    }

    fn after_read(&mut self, start: usize, len: usize) {
        if range_overlaps(start, len, reg::AL_STATUS, 2) {
            self.mem[usize::from(reg::ECAT_EVENT_REQUEST)] &= !0x08;
        }
        for n in 0..self.sm_count() {
            let Some(sm) = self.active_sm(n) else {
                continue;
            };
            if self.mailbox_sm(n, &sm) && !sm.ecat_writes() && sm.covers_last(start, len) {
                self.set_sm_full(n, false);
                self.load_read_mailbox();
                self.release_held_request();
            }
        }
    }

    /// The emulated PDI reads the write mailbox `n` (full): the application handles the
    /// request, its reply and device-initiated messages go to the read-mailbox queue.
    fn consume_write_mailbox(&mut self, n: usize, sm: &Sm) {
        let msg = self.mem[sm.start..sm.end()].to_vec();
        let reply = self.app.mailbox_received(&msg);
        self.set_sm_full(n, false);
        let mut msgs: Vec<Vec<u8>> = reply.into_iter().collect();
        msgs.extend(self.app.take_outgoing());
        self.enqueue_mailbox(msgs);
    }

    /// A request held in the write mailbox ([`MAILBOX_HOLD_AT`]) is taken once the queue has
    /// room again.
    fn release_held_request(&mut self) {
        if self.mbx_queue.len() >= MAILBOX_HOLD_AT {
            return;
        }
        let held = (0..self.sm_count()).find_map(|n| {
            self.active_sm(n)
                .filter(|sm| {
                    self.mailbox_sm(n, sm) && sm.ecat_writes() && sm.end() <= self.mem.len()
                })
                .map(|sm| (n, sm))
        });
        if let Some((n, sm)) = held {
            if self.sm_full(n) {
                self.consume_write_mailbox(n, &sm);
            }
        }
    }

    /// Queue messages for the read mailbox; beyond [`MAILBOX_QUEUE_MAX`] the oldest are dropped
    /// and counted ([`Self::mailbox_dropped`]).
    fn enqueue_mailbox(&mut self, msgs: impl IntoIterator<Item = Vec<u8>>) {
        self.mbx_queue.extend(msgs);
        while self.mbx_queue.len() > MAILBOX_QUEUE_MAX {
            self.mbx_queue.pop_front();
            self.mailbox_dropped += 1;
            if self.mailbox_dropped.is_power_of_two() {
                tracing::warn!(
                    target: "fieldprobe::sim::esc",
                    station = self.station_address(),
                    "read mailbox queue full ({MAILBOX_QUEUE_MAX} messages unread): oldest dropped ({} so far)",
                    self.mailbox_dropped
                );
            }
        }
        self.load_read_mailbox();
    }

    /// Messages waiting for the read mailbox behind the one in it (bounded by
    /// [`MAILBOX_QUEUE_MAX`]).
    pub fn mailbox_queue_len(&self) -> usize {
        self.mbx_queue.len()
    }

    /// Device-initiated messages dropped because the read-mailbox queue was full.
    pub fn mailbox_dropped(&self) -> u64 {
        self.mailbox_dropped
    }

    /// Mailbox requests the device held in the write mailbox because its reply queue was full
    /// (each refused further writes until the master read the read mailbox).
    pub fn mailbox_held(&self) -> u64 {
        self.mailbox_held
    }

    fn after_write(&mut self, start: usize, inc: &[u8], old_act: &[u8], now: u64) {
        let len = inc.len();
        if range_overlaps(start, len, 0x0800, 0x80) {
            self.sm_config_changed();
        }
        let byte_at = |a: u16| -> Option<u8> {
            let a = usize::from(a);
            (a >= start && a < start + len).then(|| inc[a - start])
        };
        if range_overlaps(start, len, reg::AL_CONTROL, 2) {
            let before = self.state;
            self.al_control_written();
            if self.state == AlState::Op && before != AlState::Op {
                // The process-data watchdog counts from the OP entry.
                self.last_output_ns = Some(now);
            }
        }
        if range_overlaps(start, len, reg::RX_ERROR_COUNTER, 12) {
            self.mem[0x0300..0x030C].fill(0);
        }
        for a in 0x0310..0x0314usize {
            if a >= start && a < start + len {
                self.mem[a] = 0;
            }
        }
        for a in 0x0442..0x0444usize {
            if a >= start && a < start + len {
                self.mem[a] = 0;
            }
        }
        if let Some(v) = byte_at(reg::SII_CONFIG) {
            if v & 0x02 != 0 {
                // Force ECAT access: PDI loses the EEPROM.
                self.mem[usize::from(reg::SII_PDI_ACCESS)] &= !0x01;
            }
        }
        if byte_at(reg::SII_CONTROL + 1).is_some() {
            self.sii_command();
        }
        // Sync managers: activation changes, repeat requests.
        for n in 0..self.sm_count() {
            let base = 0x0800 + 8 * n;
            if !(start < base + 7 && base < start + len) {
                continue;
            }
            let old = old_act.get(n).copied().unwrap_or(0);
            let new = self.mem[base + 6];
            if (old ^ new) & 0x01 != 0 {
                self.set_sm_full(n, false);
            }
            if let Some(sm) = self.active_sm(n) {
                if self.mailbox_sm(n, &sm) && !sm.ecat_writes() {
                    if (old ^ new) & 0x02 != 0 && old & 0x01 != 0 {
                        // Repeat request: put the last reply back and acknowledge.
                        if let Some(last) = self.last_reply.clone() {
                            self.fill_sm(&sm, &last);
                            self.set_sm_full(n, true);
                        }
                        self.mem[base + 7] = (self.mem[base + 7] & !0x02) | (new & 0x02);
                    }
                    self.load_read_mailbox();
                }
            }
        }
        // Mailbox / process data completion (last byte written).
        for n in 0..self.sm_count() {
            let Some(sm) = self.active_sm(n) else {
                continue;
            };
            if !sm.ecat_writes() || !sm.covers_last(start, len) || sm.end() > self.mem.len() {
                continue;
            }
            if self.mailbox_sm(n, &sm) {
                self.set_sm_full(n, true);
                if self.mbx_queue.len() >= MAILBOX_HOLD_AT {
                    // The firmware's reply buffer is taken: the request stays in the write
                    // mailbox (SM0 full, further master writes refused) until the master reads.
                    self.mailbox_held += 1;
                    continue;
                }
                self.consume_write_mailbox(n, &sm);
            } else {
                if sm.control & 0x40 != 0 {
                    self.last_output_ns = Some(now);
                    self.mem[usize::from(reg::WD_STATUS_PD)] |= 0x01;
                }
                if self.state != AlState::Op {
                    continue;
                }
                self.outputs_since_sync0 = true;
                self.app
                    .outputs_written(n as u8, &self.mem[sm.start..sm.end()]);
            }
        }
        if self.cfg.dc {
            if range_overlaps(start, len, reg::DC_RECV_TIME_PORT0, 4) {
                self.latch_receive_times(now);
            }
            if range_overlaps(start, len, reg::DC_SYSTEM_TIME, 8) {
                let mut cur = self.system_time(now).to_le_bytes();
                for (i, c) in cur.iter_mut().enumerate() {
                    if let Some(v) = byte_at(reg::DC_SYSTEM_TIME + i as u16) {
                        *c = v;
                    }
                }
                let written = u64::from_le_bytes(cur);
                let local = self.system_time(now);
                // 0x092C: bit 31 = 1 if local copy ≥ received time, bits 0..30 magnitude.
                let diff = if local >= written {
                    0x8000_0000 | (local - written).min(0x7FFF_FFFF) as u32
                } else {
                    (written - local).min(0x7FFF_FFFF) as u32
                };
                self.put(reg::DC_SYSTEM_TIME_DIFF, &diff.to_le_bytes());
            }
            if range_overlaps(start, len, reg::DC_SPEED_COUNTER_START, 2) {
                self.put(reg::DC_SPEED_COUNTER_DIFF, &[0, 0]);
            }
            if range_overlaps(start, len, reg::DC_SYNC_ACTIVATION, 1) {
                self.sync_activation_written(now);
            }
        }
    }

    fn latch_receive_times(&mut self, now: u64) {
        let t0 = self.local_time(now);
        for p in 0..4 {
            let t = if p > 0 && self.port_linked[p] {
                t0.wrapping_add(self.port_return_ns[p])
            } else {
                t0
            };
            self.put(
                reg::DC_RECV_TIME_PORT0 + 4 * p as u16,
                &(t as u32).to_le_bytes(),
            );
        }
        self.put(reg::DC_RECV_TIME_EPU, &t0.to_le_bytes());
    }

    fn fill_sm(&mut self, sm: &Sm, msg: &[u8]) {
        let end = sm.end().min(self.mem.len());
        if sm.start >= end {
            return;
        }
        let area = &mut self.mem[sm.start..end];
        area.fill(0);
        let n = msg.len().min(area.len());
        area[..n].copy_from_slice(&msg[..n]);
    }

    fn read_mailbox_sm(&self) -> Option<(usize, Sm)> {
        (0..self.sm_count()).find_map(|n| {
            self.active_sm(n)
                .filter(|sm| self.mailbox_sm(n, sm) && !sm.ecat_writes())
                .map(|sm| (n, sm))
        })
    }

    fn load_read_mailbox(&mut self) {
        let Some((n, sm)) = self.read_mailbox_sm() else {
            return;
        };
        if self.sm_full(n) {
            return;
        }
        if let Some(msg) = self.mbx_queue.pop_front() {
            self.fill_sm(&sm, &msg);
            self.set_sm_full(n, true);
            self.last_reply = Some(msg);
        }
    }

    // ---------------------------------------------------------------- SII

    fn sii_command(&mut self) {
        let c = usize::from(reg::SII_CONTROL);
        let cmd = self.mem[c + 1] & 0x07;
        // Clear command bits and the error bits 11 (checksum kept), 13, 14; never busy.
        self.mem[c + 1] &= 0x08;
        if self.mem[usize::from(reg::SII_CONFIG)] & 0x01 != 0 {
            // EEPROM assigned to the PDI: ECAT commands are not executed.
            return;
        }
        let word = self.peek_u32(reg::SII_ADDRESS) as usize;
        match cmd {
            0 => {}
            1 => {
                let n = if self.cfg.sii_read_8 { 8 } else { 4 };
                for i in 0..n {
                    let v = word
                        .checked_mul(2)
                        .and_then(|b| self.cfg.sii.get(b + i))
                        .copied()
                        .unwrap_or(0xFF);
                    self.mem[usize::from(reg::SII_DATA) + i] = v;
                }
            }
            2 => {
                if self.mem[c] & 0x01 == 0 {
                    self.mem[c + 1] |= 0x40; // write enable error
                } else {
                    let b = word.saturating_mul(2);
                    if b + 1 < self.cfg.sii.len() {
                        let d = usize::from(reg::SII_DATA);
                        self.cfg.sii[b] = self.mem[d];
                        self.cfg.sii[b + 1] = self.mem[d + 1];
                    } else {
                        self.mem[c + 1] |= 0x20; // no acknowledge
                    }
                }
                self.mem[c] &= !0x01;
            }
            4 => {
                self.sii_reload();
            }
            _ => self.mem[c + 1] |= 0x20, // command error
        }
    }

    // ---------------------------------------------------------------- AL state machine

    fn set_error(&mut self, code: AlStatusCode) {
        let a = usize::from(reg::AL_STATUS);
        self.mem[a] = self.state.bits() | 0x10;
        self.put(reg::AL_STATUS_CODE, &code.0.to_le_bytes());
        self.mem[usize::from(reg::ECAT_EVENT_REQUEST)] |= 0x08;
    }

    fn enter_state(&mut self, s: AlState) {
        if self.state == AlState::Op && s != AlState::Op {
            self.app.outputs_invalid();
        }
        self.state = s;
        let a = usize::from(reg::AL_STATUS);
        self.mem[a] = s.bits() | (self.mem[a] & 0x10);
        self.mem[usize::from(reg::ECAT_EVENT_REQUEST)] |= 0x08;
        if s == AlState::Op {
            self.last_output_ns = None;
        }
        if s == AlState::Init {
            self.mbx_queue.clear();
            // A request held in SM0 goes with the mailbox session (the SMs are off in INIT).
            self.last_reply = None;
            self.app.mailbox_reset();
        }
        self.update_sm_pdi_control();
        self.load_read_mailbox();
    }

    /// SM PDI control bit 0 ("deactivate"): the firmware keeps the mailbox SMs off in INIT and
    /// the process-data SMs off below SAFE-OP.
    fn update_sm_pdi_control(&mut self) {
        self.sm_config_changed();
        let mbx = self.cfg.mailbox.is_some();
        for n in 0..self.sm_count() {
            let mailbox_sm = mbx && n < 2;
            let off = if mailbox_sm {
                self.state == AlState::Init
            } else {
                !matches!(self.state, AlState::SafeOp | AlState::Op)
            };
            let a = 0x0807 + 8 * n;
            if off {
                self.mem[a] |= 0x01;
                self.set_sm_full(n, false);
            } else {
                self.mem[a] &= !0x01;
            }
        }
    }

    fn al_control_written(&mut self) {
        let ctl = self.peek_u16(reg::AL_CONTROL);
        let ack = ctl & 0x10 != 0;
        let req = AlState::from_bits(ctl as u8);
        let error = self.mem[usize::from(reg::AL_STATUS)] & 0x10 != 0;
        if error && !ack {
            // Without acknowledge only a step down is executed; the error stays indicated.
            if let Some(r) = req {
                if r < self.state && r != AlState::Bootstrap {
                    self.enter_state(r);
                }
            }
            return;
        }
        if ack {
            self.mem[usize::from(reg::AL_STATUS)] &= !0x10;
            self.put(reg::AL_STATUS_CODE, &[0, 0]);
            self.mem[usize::from(reg::ECAT_EVENT_REQUEST)] |= 0x08;
        }
        let Some(req) = req else {
            self.set_error(AlStatusCode::UNKNOWN_REQUESTED_STATE);
            return;
        };
        if req == self.state {
            return;
        }
        let from = self.state;
        match self
            .check_transition(from, req)
            .and_then(|()| self.app.state_change(from, req))
        {
            Ok(()) => {
                self.enter_state(req);
                if req == AlState::SafeOp && from == AlState::PreOp {
                    self.log_process_data_sms();
                }
            }
            Err(code) => self.set_error(code),
        }
    }

    /// Debug log of the process-data SMs the master configured (control byte: bit 6 = watchdog
    /// trigger) when the device enters SAFE-OP.
    fn log_process_data_sms(&self) {
        for n in 0..self.sm_count() {
            if let Some(sm) = self.active_sm(n).filter(|sm| !self.mailbox_sm(n, sm)) {
                tracing::debug!(
                    station = self.station_address(),
                    sm = n,
                    start = sm.start,
                    len = sm.len,
                    control = sm.control,
                    outputs = sm.ecat_writes(),
                    watchdog_trigger = sm.control & 0x40 != 0,
                    "process-data sync manager at SAFE-OP"
                );
            }
        }
    }

    /// Is sync manager `n` (active as `sm`) a mailbox — in mailbox (one-buffer) mode and not
    /// one of the process-data sync managers? ETG.1000.4 §6.7 lets process data run in either
    /// mode (the Beckhoff AX2000's ESI gives its inputs control byte 0x22, one-buffer): such a
    /// process-data SM is served as process data; the emulated PDI refreshes it before every
    /// read, so it is never empty when the master reads it (a simplification: a real ESC
    /// refuses the read of an empty one-buffer SM).
    fn mailbox_sm(&self, n: usize, sm: &Sm) -> bool {
        sm.is_mailbox()
            && n != usize::from(self.cfg.output_sm)
            && n != usize::from(self.cfg.input_sm)
    }

    fn check_transition(&self, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        use AlState::*;
        match (from, to) {
            (_, Init) => Ok(()),
            (Init, PreOp) => self.check_mailbox_sms(),
            (Init, Bootstrap) => {
                if self.cfg.bootstrap {
                    Ok(())
                } else {
                    Err(AlStatusCode::BOOTSTRAP_NOT_SUPPORTED)
                }
            }
            (PreOp, SafeOp) => self.check_pd_sms(),
            (SafeOp, Op) | (SafeOp | Op, PreOp) | (Op, SafeOp) => Ok(()),
            _ => Err(AlStatusCode::INVALID_STATE_CHANGE),
        }
    }

    fn sm_regs(&self, n: usize) -> Option<(Sm, bool)> {
        if n >= self.sm_count() {
            return None;
        }
        let b = self.peek(reg::sm(n as u16), 8);
        Some((
            Sm {
                start: usize::from(u16::from_le_bytes([b[0], b[1]])),
                len: usize::from(u16::from_le_bytes([b[2], b[3]])),
                control: b[4],
            },
            b[6] & 0x01 != 0,
        ))
    }

    fn check_mailbox_sms(&self) -> Result<(), AlStatusCode> {
        let Some(m) = self.cfg.mailbox else {
            return Ok(());
        };
        let ok = |n: usize, start: u16, size: u16, write: bool| {
            self.sm_regs(n).is_some_and(|(sm, en)| {
                en && sm.start == usize::from(start)
                    && sm.len == usize::from(size)
                    && sm.is_mailbox()
                    && sm.ecat_writes() == write
            })
        };
        if ok(0, m.rx_offset, m.rx_size, true) && ok(1, m.tx_offset, m.tx_size, false) {
            Ok(())
        } else {
            Err(AlStatusCode::INVALID_MAILBOX_CONFIG)
        }
    }

    fn check_pd_sms(&self) -> Result<(), AlStatusCode> {
        let sizes = self.app.process_data_sizes();
        let ok = |n: u8, expected: u16, write: bool| match self.sm_regs(usize::from(n)) {
            None => expected == 0,
            Some((sm, en)) => {
                if expected == 0 {
                    !en || sm.len == 0
                } else {
                    en && sm.len == usize::from(expected) && sm.ecat_writes() == write
                }
            }
        };
        if !ok(self.cfg.output_sm, sizes.outputs, true) {
            return Err(AlStatusCode::INVALID_OUTPUT_CONFIG);
        }
        if !ok(self.cfg.input_sm, sizes.inputs, false) {
            return Err(AlStatusCode::INVALID_INPUT_CONFIG);
        }
        Ok(())
    }

    fn update_dl_status(&mut self) {
        // bit 0 PDI operational; per port p: link bit 4+p, loop closed 8+2p, communication 9+2p.
        let mut v: u16 = 0x0001;
        for p in 0..4 {
            if self.port_linked[p] {
                v |= 1 << (4 + p);
                v |= 1 << (9 + 2 * p);
            } else {
                v |= 1 << (8 + 2 * p);
            }
        }
        self.put(reg::DL_STATUS, &v.to_le_bytes());
    }
}

/// Devices in ring order; passes each datagram through all of them like the wire does.
#[derive(Debug)]
pub struct EscChain {
    /// The devices, position 0 first.
    pub escs: Vec<Esc>,
    /// Forwarding delay between neighbouring devices.
    pub hop_delay_ns: u64,
    /// [`Esc::irq`] of every device as of the last [`Self::refresh_irq`], updated for the devices
    /// a datagram touches (a configured-address datagram touches one device only).
    irq_cache: Vec<u16>,
}

impl EscChain {
    /// Chain the devices in a line: port 1 of every device but the last is linked, with the
    /// return delay of the rest of the line (2 × hops × `hop_delay_ns`).
    pub fn new(mut escs: Vec<Esc>, hop_delay_ns: u64) -> Self {
        let n = escs.len();
        for (i, e) in escs.iter_mut().enumerate() {
            let downstream = (n - 1 - i) as u64;
            e.set_port_link(1, downstream > 0, 2 * downstream * hop_delay_ns);
        }
        Self {
            escs,
            hop_delay_ns,
            irq_cache: Vec::new(),
        }
    }

    /// Re-read every device's [`Esc::irq`] bits (call when the devices may have changed other
    /// than by datagrams: a segment does at every frame).
    pub fn refresh_irq(&mut self) {
        self.irq_cache.clear();
        self.irq_cache.extend(self.escs.iter().map(Esc::irq));
    }

    /// Pass one datagram through all devices; returns the working counter increment and the
    /// address as it comes back to the master.
    pub fn process(
        &mut self,
        cmd: Command,
        addr: Address,
        data: &mut [u8],
        now_ns: u64,
    ) -> (u16, Address) {
        let (wkc, a, _) = self.process_with_irq(cmd, addr, data, now_ns);
        (wkc, a)
    }

    /// [`Self::process`], also returning the OR of the devices' [`Esc::irq`] bits as each
    /// device forwards the datagram (what the datagram's IRQ field collects on its way).
    pub fn process_with_irq(
        &mut self,
        cmd: Command,
        addr: Address,
        data: &mut [u8],
        now_ns: u64,
    ) -> (u16, Address, u16) {
        if self.irq_cache.len() != self.escs.len() {
            self.refresh_irq();
        }
        let mut a = addr;
        let mut wkc = 0u16;
        match (cmd, addr) {
            // Configured-address read / write: only the device with that station address (or
            // alias) acts; the others forward the datagram unchanged (the address too).
            (Command::Fprd | Command::Fpwr | Command::Fprw, Address::Physical { adp, .. }) => {
                for (i, e) in self.escs.iter_mut().enumerate() {
                    if e.matches_station(adp) {
                        let t = now_ns + i as u64 * self.hop_delay_ns;
                        e.process(cmd, &mut a, data, &mut wkc, t);
                        self.irq_cache[i] = e.irq();
                    }
                }
            }
            _ => {
                for (i, e) in self.escs.iter_mut().enumerate() {
                    let t = now_ns + i as u64 * self.hop_delay_ns;
                    e.process(cmd, &mut a, data, &mut wkc, t);
                    self.irq_cache[i] = e.irq();
                }
            }
        }
        let irq = self.irq_cache.iter().fold(0, |acc, b| acc | b);
        (wkc, a, irq)
    }

    /// OR of the devices' [`Esc::irq`] bits (the datagram IRQ field after the ring).
    pub fn irq(&self) -> u16 {
        self.escs.iter().fold(0, |acc, e| acc | e.irq())
    }

    /// Codec-level entry: raw command byte and raw 32-bit address field; `wkc` is the
    /// datagram's working counter (incremented in place). Returns the raw address after the
    /// ring. Reserved command codes pass unchanged.
    pub fn process_raw(
        &mut self,
        cmd: u8,
        raw_addr: u32,
        data: &mut [u8],
        wkc: &mut u16,
        now_ns: u64,
    ) -> u32 {
        self.process_raw_with_irq(cmd, raw_addr, data, wkc, now_ns)
            .0
    }

    /// [`Self::process_raw`], also returning the devices' IRQ bits
    /// ([`Self::process_with_irq`]); a reserved command code passes every device unprocessed,
    /// which still ORs its bits in.
    pub fn process_raw_with_irq(
        &mut self,
        cmd: u8,
        raw_addr: u32,
        data: &mut [u8],
        wkc: &mut u16,
        now_ns: u64,
    ) -> (u32, u16) {
        let Some(cmd) = Command::from_u8(cmd) else {
            return (raw_addr, self.irq());
        };
        let (inc, a, irq) =
            self.process_with_irq(cmd, Address::from_raw(cmd, raw_addr), data, now_ns);
        *wkc = wkc.wrapping_add(inc);
        (a.to_raw(), irq)
    }
}
