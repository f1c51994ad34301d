//! The CNC channel.
