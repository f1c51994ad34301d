//! Drive adapters (master side, sans-IO) and drive models (drive side).
//!
//! An adapter turns an axis command into the bytes of the drive's output process image
//! (master → drive, the RxPDO in CiA 402 terms) and decodes the input image (drive → master,
//! TxPDO) into [`DriveFeedback`]. It never does IO: the link moves the bytes.
//!
//! | family | adapter | model |
//! |---|---|---|
//! | CiA 402 (CANopen, CoE) | [`ds402::Ds402Adapter`] | [`model::ds402::Ds402Model`] |
//!
//! Drive definition files (`drives/*.toml`) are read by [`catalogue`].

pub mod catalogue;
pub mod ds402;
pub mod model;
pub mod pdo;

use crate::units::Nanos;
use std::fmt;

/// CiA 402 power state (statusword 0x6041 decode, CiA 402 §6.2; also the common state model the
/// other families map onto).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PowerState {
    /// xxxx xxxx x0xx 0000
    NotReadyToSwitchOn,
    /// xxxx xxxx x1xx 0000
    SwitchOnDisabled,
    /// xxxx xxxx x01x 0001
    ReadyToSwitchOn,
    /// xxxx xxxx x01x 0011
    SwitchedOn,
    /// xxxx xxxx x01x 0111
    OperationEnabled,
    /// xxxx xxxx x00x 0111
    QuickStopActive,
    /// xxxx xxxx x0xx 1111
    FaultReactionActive,
    /// xxxx xxxx x0xx 1000
    Fault,
    /// Any other bit pattern (kept, not rejected).
    Unknown(u16),
}

/// What the axis layer asks of the drive in one cycle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DriveCommand {
    /// Bring the drive to (or keep it in) *operation enabled*; `false` disables it.
    pub enable: bool,
    /// Target position in drive increments (0x607A in cyclic synchronous position mode).
    pub target: i32,
    /// Request a fault reset (the adapter produces the rising edge of controlword bit 7).
    pub fault_reset: bool,
    /// Request a quick stop.
    pub quick_stop: bool,
}

/// What the drive reported in one cycle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveFeedback {
    /// Decoded power state.
    pub state: PowerState,
    /// Raw statusword (0x6041) or the family's equivalent.
    pub statusword: u16,
    /// Position actual value in increments (0x6064).
    pub position: i32,
    /// Following error actual value in increments (0x60F4), when mapped.
    pub following_error: Option<i32>,
    /// Modes of operation display (0x6061), when mapped.
    pub mode_display: Option<i8>,
    /// The drive follows the cyclic target: operation enabled and, where mapped, mode 8 (CSP).
    pub operational: bool,
    /// The drive is in fault or fault reaction.
    pub fault: bool,
    /// Statusword bit 13 (following error in CSP).
    pub following_error_flag: bool,
}

/// Errors of the drive layer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DriveError {
    /// The process image is shorter than the layout needs.
    #[error("process image too short: layout needs {expected} bytes, got {got}")]
    ImageTooShort {
        /// Bytes the layout needs.
        expected: usize,
        /// Bytes present.
        got: usize,
    },
    /// A drive definition file is invalid.
    #[error("{file}:{line}: {message}")]
    Definition {
        /// File name.
        file: String,
        /// 1-based line (0 when unknown).
        line: usize,
        /// What is wrong and what is allowed.
        message: String,
    },
}

/// Master-side adapter of one drive (sans-IO).
pub trait DriveAdapter: Send + fmt::Debug {
    /// Bytes of the output image (master → drive).
    fn output_len(&self) -> usize;
    /// Bytes of the input image (drive → master).
    fn input_len(&self) -> usize;
    /// Decode the input image received in this cycle.
    fn read_inputs(&mut self, now: Nanos, inputs: &[u8]) -> Result<DriveFeedback, DriveError>;
    /// Encode this cycle's command into the output image.
    fn write_outputs(
        &mut self,
        now: Nanos,
        command: &DriveCommand,
        outputs: &mut [u8],
    ) -> Result<(), DriveError>;
}
