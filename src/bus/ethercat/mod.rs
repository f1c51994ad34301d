//! EtherCAT: frame and datagram wire format ([`wire`]), pcap / pcapng capture files ([`pcap`]).

pub mod mailbox;
pub mod pcap;
pub mod soe;
pub mod wire;
