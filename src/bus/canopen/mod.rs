//! CANopen (CiA 301) master and node building blocks, sans-IO: SDO client and server
//! ([`sdo`]), NMT / heartbeat / SYNC / EMCY ([`nmt`]), PDO packing and remapping ([`pdo`]),
//! EDS / DCF files ([`eds`]).

pub mod eds;
pub mod nmt;
pub mod pdo;
pub mod sdo;
