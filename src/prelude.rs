//! The types the three ways into fieldprobe share (see the crate documentation):
//! `use fieldprobe::prelude::*;`.
//!
//! - the drive layer: [`DriveDefinition`] (a drive file: PDO layout, [`Scaling`], drive
//!   functions), the CiA 402 adapter [`Ds402Adapter`] behind the [`DriveAdapter`] trait, its
//!   per-cycle [`DriveCommand`] / [`DriveFeedback`] and the touch probe ([`ProbeRequest`],
//!   [`ProbeEvent`], [`ProbeState`]);
//! - the transport seam: [`Link`], [`ProcessImage`], [`LinkError`], and with the buses
//!   `CoeClient` (feature `ethercat`), `CanBus`, `VirtualCan`, `SocketCanBus` (feature
//!   `canopen`), `CanopenLink` (feature `canopen`);
//! - the core: [`MeasurementRun`], [`Latch`], [`RunStep`], [`MeasType`],
//!   [`MeasurementOutcome`], [`AxisResult`], [`MeasuringBlock`], [`Frames`], [`SoftLimits`],
//!   [`AxisLimitConfig`], [`Violation`], [`CncMessage`].

pub use crate::core::frames::Frames;
pub use crate::core::measure::results::{AxisResult, MeasuringBlock};
pub use crate::core::measure::run::{Latch, MeasurementRun, RunStep};
pub use crate::core::measure::{ChannelMeasConfig, MeasType, MeasurementOutcome};
pub use crate::core::monitor::sls::{AxisLimitConfig, SoftLimits, Violation};
pub use crate::drive::catalogue::DriveDefinition;
pub use crate::drive::ds402::Ds402Adapter;
pub use crate::drive::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode,
};
pub use crate::link::{Link, LinkError, ProcessImage};
pub use crate::messages::CncMessage;
pub use crate::units::{Nanos, Scaling};

#[cfg(feature = "ethercat")]
pub use crate::bus::ethercat::mailbox::CoeClient;

#[cfg(feature = "canopen")]
pub use crate::bus::can::{CanBus, SocketCanBus, VirtualCan};

#[cfg(feature = "canopen")]
pub use crate::link::canopen::CanopenLink;
