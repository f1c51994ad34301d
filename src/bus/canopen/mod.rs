//! CANopen (CiA 301) master and node building blocks, sans-IO: SDO client and server
//! ([`sdo`]), EDS / DCF files ([`eds`]).

pub mod eds;
pub mod sdo;
