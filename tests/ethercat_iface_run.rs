//! `fieldprobe run --link ethercat:IFACE` across a real kernel interface: our master
//! (ethercrab, raw socket on v0) and `fieldprobe sim ethercat` (raw socket on v1, the plant's
//! probe surface in the emulator: `--probe-at 3=100`, ring position 3 = the Z servo) on the two
//! ends of a veth pair inside a private user + network namespace (`scripts/netns.sh`), which
//! vanishes with its processes. The run prints the seed's meas1 values (seed 004 §5).
//!
//! Both run on their own clocks as on a real bus: the master paces its cycle half a period
//! after SYNC0, the emulated drives step at their SYNC0 on the emulator's clock (the timing
//! itself is checked in `tests/ethercat_rt.rs`).
//!
//! Prints `SKIP` and passes only where unprivileged namespaces / `unshare` / `ip` are missing.
//! Every process is bounded by `timeout` (harness: `tests/common/veth.rs`, `netns.rs`).

#[path = "common/veth.rs"]
mod veth;

#[test]
fn meas1_over_a_veth_pair_prints_the_seed_values() {
    let Some((code, stdout, stderr)) = veth::netns::meas1_against_sim(
        "meas1_over_a_veth_pair_prints_the_seed_values",
        veth::veth_probe,
        &["scripts/netns.sh"],
        "",
        "ethercat --iface v1 --device esi/fieldprobe-ek1100.xml \
         --device esi/fieldprobe-cia402-servo.xml:3 --probe-at 3=100",
        "ethercat:v0",
    ) else {
        return;
    };
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    // Seed 004 §5 meas1 annotations.
    let want = veth::netns::SEED004_MEAS1;
    assert_eq!(stdout.lines().collect::<Vec<_>>(), want);
}
