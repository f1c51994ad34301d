//! Datagram commands, addresses, AL states and AL status codes of the emulated ESC.

/// EtherCAT datagram command (ETG.1000.4 Table 21 command codes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Command {
    /// 0x00 no operation.
    Nop,
    /// 0x01 auto-increment physical read.
    Aprd,
    /// 0x02 auto-increment physical write.
    Apwr,
    /// 0x03 auto-increment physical read-write.
    Aprw,
    /// 0x04 configured-address physical read.
    Fprd,
    /// 0x05 configured-address physical write.
    Fpwr,
    /// 0x06 configured-address physical read-write.
    Fprw,
    /// 0x07 broadcast read (data OR-ed).
    Brd,
    /// 0x08 broadcast write.
    Bwr,
    /// 0x09 broadcast read-write.
    Brw,
    /// 0x0A logical read.
    Lrd,
    /// 0x0B logical write.
    Lwr,
    /// 0x0C logical read-write.
    Lrw,
    /// 0x0D auto-increment read, multiple write.
    Armw,
    /// 0x0E configured-address read, multiple write.
    Frmw,
}

impl Command {
    /// Decode a command byte; `None` for reserved codes.
    pub fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0x00 => Self::Nop,
            0x01 => Self::Aprd,
            0x02 => Self::Apwr,
            0x03 => Self::Aprw,
            0x04 => Self::Fprd,
            0x05 => Self::Fpwr,
            0x06 => Self::Fprw,
            0x07 => Self::Brd,
            0x08 => Self::Bwr,
            0x09 => Self::Brw,
            0x0A => Self::Lrd,
            0x0B => Self::Lwr,
            0x0C => Self::Lrw,
            0x0D => Self::Armw,
            0x0E => Self::Frmw,
            _ => return None,
        })
    }

    /// The command byte.
    pub fn code(self) -> u8 {
        match self {
            Self::Nop => 0x00,
            Self::Aprd => 0x01,
            Self::Apwr => 0x02,
            Self::Aprw => 0x03,
            Self::Fprd => 0x04,
            Self::Fpwr => 0x05,
            Self::Fprw => 0x06,
            Self::Brd => 0x07,
            Self::Bwr => 0x08,
            Self::Brw => 0x09,
            Self::Lrd => 0x0A,
            Self::Lwr => 0x0B,
            Self::Lrw => 0x0C,
            Self::Armw => 0x0D,
            Self::Frmw => 0x0E,
        }
    }

    /// True for LRD/LWR/LRW (32-bit logical address).
    pub fn is_logical(self) -> bool {
        matches!(self, Self::Lrd | Self::Lwr | Self::Lrw)
    }
}

/// Datagram address field (4 bytes on the wire, little endian).
///
/// Physical commands carry `ADP` (position / station address) in the first two bytes and `ADO`
/// (register offset) in the last two; logical commands carry one 32-bit logical address.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Address {
    /// Physical addressing (AP*, FP*, B*, ARMW, FRMW, NOP).
    Physical {
        /// Position (auto-increment, incremented by every ESC) or configured station address.
        adp: u16,
        /// Physical memory offset inside the ESC.
        ado: u16,
    },
    /// Logical addressing (LRD/LWR/LRW).
    Logical(u32),
}

impl Address {
    /// Decode the raw little-endian 32-bit address field for `cmd`.
    pub fn from_raw(cmd: Command, raw: u32) -> Self {
        if cmd.is_logical() {
            Self::Logical(raw)
        } else {
            Self::Physical {
                adp: raw as u16,
                ado: (raw >> 16) as u16,
            }
        }
    }

    /// Encode as the raw little-endian 32-bit address field.
    pub fn to_raw(self) -> u32 {
        match self {
            Self::Physical { adp, ado } => u32::from(adp) | (u32::from(ado) << 16),
            Self::Logical(a) => a,
        }
    }

    /// Auto-increment address of ring position `pos` (what masters send: `0 - pos`).
    pub fn position(pos: u16, ado: u16) -> Self {
        Self::Physical {
            adp: 0u16.wrapping_sub(pos),
            ado,
        }
    }

    /// Configured station address `station`, register `ado`.
    pub fn station(station: u16, ado: u16) -> Self {
        Self::Physical { adp: station, ado }
    }

    /// Broadcast address of register `ado` (ADP 0).
    pub fn broadcast(ado: u16) -> Self {
        Self::Physical { adp: 0, ado }
    }
}

/// Application-layer state (AL control / AL status bits 0-3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum AlState {
    /// 1 INIT.
    Init,
    /// 2 PRE-OPERATIONAL.
    PreOp,
    /// 3 BOOTSTRAP.
    Bootstrap,
    /// 4 SAFE-OPERATIONAL.
    SafeOp,
    /// 8 OPERATIONAL.
    Op,
}

impl AlState {
    /// Decode the 4-bit state value; `None` for undefined values.
    pub fn from_bits(v: u8) -> Option<Self> {
        Some(match v & 0x0F {
            1 => Self::Init,
            2 => Self::PreOp,
            3 => Self::Bootstrap,
            4 => Self::SafeOp,
            8 => Self::Op,
            _ => return None,
        })
    }

    /// The 4-bit state value.
    pub fn bits(self) -> u8 {
        match self {
            Self::Init => 1,
            Self::PreOp => 2,
            Self::Bootstrap => 3,
            Self::SafeOp => 4,
            Self::Op => 8,
        }
    }
}

/// AL status code (register 0x0134), ETG.1000.6 Table 11.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct AlStatusCode(pub u16);

#[allow(missing_docs)]
impl AlStatusCode {
    pub const NO_ERROR: Self = Self(0x0000);
    pub const UNSPECIFIED_ERROR: Self = Self(0x0001);
    pub const NO_MEMORY: Self = Self(0x0002);
    pub const INVALID_DEVICE_SETUP: Self = Self(0x0003);
    pub const INVALID_STATE_CHANGE: Self = Self(0x0011);
    pub const UNKNOWN_REQUESTED_STATE: Self = Self(0x0012);
    pub const BOOTSTRAP_NOT_SUPPORTED: Self = Self(0x0013);
    pub const NO_VALID_FIRMWARE: Self = Self(0x0014);
    pub const INVALID_MAILBOX_CONFIG_BOOT: Self = Self(0x0015);
    pub const INVALID_MAILBOX_CONFIG: Self = Self(0x0016);
    pub const INVALID_SYNC_MANAGER_CONFIG: Self = Self(0x0017);
    pub const NO_VALID_INPUTS: Self = Self(0x0018);
    pub const NO_VALID_OUTPUTS: Self = Self(0x0019);
    pub const SYNCHRONIZATION_ERROR: Self = Self(0x001A);
    pub const SYNC_MANAGER_WATCHDOG: Self = Self(0x001B);
    pub const INVALID_SYNC_MANAGER_TYPES: Self = Self(0x001C);
    pub const INVALID_OUTPUT_CONFIG: Self = Self(0x001D);
    pub const INVALID_INPUT_CONFIG: Self = Self(0x001E);
    pub const INVALID_WATCHDOG_CONFIG: Self = Self(0x001F);
    pub const NEEDS_COLD_START: Self = Self(0x0020);
    pub const NEEDS_INIT: Self = Self(0x0021);
    pub const NEEDS_PREOP: Self = Self(0x0022);
    pub const NEEDS_SAFEOP: Self = Self(0x0023);
    pub const INVALID_INPUT_MAPPING: Self = Self(0x0024);
    pub const INVALID_OUTPUT_MAPPING: Self = Self(0x0025);
    pub const INCONSISTENT_SETTINGS: Self = Self(0x0026);
    pub const FREERUN_NOT_SUPPORTED: Self = Self(0x0027);
    pub const SYNC_MODE_NOT_SUPPORTED: Self = Self(0x0028);
    pub const INVALID_DC_SYNC_CONFIG: Self = Self(0x0030);
    pub const INVALID_DC_LATCH_CONFIG: Self = Self(0x0031);
    pub const DC_INVALID_SYNC_CYCLE_TIME: Self = Self(0x0035);
    pub const DC_SYNC0_CYCLE_TIME: Self = Self(0x0036);
    pub const DC_SYNC1_CYCLE_TIME: Self = Self(0x0037);
    pub const MBX_COE: Self = Self(0x0043);
    pub const MBX_SOE: Self = Self(0x0045);
    pub const EEPROM_NO_ACCESS: Self = Self(0x0050);
    pub const EEPROM_ERROR: Self = Self(0x0051);
}

/// Register offsets of the ESC (ET1100/ET1200 register map, ETG.1000.4 §6 / Beckhoff ESC datasheet).
#[allow(missing_docs)]
pub mod reg {
    pub const TYPE: u16 = 0x0000;
    pub const REVISION: u16 = 0x0001;
    pub const BUILD: u16 = 0x0002;
    pub const FMMU_COUNT: u16 = 0x0004;
    pub const SM_COUNT: u16 = 0x0005;
    pub const RAM_SIZE: u16 = 0x0006;
    pub const PORT_DESCRIPTOR: u16 = 0x0007;
    pub const FEATURES: u16 = 0x0008;
    pub const STATION_ADDRESS: u16 = 0x0010;
    pub const STATION_ALIAS: u16 = 0x0012;
    pub const DL_CONTROL: u16 = 0x0100;
    pub const PHYS_RW_OFFSET: u16 = 0x0108;
    pub const DL_STATUS: u16 = 0x0110;
    pub const AL_CONTROL: u16 = 0x0120;
    pub const AL_STATUS: u16 = 0x0130;
    pub const AL_STATUS_CODE: u16 = 0x0134;
    pub const PDI_CONTROL: u16 = 0x0140;
    pub const ESC_CONFIG: u16 = 0x0141;
    pub const PDI_CONFIG: u16 = 0x0150;
    pub const ECAT_EVENT_MASK: u16 = 0x0200;
    pub const AL_EVENT_MASK: u16 = 0x0204;
    pub const ECAT_EVENT_REQUEST: u16 = 0x0210;
    pub const AL_EVENT_REQUEST: u16 = 0x0220;
    pub const RX_ERROR_COUNTER: u16 = 0x0300;
    pub const LOST_LINK_COUNTER: u16 = 0x0310;
    pub const WD_DIVIDER: u16 = 0x0400;
    pub const WD_TIME_PDI: u16 = 0x0410;
    pub const WD_TIME_PD: u16 = 0x0420;
    pub const WD_STATUS_PD: u16 = 0x0440;
    pub const WD_COUNTER_PD: u16 = 0x0442;
    pub const WD_COUNTER_PDI: u16 = 0x0443;
    pub const SII_CONFIG: u16 = 0x0500;
    pub const SII_PDI_ACCESS: u16 = 0x0501;
    pub const SII_CONTROL: u16 = 0x0502;
    pub const SII_ADDRESS: u16 = 0x0504;
    pub const SII_DATA: u16 = 0x0508;
    pub const FMMU0: u16 = 0x0600;
    pub const SM0: u16 = 0x0800;
    pub const DC_RECV_TIME_PORT0: u16 = 0x0900;
    pub const DC_SYSTEM_TIME: u16 = 0x0910;
    pub const DC_RECV_TIME_EPU: u16 = 0x0918;
    pub const DC_SYSTEM_TIME_OFFSET: u16 = 0x0920;
    pub const DC_SYSTEM_TIME_DELAY: u16 = 0x0928;
    pub const DC_SYSTEM_TIME_DIFF: u16 = 0x092C;
    pub const DC_SPEED_COUNTER_START: u16 = 0x0930;
    pub const DC_SPEED_COUNTER_DIFF: u16 = 0x0932;
    pub const DC_FILTER_DEPTH: u16 = 0x0934;
    pub const DC_CYCLIC_UNIT_CONTROL: u16 = 0x0980;
    pub const DC_SYNC_ACTIVATION: u16 = 0x0981;
    pub const DC_PULSE_LENGTH: u16 = 0x0982;
    pub const DC_ACTIVATION_STATUS: u16 = 0x0984;
    pub const DC_SYNC0_STATUS: u16 = 0x098E;
    pub const DC_SYNC1_STATUS: u16 = 0x098F;
    pub const DC_START_TIME: u16 = 0x0990;
    pub const DC_NEXT_SYNC1: u16 = 0x0998;
    pub const DC_SYNC0_CYCLE: u16 = 0x09A0;
    pub const DC_SYNC1_CYCLE: u16 = 0x09A4;
    pub const DC_LATCH0_CONTROL: u16 = 0x09A8;
    pub const DC_LATCH1_CONTROL: u16 = 0x09A9;
    pub const PROCESS_RAM: u16 = 0x1000;

    /// FMMU `n` register block (16 bytes).
    pub const fn fmmu(n: u16) -> u16 {
        FMMU0 + 16 * n
    }
    /// Sync manager `n` register block (8 bytes).
    pub const fn sm(n: u16) -> u16 {
        SM0 + 8 * n
    }
    /// Sync manager `n` status byte (bit 3 = mailbox full).
    pub const fn sm_status(n: u16) -> u16 {
        SM0 + 8 * n + 5
    }
}
