//! EtherCAT: frame and datagram wire format ([`wire`]), pcap / pcapng capture files ([`pcap`]),
//! CoE / SoE mailbox clients ([`mailbox`], [`soe`]), the CoE SDO Information service
//! ([`sdo_info`]) and the raw packet socket on a network interface ([`raw`]) that fieldprobe's
//! `ethercat:IFACE` link and the emulator's `sim ethercat` share.

pub mod mailbox;
pub mod pcap;
pub mod raw;
pub mod sdo_info;
pub mod soe;
pub mod wire;
