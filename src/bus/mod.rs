//! Fieldbus wire formats and masters.
//!
//! | module | feature | what |
//! |---|---|---|
//! | `capture` | `ethercat` or `canopen` | the wall-clock timestamps of `--pcap` / `--candump` captures (real and virtual time) |
//! | [`abort`] | — | CiA 301 SDO abort codes and emergency error codes in words (CANopen and CoE) |
//! | `can` | `canopen` | the CAN seam `CanBus`: virtual bus, SocketCAN (`socketcan`), python-can `udp_multicast`, candump logs, fault injection |
//! | `canopen` | `canopen` | CiA 301 building blocks: SDO client / server, NMT, heartbeat, SYNC, EMCY, PDO mapping, EDS |
//! | `ethercat` | `ethercat` | EtherCAT wire formats, CoE / SoE mailbox clients on an ethercrab `MainDevice`, pcap, the raw-socket port of `ethercat:IFACE` |

pub mod abort;
#[cfg(feature = "canopen")]
pub mod can;
#[cfg(feature = "canopen")]
pub mod canopen;
#[cfg(any(feature = "ethercat", feature = "canopen"))]
pub mod capture;
#[cfg(feature = "ethercat")]
pub mod ethercat;
