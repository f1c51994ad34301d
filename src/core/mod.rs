//! The sans-IO CNC core: measurement ([`measure`], FCT-C4), monitoring ([`monitor`]: software
//! limit switches FCT-A2, workspace / protection areas FCT-C14), frames ([`frames`]) and path
//! geometry ([`path`]). Nothing here does IO or reads a clock; the per-cycle checks do not
//! allocate.

pub mod frames;
pub mod measure;
pub mod monitor;
pub mod path;
