//! `fieldprobe run --link canopen-udp:GROUP:PORT` across processes: our CANopen master and
//! `fieldprobe sim canopen` (three emulated CiA 402 nodes, the plant's probe surface on node 3 =
//! Z at 100 mm) exchange python-can `udp_multicast` datagrams inside a private user + network
//! namespace with multicast routed to `lo`; nothing reaches the host network. The run prints
//! the seed's meas1 values (seed 004 §5).
//!
//! Prints `SKIP` and passes only where unprivileged namespaces / `unshare` / `ip` are missing.
//! Every process is bounded by `timeout` (harness: `tests/common/netns.rs`).

#[path = "common/netns.rs"]
mod netns;

#[test]
fn meas1_over_udp_multicast_prints_the_seed_values() {
    let bus = "udp:239.74.173.1:43501";
    let Some((code, stdout, stderr)) = netns::meas1_against_sim(
        "meas1_over_udp_multicast_prints_the_seed_values",
        netns::namespace_probe,
        &["unshare", "-rn"],
        "ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo; ",
        &format!("canopen --bus {bus} --node 1 --node 2 --node 3 --probe-at 3=100"),
        &format!("canopen-{bus}"),
    ) else {
        return;
    };
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    let want = netns::SEED004_MEAS1;
    assert_eq!(stdout.lines().collect::<Vec<_>>(), want);
}
