//! Monitoring: software limit switches (seed 001).
