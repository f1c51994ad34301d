//! The types the three ways into fieldprobe need (see the crate documentation): `use
//! fieldprobe::prelude::*;`.

pub use crate::drive::catalogue::DriveDefinition;
pub use crate::drive::ds402::Ds402Adapter;
pub use crate::drive::{
    DriveAdapter, DriveCommand, DriveError, DriveFeedback, PowerState, ProbeEdge, ProbeEvent,
    ProbeRequest, ProbeState, ProbeTrigger, TriggerSourceMode,
};
pub use crate::link::{Link, LinkError, ProcessImage};
pub use crate::units::{Nanos, Scaling};
