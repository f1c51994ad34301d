//! Fieldbus wire formats and masters.

pub mod ethercat;
