//! Simulation of the physical world around the drives: probe surfaces, fixed stops, a scripted
//! PLC — and, with the `sim` feature, the bus emulators.
//!
//! | module | feature | what |
//! |---|---|---|
//! | [`plant`], [`world`] | — | probe surfaces and fixed stops around drive models; one process-data step of them |
//! | [`plc`] | — | a scripted PLC for the PLC probing-signal sources (FCT-C4 §6) |
//! | `esc` | `sim` | emulated EtherCAT SubDevices (ESC registers, SII from ESI, AL states, CoE / SoE servers, DC, raw-socket wire) |
//! | `canopen` | `sim` | emulated CiA 301 / CiA 402 CANopen nodes |

#[cfg(feature = "sim")]
pub mod canopen;
#[cfg(feature = "sim")]
pub mod esc;
pub mod plant;
pub mod plc;
pub mod world;
