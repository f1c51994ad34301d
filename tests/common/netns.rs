//! Bounded child processes and the "re-run this test inside a private user + network namespace
//! with multicast on `lo`" harness of the CAN interop tests, plus the python-can / canopen venv.
//!
//! Outer half: [`run_in_namespace`] checks that `unshare -rn` works (else prints `SKIP` and
//! returns), builds the venv (a failure is a test failure: PyPI unreachable is not a skip),
//! re-executes the test binary for `test_name` under `unshare -rn` with `inner_env` set to the
//! venv's python, and expects `INNER OK` in its output. Inner half: [`inner_python`] tells the
//! test it is inside; it calls [`netns_setup`] first. Every wait is bounded.

#![allow(dead_code)] // each test crate uses its own subset

use std::{
    ffi::OsStr,
    io::Read,
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::Mutex,
    thread,
    time::{Duration, Instant},
};

/// A path in the crate directory.
pub fn manifest_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// Wait for `child` at most `timeout`; kill it if it is still running.
pub fn wait_bounded(child: &mut Child, timeout: Duration) -> Option<std::process::ExitStatus> {
    let t0 = Instant::now();
    loop {
        if let Some(s) = child.try_wait().expect("try_wait") {
            return Some(s);
        }
        if t0.elapsed() >= timeout {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        thread::sleep(Duration::from_millis(20));
    }
}

/// Exit status (`None`: killed at the timeout), stdout, stderr.
pub type Outcome = (Option<std::process::ExitStatus>, String, String);

/// Threads reading a child's stdout and stderr to strings.
pub fn collect(child: &mut Child) -> (thread::JoinHandle<String>, thread::JoinHandle<String>) {
    let mut out = child.stdout.take().expect("stdout");
    let mut err = child.stderr.take().expect("stderr");
    let o = thread::spawn(move || {
        let mut s = String::new();
        let _ = out.read_to_string(&mut s);
        s
    });
    let e = thread::spawn(move || {
        let mut s = String::new();
        let _ = err.read_to_string(&mut s);
        s
    });
    (o, e)
}

/// Run `cmd` to completion (at most `timeout`), collecting stdout and stderr.
pub fn try_run_bounded(cmd: &mut Command, timeout: Duration) -> Result<Outcome, String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot run {cmd:?}: {e}"))?;
    let (o, e) = collect(&mut child);
    let status = wait_bounded(&mut child, timeout);
    Ok((
        status,
        o.join().unwrap_or_default(),
        e.join().unwrap_or_default(),
    ))
}

/// [`try_run_bounded`], panicking if the command cannot start.
pub fn run_bounded(cmd: &mut Command, timeout: Duration) -> Outcome {
    try_run_bounded(cmd, timeout).unwrap_or_else(|e| panic!("{e}"))
}

/// Inside the namespace: `lo` up, multicast on, IPv4 multicast routed to `lo` (notes
/// `canopen.md` §3.2).
pub const NETNS_SETUP: &str =
    "ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo";

/// Can this machine create a user + network namespace with multicast on `lo`?
pub fn namespace_probe() -> Result<(), String> {
    namespace_probe_with(NETNS_SETUP, "multicast on lo")
}

/// Can this machine create a user + network namespace and run `setup` (`what`, for the message)
/// in it? At most 10 s.
pub fn namespace_probe_with(setup: &str, what: &str) -> Result<(), String> {
    let mut cmd = Command::new("unshare");
    cmd.args(["-rn", "sh", "-c", setup]);
    match try_run_bounded(&mut cmd, Duration::from_secs(10))? {
        (Some(s), _, _) if s.success() => Ok(()),
        (Some(s), _, err) => Err(format!(
            "`unshare -rn` + {what} failed ({s}): {}",
            err.trim()
        )),
        (None, _, _) => Err("`unshare -rn` did not finish within 10 s".into()),
    }
}

/// Bound for building the venv.
pub const VENV_TIMEOUT: Duration = Duration::from_secs(300);

/// Build the python-can + canopen venv once per test binary (`scripts/python-can-venv.sh`
/// locks against other binaries); returns its python.
pub fn ensure_venv() -> PathBuf {
    static ONCE: Mutex<Option<PathBuf>> = Mutex::new(None);
    let mut done = ONCE.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(p) = done.as_ref() {
        return p.clone();
    }
    let venv = match std::env::var_os("PYTHON_CAN_VENV") {
        Some(v) => PathBuf::from(v),
        None => manifest_path("target/can-venv"),
    };
    let python = build_venv(
        "scripts/python-can-venv.sh",
        &venv,
        VENV_TIMEOUT,
        "python-can / canopen could not be installed (PyPI unreachable?)",
    );
    *done = Some(python.clone());
    python
}

/// Run `bash SCRIPT VENV` (idempotent venv builder, `script` relative to the crate) at most
/// `timeout`; returns the venv's python. A failure panics with the script's output and
/// `on_failure` (registry unreachable is a test failure, not a skip).
pub fn build_venv(script: &str, venv: &Path, timeout: Duration, on_failure: &str) -> PathBuf {
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new("bash").arg(manifest_path(script)).arg(venv),
        timeout,
    );
    eprintln!("{script} ({:?}): {}{}", t0.elapsed(), out, err);
    match status {
        Some(s) if s.success() => {}
        Some(s) => panic!("{script} failed ({s}); {on_failure}:\n{out}\n{err}"),
        None => panic!("{script} did not finish within {timeout:?}:\n{out}\n{err}"),
    }
    venv.join("bin/python")
}

/// Outer half of a test: re-run `test_name` inside a new namespace with `inner_env` = the
/// venv's python (or plain `python3` when `needs_python` is false), at most `timeout`.
pub fn run_in_namespace(test_name: &str, inner_env: &str, timeout: Duration, needs_python: bool) {
    if let Err(why) = namespace_probe() {
        eprintln!("SKIP {test_name}: {why}");
        return;
    }
    let python = if needs_python {
        ensure_venv()
    } else {
        PathBuf::from("python3")
    };
    rerun_in_namespace(test_name, inner_env, python.as_os_str(), timeout);
}

/// Re-run this test binary's `test_name` under `unshare -rn` with `inner_env` = `value`, at
/// most `timeout` (killed then); the child must succeed and print `INNER OK`.
pub fn rerun_in_namespace(test_name: &str, inner_env: &str, value: &OsStr, timeout: Duration) {
    let exe = std::env::current_exe().expect("current_exe");
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new("unshare")
            .arg("-rn")
            .arg("--")
            .arg(&exe)
            .args([
                super::full_test_name(test_name).as_str(),
                "--exact",
                "--nocapture",
                "--test-threads=1",
            ])
            .env(inner_env, value),
        timeout,
    );
    eprintln!(
        "--- {test_name} in namespace ({:?}) stdout:\n{out}\n--- stderr:\n{err}",
        t0.elapsed()
    );
    match status {
        Some(s) => assert!(s.success(), "namespace child failed: {s}"),
        None => panic!("namespace child did not finish within {timeout:?}"),
    }
    assert!(
        out.contains("INNER OK"),
        "inner test did not report success"
    );
}

/// Inside the namespace: the python to use (`None`: this is the outer process).
pub fn inner_python(inner_env: &str) -> Option<PathBuf> {
    std::env::var_os(inner_env).map(PathBuf::from)
}

/// Inside the namespace: [`NETNS_SETUP`].
pub fn netns_setup() {
    let s = Command::new("sh")
        .args(["-c", NETNS_SETUP])
        .status()
        .expect("run sh");
    assert!(s.success(), "{NETNS_SETUP}: {s}");
}

/// What `fieldprobe run examples/nc/seed004/meas1.nc` prints (seed 004 §5 meas1 annotations).
pub const SEED004_MEAS1: [&str; 9] = [
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

/// `fieldprobe run examples/nc/seed004/meas1.nc --link LINK` against `fieldprobe sim SIM`
/// started in the background, both in one shell in a private namespace: `timeout 90 WRAP… sh
/// -c 'PRELUDE timeout 60 fieldprobe sim SIM --seconds 60 & sleep 0.5; timeout 60 fieldprobe
/// run …'` in the crate directory (`wrap` makes the namespace, e.g. `unshare -rn` or
/// `scripts/netns.sh`). `probe` first: on `Err` prints `SKIP test_name` and returns `None`.
/// Otherwise the exit code of the run (`None`: killed), its stdout and its stderr.
pub fn meas1_against_sim(
    test_name: &str,
    probe: impl FnOnce() -> Result<(), String>,
    wrap: &[&str],
    prelude: &str,
    sim: &str,
    link: &str,
) -> Option<(Option<i32>, String, String)> {
    if let Err(why) = probe() {
        eprintln!("SKIP {test_name}: {why}");
        return None;
    }
    let bin = env!("CARGO_BIN_EXE_fieldprobe");
    let script = format!(
        "{prelude}timeout 60 {bin} sim {sim} --seconds 60 2>/dev/null & \
         sleep 0.5; timeout 60 {bin} run examples/nc/seed004/meas1.nc --link {link}; \
         rc=$?; kill %1 2>/dev/null; exit $rc"
    );
    let out = Command::new("timeout")
        .arg("90")
        .args(wrap)
        .args(["sh", "-c", &script])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap_or_else(|e| panic!("run {wrap:?}: {e}"));
    Some((
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    ))
}
