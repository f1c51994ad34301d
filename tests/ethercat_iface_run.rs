//! `fieldprobe run --link ethercat:IFACE` across a real kernel interface: our master
//! (ethercrab, raw socket on v0) and `fieldprobe sim ethercat` (raw socket on v1, the plant's
//! probe surface in the emulator: `--probe-at 3=100`, ring position 3 = the Z servo) on the two
//! ends of a veth pair inside a private user + network namespace (`scripts/netns.sh`), which
//! vanishes with its processes. The run prints the seed's meas1 values (seed 004 §5).
//!
//! Prints `SKIP` and passes only where unprivileged namespaces / `unshare` / `ip` are missing.
//! Every process is bounded by `timeout`.

use std::process::Command;

fn namespaces_work() -> Result<(), String> {
    let out = Command::new("unshare")
        .args([
            "-rn", "ip", "link", "add", "t0", "type", "veth", "peer", "name", "t1",
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
fn meas1_over_a_veth_pair_prints_the_seed_values() {
    if let Err(why) = namespaces_work() {
        eprintln!("SKIP meas1_over_a_veth_pair_prints_the_seed_values: {why}");
        return;
    }
    let bin = env!("CARGO_BIN_EXE_fieldprobe");
    let script = format!(
        "timeout 60 {bin} sim ethercat --iface v1 --device esi/fieldprobe-ek1100.xml \
         --device esi/fieldprobe-cia402-servo.xml:3 --probe-at 3=100 --seconds 60 2>/dev/null & \
         sleep 0.5; timeout 60 {bin} run examples/nc/seed004/meas1.nc --link ethercat:v0; \
         rc=$?; kill %1 2>/dev/null; exit $rc"
    );
    let out = Command::new("timeout")
        .args(["90", "scripts/netns.sh", "sh", "-c", &script])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run netns.sh");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Seed 004 §5 meas1 annotations.
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
