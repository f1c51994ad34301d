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
    let mut cmd = Command::new("unshare");
    cmd.args(["-rn", "sh", "-c", NETNS_SETUP]);
    match try_run_bounded(&mut cmd, Duration::from_secs(10))? {
        (Some(s), _, _) if s.success() => Ok(()),
        (Some(s), _, err) => Err(format!(
            "`unshare -rn` + multicast on lo failed ({s}): {}",
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
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new("bash")
            .arg(manifest_path("scripts/python-can-venv.sh"))
            .arg(&venv),
        VENV_TIMEOUT,
    );
    eprintln!("python-can venv ({:?}): {}{}", t0.elapsed(), out, err);
    match status {
        Some(s) if s.success() => {}
        Some(s) => panic!(
            "scripts/python-can-venv.sh failed ({s}); python-can / canopen could not be \
             installed (PyPI unreachable?):\n{out}\n{err}"
        ),
        None => panic!(
            "scripts/python-can-venv.sh did not finish within {VENV_TIMEOUT:?}:\n{out}\n{err}"
        ),
    }
    let python = venv.join("bin/python");
    *done = Some(python.clone());
    python
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
    let exe = std::env::current_exe().expect("current_exe");
    let t0 = Instant::now();
    let (status, out, err) = run_bounded(
        Command::new("unshare")
            .arg("-rn")
            .arg("--")
            .arg(&exe)
            .args([test_name, "--exact", "--nocapture", "--test-threads=1"])
            .env(inner_env, &python),
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
