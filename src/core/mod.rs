//! The sans-IO CNC core: geometry of paths, monitoring (software limit switches, later control
//! areas) and, later, measurement. Nothing here does IO, reads a clock or allocates per cycle.

pub mod frames;
pub mod measure;
pub mod monitor;
pub mod path;
