//! EtherCAT frame and datagram wire format (ETG.1000.4).
