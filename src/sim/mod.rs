//! Simulation of the physical world around the drives: probe surfaces, fixed stops, a scripted PLC.

pub mod canopen;
pub mod esc;
pub mod plant;
pub mod plc;
pub mod world;
