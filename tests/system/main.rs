//! Integration tests that leave the process or depend on the machine: network namespaces and
//! veth pairs, the SocketCAN guest (QEMU), independent Python peers (python-canopen, pysoem,
//! KickCAT, ebpfcat), tcpdump / tshark / can-utils, cargo-fuzz, the paced real-time cycle. One
//! test binary (issue 29); each former test file is a module, built when the features it needs
//! are on. The modules run one at a time ([`gate`]), the tests of one module side by side.

#[path = "../common/mod.rs"]
mod common;
mod gate;

#[cfg(feature = "socketcan")]
mod can_transport;
#[cfg(feature = "cli")]
mod can_udp_interop;
#[cfg(feature = "cli")]
mod candump_logs;
#[cfg(feature = "cli")]
mod canopen_independent_node;
#[cfg(feature = "cli")]
mod canopen_interop;
#[cfg(feature = "sim")]
mod canopen_paced;
#[cfg(feature = "cli")]
mod canopen_sdos;
#[cfg(feature = "cli")]
mod canopen_sessions;
#[cfg(feature = "cli")]
mod canopen_udp_run;
#[cfg(feature = "cli")]
mod capture_wall_clock;
#[cfg(feature = "cli")]
mod cli_messages_once;
#[cfg(feature = "cli")]
mod cli_numbers;
#[cfg(feature = "cli")]
mod cli_option_refusals;
#[cfg(feature = "cli")]
mod cli_progress;
#[cfg(feature = "cli")]
mod ethercat_iface_run;
#[cfg(feature = "cli")]
mod ethercat_large;
#[cfg(feature = "cli")]
mod ethercat_rt;
#[cfg(feature = "cli")]
mod ethercat_veth;
#[cfg(feature = "cli")]
mod ethercat_veth_watchdog;
mod examples;
#[cfg(feature = "cli")]
mod fuzz_targets;
#[cfg(feature = "cli")]
mod independent_masters;
mod link_bus_features;
#[cfg(feature = "cli")]
mod pysoem_interop;
#[cfg(feature = "cli")]
mod pysoem_sdoinfo;
#[cfg(feature = "cli")]
mod rt_options;
#[cfg(feature = "cli")]
mod run_end_state;
#[cfg(feature = "cli")]
mod run_signals_canopen;
#[cfg(feature = "cli")]
mod serve_sessions;
#[cfg(feature = "cli")]
mod socketcan;
#[cfg(feature = "cli")]
mod vendor_canopen;
#[cfg(feature = "cli")]
mod vendor_corpus_ethercat;
#[cfg(feature = "cli")]
mod vendor_eds_corpus;
#[cfg(feature = "cli")]
mod vendor_ethercat;
#[cfg(feature = "cli")]
mod vendor_ethercat_mixed;
#[cfg(feature = "cli")]
mod vendor_timestamp_veth;
