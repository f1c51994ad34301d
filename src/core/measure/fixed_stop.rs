//! Measurement: fixed_stop.
