//! `fieldprobe run --link canopen-udp:GROUP:PORT` across processes: our CANopen master and
//! `fieldprobe sim canopen` (three emulated CiA 402 nodes, the plant's probe surface on node 3 =
//! Z at 100 mm) exchange python-can `udp_multicast` datagrams inside a private user + network
//! namespace with multicast routed to `lo`; nothing reaches the host network. The run prints
//! the seed's meas1 values (seed 004 §5).
//!
//! Prints `SKIP` and passes only where unprivileged namespaces / `unshare` / `ip` are missing.
//! Every process is bounded by `timeout`.

use std::process::Command;

fn namespaces_work() -> Result<(), String> {
    let out = Command::new("unshare")
        .args([
            "-rn",
            "sh",
            "-c",
            "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo",
        ])
        .output()
        .map_err(|e| format!("unshare not available: {e}"))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).into_owned())
    }
}

#[test]
fn meas1_over_udp_multicast_prints_the_seed_values() {
    if let Err(why) = namespaces_work() {
        eprintln!("SKIP meas1_over_udp_multicast_prints_the_seed_values: {why}");
        return;
    }
    let bin = env!("CARGO_BIN_EXE_fieldprobe");
    let bus = "udp:239.74.173.1:43501";
    let script = format!(
        "ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo; \
         timeout 60 {bin} sim canopen --bus {bus} --node 1 --node 2 --node 3 --probe-at 3=100 \
         --seconds 60 2>/dev/null & \
         sleep 0.5; timeout 60 {bin} run examples/nc/seed004/meas1.nc --link canopen-{bus}; \
         rc=$?; kill %1 2>/dev/null; exit $rc"
    );
    let out = Command::new("timeout")
        .args(["90", "unshare", "-rn", "sh", "-c", &script])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run unshare");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = [
        "V.A.MESS.Z=100.000000",
        "V.A.MEAS.ACS.VALUE.Z=100.000000",
        "V.A.MEAS.PCS.VALUE.Z=100.000000",
        "V.A.MOFFS.Z=80.000000",
        "V.A.MEIN.Z=0.000000",
        "V.A.MEIN.Z=80.000000",
        "V.A.ABS.Z=180.000000",
        "V.A.MEIN.Z=0.000000",
        "V.A.ABS.Z=100.000000",
    ];
    assert_eq!(stdout.lines().collect::<Vec<_>>(), want);
}
