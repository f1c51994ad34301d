//! CANopen interop over python-can's udp_multicast bus, both directions, with python-canopen
//! 2.4.1 as the independent peer (notes `canopen.md` §3, §4); the cases themselves are in
//! `tests/common/canopen_peers.rs`, shared with the SocketCAN tests (`tests/system/socketcan.rs`):
//!
//! (a) python-canopen as master against `fieldprobe sim canopen`;
//! (b) our master against a python-canopen `LocalNode` built from `python-canopen-e35.eds`;
//! (c) python-canopen drives `sim canopen --eds` (Technosoft EDS) by SDO alone to OPERATION
//!     ENABLED.
//!
//! Isolation as in `can_udp_interop.rs`: each test re-executes itself inside a fresh
//! unprivileged user + network namespace (`unshare -rn`) with multicast routed to `lo`; only a
//! machine without namespaces SKIPs. The venv (`scripts/python-can-venv.sh`) is built before
//! entering the namespace; an install failure is a test failure. Each test has its own group
//! and port. Every wait is bounded.

use std::{net::Ipv4Addr, path::PathBuf, time::Duration};

use crate::common::netns;
use netns::netns_setup;

use crate::common::canopen_peers;
use canopen_peers::PeerBus;

use crate::common::test_data;
use test_data::test_data;

/// Set in the re-executed test process (inside the namespace); value = venv python.
const INNER_ENV: &str = "FIELDPROBE_CANOPEN_INTEROP_INNER";
const OUTER_TIMEOUT: Duration = Duration::from_secs(150);

/// Outer half: see [`netns::run_in_namespace`].
fn run_in_namespace(test_name: &str) {
    netns::run_in_namespace(test_name, INNER_ENV, OUTER_TIMEOUT, true);
}

fn inner_python() -> Option<PathBuf> {
    netns::inner_python(INNER_ENV)
}

const SIM_AS_SLAVE: &str = "python_canopen_master_drives_sim_canopen";

#[test]
fn python_canopen_master_drives_sim_canopen() {
    let _one_module = crate::gate::enter(module_path!());
    let Some(python) = inner_python() else {
        return run_in_namespace(SIM_AS_SLAVE);
    };
    netns_setup();
    canopen_peers::python_master_drives_sim(
        &python,
        PeerBus::Udp(Ipv4Addr::new(239, 74, 171, 1), 43301),
    );
    println!("INNER OK");
}

const LOCAL_NODE: &str = "rust_master_against_python_canopen_local_node";

#[test]
fn rust_master_against_python_canopen_local_node() {
    let _one_module = crate::gate::enter(module_path!());
    // Checked in both halves: the outer one skips (or fails) before building the venv.
    let Some(eds_path) = test_data("eds/python-canopen-e35.eds", LOCAL_NODE) else {
        return;
    };
    let Some(python) = inner_python() else {
        return run_in_namespace(LOCAL_NODE);
    };
    netns_setup();
    canopen_peers::rust_master_against_local_node(
        &python,
        &eds_path,
        PeerBus::Udp(Ipv4Addr::new(239, 74, 171, 2), 43302),
    );
    println!("INNER OK");
}

const SDO_DRIVE: &str = "python_canopen_drives_an_eds_node_by_sdo_without_sync";

#[test]
fn python_canopen_drives_an_eds_node_by_sdo_without_sync() {
    let _one_module = crate::gate::enter(module_path!());
    // Checked in both halves: the outer one skips (or fails) before building the venv.
    let Some(eds_path) = test_data("eds/technosoft-ipos-cia402.eds", SDO_DRIVE) else {
        return;
    };
    let Some(python) = inner_python() else {
        return run_in_namespace(SDO_DRIVE);
    };
    netns_setup();
    canopen_peers::python_sdo_drives_eds_node(
        &python,
        &eds_path,
        PeerBus::Udp(Ipv4Addr::new(239, 74, 171, 3), 43303),
    );
    println!("INNER OK");
}
