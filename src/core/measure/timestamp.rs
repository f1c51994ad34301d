//! Measurement: timestamp.
