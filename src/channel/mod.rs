//! The CNC channel.

pub mod profile;
