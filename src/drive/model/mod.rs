//! Drive models (drive side of each profile).

pub mod ds402;
