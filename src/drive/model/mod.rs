//! Drive models: the drive side of each profile, used by the emulators and the in-memory link.
//!
//! A model is sans-IO like the adapters: it gets the output image the master sent, the time and
//! the cycle length, and writes its input image. Object access for SDO / CoE servers returns CiA
//! 301 abort codes ([`abort`]).

pub mod ds402;

/// CiA 301 SDO abort codes (CiA 301 §7.2.4.3.17, Table 22) returned by model object access.
pub mod abort {
    /// 0x06010002 — attempt to write a read-only object.
    pub const READ_ONLY: u32 = 0x0601_0002;
    /// 0x06020000 — object does not exist in the object dictionary.
    pub const NO_OBJECT: u32 = 0x0602_0000;
    /// 0x06090011 — sub-index does not exist.
    pub const NO_SUB_INDEX: u32 = 0x0609_0011;
    /// 0x06090030 — invalid value for parameter (value range exceeded).
    pub const VALUE_RANGE: u32 = 0x0609_0030;
}
