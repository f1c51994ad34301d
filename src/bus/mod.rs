//! Fieldbus wire formats and masters.

pub mod can;
pub mod canopen;
pub mod ethercat;
