//! Velocity profiles.
