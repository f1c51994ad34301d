//! pcap / pcapng capture files of EtherCAT traffic.
