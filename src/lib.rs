//! fieldprobe — a fieldbus drive-probing stack.
//!
//! Drive adapters (CiA 402 over CANopen and EtherCAT, SERCOS, PROFIdrive, Lightbus, encoder
//! terminals) map probe latches and torque / lag-monitor settings into an axis layer, which feeds a
//! CNC-style core: measurement runs, software limit switches and workspace monitoring, as specified
//! by the ISG kernel documents in `shared/seeds/`.
//!
//! Layering (arrows point to what a module may use; see `DESIGN.md`):
//!
//! ```text
//! cli ──► machine ──► nc ──► channel ──► core::{monitor, path}
//!                      │         └────► axis ──► drive (adapters, sans-IO)
//!                      └─► link ──► (buses)
//! params, units, messages: used by all
//! ```

pub mod axis;
pub mod bus;
pub mod channel;
pub mod core;
pub mod drive;
#[cfg(feature = "ethercat")]
pub mod esi;
pub mod limits;
pub mod link;
pub mod machine;
pub mod messages;
pub mod nc;
pub mod params;
pub mod rt;
pub mod sim;
pub mod units;

/// ethercrab, the EtherCAT MainDevice fieldprobe's EtherCAT side is built on (`ethercat`
/// feature): use this re-export so that your `MainDevice` and fieldprobe's mailbox clients are
/// of the same version.
#[cfg(feature = "ethercat")]
pub use ethercrab;

pub mod prelude;
