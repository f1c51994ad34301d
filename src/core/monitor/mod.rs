//! Monitoring in the CNC core.
//!
//! - [`sls`]: software limit switches, command and actual side, G98 / G99, manual-mode ranges
//!   and the PCS display (seed 001, FCT-A2).
//!
//! Workspace and protection areas (seeds 000 / 002) join here later.

pub mod area_geom;
pub mod areas;
pub mod sls;

pub use sls::{AxisLimitConfig, PcsLimits, Side, SlsBehaviour, SoftLimits, Violation};
