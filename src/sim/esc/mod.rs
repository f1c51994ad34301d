//! Emulated EtherCAT SubDevice controller (ESC): register file, datagram processing with the
//! working-counter rules, AL state machine.
