//! EtherCAT: frame and datagram wire format ([`wire`]), pcap / pcapng capture files ([`pcap`]),
//! CoE / SoE mailbox clients ([`mailbox`], [`soe`]), the CoE SDO Information service ([`sdo_info`]).

pub mod mailbox;
pub mod pcap;
pub mod sdo_info;
pub mod soe;
pub mod wire;
