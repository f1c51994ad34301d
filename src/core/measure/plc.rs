//! Measurement: plc.
