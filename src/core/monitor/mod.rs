//! Monitoring in the CNC core.
//!
//! - [`sls`]: software limit switches, command and actual side, G98 / G99, manual-mode ranges
//!   and the PCS display (FCT-A2, FCT-A2).
//!
//! - [`areas`]: workspace / protection area commands, definitions and states (FCT-C14).
//! - [`area_geom`]: exact path-versus-area geometry.
//! - [`area_monitor`]: the active areas bound to channel axes, checking channel paths.

pub mod area_geom;
pub mod area_monitor;
pub mod areas;
pub mod sls;

pub use sls::{AxisLimitConfig, PcsLimits, Side, SlsBehaviour, SoftLimits, Violation};
