//! `fieldprobe run`.

use super::progress::Progress;
use super::{load_machine, load_program, LinkArgs, EXIT_BAD_INPUT, EXIT_CNC_ERROR, EXIT_OK};
use anyhow::Context;
use fieldprobe::machine::{Machine, RunEvent, RunReport, RunStatus, StopRequest};
use fieldprobe::nc::exec::Executor;
use std::io::IsTerminal;
use std::path::PathBuf;

/// Arguments of `fieldprobe run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// The NC program.
    program: PathBuf,
    /// Machine file (TOML); default: axes X, Y, Z on emulated CiA 402 drives.
    #[arg(long)]
    machine: Option<PathBuf>,
    #[command(flatten)]
    link: LinkArgs,
    /// Parameter assignment in seed units, e.g. `P-CHAN-00498=1`, `X.P-AXIS-00178=2000000`.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    sets: Vec<String>,
    /// Simulated probe: switches when the axis's actual (ACS) position crosses POS.
    #[arg(long = "probe-at", value_name = "AXIS=POS")]
    probe_at: Vec<String>,
    /// Simulated mechanical stop at ACS position POS.
    #[arg(long = "fixed-stop-at", value_name = "AXIS=POS")]
    fixed_stop_at: Vec<String>,
    /// Print one JSON document on stdout instead of the `#MSG` lines.
    #[arg(long)]
    json: bool,
    /// Draw the run into an SVG or PNG file (by the extension): position and velocity per axis
    /// over time, probe edges and the latched values of the axes that measured marked.
    #[arg(long, value_name = "FILE.svg|FILE.png")]
    trace: Option<PathBuf>,
    /// No progress line on stderr (it is shown only when stderr is a terminal and the run
    /// lasts longer than a second).
    #[arg(long, short = 'q')]
    quiet: bool,
}

/// `AXIS=POS` (POS in mm, [`super::number::position`]).
fn parse_axis_pos(opt: &str, s: &str) -> anyhow::Result<(String, f64)> {
    let (ax, pos) = s
        .split_once('=')
        .with_context(|| format!("{opt} {s}: expected AXIS=POS, e.g. Z=100"))?;
    let pos = super::number::position(opt, pos.trim()).map_err(|e| super::number::NumberError {
        text: s.to_string(),
        expected: format!("AXIS=POS with {}", e.expected),
        ..e
    })?;
    Ok((ax.trim().to_string(), pos))
}

/// Run the command; returns the exit code.
pub fn run(a: RunArgs) -> anyhow::Result<i32> {
    // A picture format we cannot write is bad input, refused before anything runs.
    let trace_format = match a.trace.as_deref().map(super::plot::Format::of) {
        Some(Err(e)) => {
            eprintln!("fieldprobe: --trace {e}");
            return Ok(EXIT_BAD_INPUT);
        }
        Some(Ok(f)) => Some(f),
        None => None,
    };
    let file = a.program.display().to_string();
    let Some(program) = load_program(&a.program)? else {
        return Ok(EXIT_BAD_INPUT);
    };
    let cfg = load_machine(a.machine.as_deref(), &a.sets)?;
    let choice = a.link.choice(&cfg);
    if let Err(e) = a.link.check_rt(&choice) {
        eprintln!("fieldprobe: {e}");
        return Ok(EXIT_BAD_INPUT);
    }
    // SIGINT / SIGTERM from here on: the run stops its axes and disables the drives first
    // (before the link starts threads, which inherit the blocked signals).
    let stop = StopRequest::new();
    let signal = stop_signals::watch(stop.clone());
    let mut machine = Machine::with_link(&cfg, &choice)?;
    machine.set_stop_request(stop.clone());
    // The bus as it came up (EtherCAT segment, SubDevices not named, wire time per cycle): on
    // stderr for a real bus and for a machine that names terminals; the emulator's default
    // segment of axes only is logged (FIELDPROBE_LOG=info), not printed. A warning (a device
    // without touch probe, 900404 / 900504) is printed on every link.
    let print_report = choice.leaves_process() || !cfg.terminals.is_empty();
    for m in machine.startup_report() {
        if print_report || m.severity != fieldprobe::messages::Severity::Info {
            eprintln!("{m}");
        } else {
            tracing::info!(target: "fieldprobe::link::ethercat", "{m}");
        }
    }
    // The cyclic phase runs with the real-time options; the start-up (SII, mailbox, PDO
    // mapping) ran without them, as the masters' start-up threads do.
    match a.link.rt().apply() {
        Ok(applied) => {
            for what in applied {
                tracing::info!("real-time: {what}");
            }
        }
        Err(e) => {
            eprintln!("fieldprobe: {e}");
            return Ok(EXIT_BAD_INPUT);
        }
    }
    for p in &a.probe_at {
        let (ax, pos) = parse_axis_pos("--probe-at", p)?;
        machine
            .add_probe(&ax, pos)
            .with_context(|| format!("--probe-at {p}"))?;
    }
    for p in &a.fixed_stop_at {
        let (ax, pos) = parse_axis_pos("--fixed-stop-at", p)?;
        machine
            .add_fixed_stop(&ax, pos)
            .with_context(|| format!("--fixed-stop-at {p}"))?;
    }
    let names = machine
        .channel()
        .axes()
        .iter()
        .map(|x| x.name().to_string())
        .collect();
    if let Err((span, msg)) = Executor::new(program.clone(), names).validate() {
        eprintln!("{file}:{}:{}: {msg}", span.line, span.col);
        return Ok(EXIT_BAD_INPUT);
    }
    if a.trace.is_some() {
        machine.enable_trace();
    }
    let json = a.json;
    // The progress line: on a terminal, unless --quiet; cycles per second on the links that
    // run on the wall clock.
    let mut progress = Progress::new(
        !a.quiet && std::io::stderr().is_terminal(),
        choice.leaves_process(),
    );
    let report = machine.run_program_with_progress(
        &program,
        &mut |e| {
            super::progress::clear();
            match e {
                RunEvent::Output(line) if !json => outln!("{line}"),
                RunEvent::Message(m) => eprintln!("{m}"),
                RunEvent::Output(_) => {}
            }
        },
        &mut |p| progress.tick(p),
    );
    progress.finish();
    // The JSON report is the state at the program's end (command and actual positions,
    // limits); the power-off below makes the command follow the actual position.
    let mut json_report = json.then(|| report_json(&program.name, &report, &machine));
    // The end of the run, completed or aborted: drives disabled (CiA 402 shutdown), CANopen
    // nodes to pre-operational (docs/canopen.md "The end of a run"); what could not be
    // confirmed is a warning.
    let off = machine.power_off();
    for m in &off {
        eprintln!("{m}");
    }
    if let Some(cause) = stop.cause() {
        if off
            .iter()
            .any(|m| m.id == fieldprobe::messages::ids::POWER_OFF)
        {
            eprintln!(
                "fieldprobe: {cause}: axes stopped; the drives could not all be confirmed disabled"
            );
        } else {
            eprintln!("fieldprobe: {cause}: axes stopped, every drive disabled");
        }
    }
    // A capture (--pcap, --candump) that could not be written all through: an error of the
    // command (not 0), reported now that the axes stopped.
    super::finish_capture(machine.finish_capture());
    // The paced cycle of a link that leaves the process: one summary line, and the log.
    let cycle = machine.cycle_summary();
    if let Some(c) = &cycle {
        eprintln!("{c}");
    }
    if let Err(e) = machine.finish_cycle_log() {
        // A log that could not be written is an error (exit 2, as for --trace), never silent.
        anyhow::bail!("--cycle-log {e}");
    }
    if let (Some(path), Some(format), Some(tr)) = (&a.trace, trace_format, machine.trace()) {
        if tr.stride > 1 {
            eprintln!(
                "fieldprobe: --trace {}: {} cycles drawn with one sample every {} cycles ({} samples at most)",
                path.display(),
                report.cycles,
                tr.stride,
                fieldprobe::machine::MAX_TRACE_SAMPLES
            );
        }
        if tr.dropped_marks > 0 {
            eprintln!(
                "fieldprobe: --trace {}: {} probe edges / latches beyond the first {} not drawn",
                path.display(),
                tr.dropped_marks,
                fieldprobe::machine::MAX_TRACE_MARKS
            );
        }
        super::trace::write(tr, path, format)
            .with_context(|| format!("--trace {}", path.display()))?;
    }
    if let Some(v) = json_report.as_mut() {
        // The paced cycle's statistics include the power-off cycles.
        v["cycle"] = serde_json::to_value(machine.cycle_summary())?;
        outln!("{}", serde_json::to_string_pretty(v)?);
    }
    if let Some(signo) = signal.as_ref().and_then(stop_signals::Received::signal) {
        // As a shell reports a command ended by the signal: 128 + its number.
        return Ok(128 + signo);
    }
    Ok(match report.status {
        RunStatus::Completed => EXIT_OK,
        RunStatus::Aborted => EXIT_CNC_ERROR,
    })
}

/// SIGINT and SIGTERM during `run` (issue 28 item 3), through a signalfd read by a thread of
/// its own (no signal handler, no unsafe code): the first one asks the machine to stop
/// ([`StopRequest`], error 900019); the run then brakes the axes, disables every drive
/// ([`Machine::power_off`]) and exits 128 + the signal's number (130 / 143). A second one, a
/// second or more later, exits at once with that code, leaving the drives to their own
/// communication watchdogs.
/// A signal during the link's start-up is acted on when the run starts.
mod stop_signals {
    use fieldprobe::machine::StopRequest;
    use std::sync::atomic::{AtomicI32, Ordering};
    use std::sync::Arc;

    /// A second stop signal this soon after the first counts as the same one.
    const REPEAT: std::time::Duration = std::time::Duration::from_secs(1);

    /// The signal received, if any.
    pub struct Received(Arc<AtomicI32>);

    impl Received {
        /// The number of the first stop signal received.
        pub fn signal(&self) -> Option<i32> {
            Some(self.0.load(Ordering::SeqCst)).filter(|&s| s != 0)
        }
    }

    /// Block SIGINT and SIGTERM in this thread (threads started later inherit it) and read
    /// them in a thread; `None` (the signals keep their default action) if that fails.
    #[cfg(target_os = "linux")]
    pub fn watch(stop: StopRequest) -> Option<Received> {
        use nix::sys::signal::{SigSet, Signal};
        use nix::sys::signalfd::{SfdFlags, SignalFd};
        let mut mask = SigSet::empty();
        mask.add(Signal::SIGTERM);
        mask.add(Signal::SIGINT);
        let fd = SignalFd::with_flags(&mask, SfdFlags::SFD_CLOEXEC).ok()?;
        mask.thread_block().ok()?;
        let got = Arc::new(AtomicI32::new(0));
        let seen = got.clone();
        let spawned = std::thread::Builder::new()
            .name("fieldprobe-signals".into())
            .spawn(move || {
                let mut first = None;
                loop {
                    let info = match fd.read_signal() {
                        Ok(Some(info)) => info,
                        Ok(None) => continue,
                        // The signalfd failed: nothing more to read.
                        Err(_) => return,
                    };
                    let signo = info.ssi_signo as i32;
                    let name = Signal::try_from(signo).map_or("a stop signal", Signal::as_str);
                    // A repeat within a second is the same request reaching the run twice (a
                    // signal to the process group and one forwarded, as `timeout` does).
                    if first.is_some_and(|t: std::time::Instant| t.elapsed() < REPEAT) {
                        continue;
                    }
                    if seen.swap(signo, Ordering::SeqCst) != 0 {
                        eprintln!(
                            "fieldprobe: {name} again: exit without waiting for the drives; they \
                         stop on their own communication watchdogs"
                        );
                        std::process::exit(128 + signo);
                    }
                    first = Some(std::time::Instant::now());
                    stop.request(name);
                }
            });
        if spawned.is_err() {
            let _ = mask.thread_unblock();
            return None;
        }
        Some(Received(got))
    }

    #[cfg(not(target_os = "linux"))]
    pub fn watch(_stop: StopRequest) -> Option<Received> {
        None
    }
}

fn report_json(name: &Option<String>, r: &RunReport, m: &Machine) -> serde_json::Value {
    let ch = m.channel();
    let axes: Vec<_> = ch
        .axes()
        .iter()
        .enumerate()
        .map(|(i, ax)| {
            let (neg, pos) = ch.soft_limits().active_limits(i).unwrap_or((f64::NAN, f64::NAN));
            serde_json::json!({
                "name": ax.name(),
                "command": ax.command(),
                "actual": ax.actual(),
                "lag": ax.lag(),
                "sls_negative": neg,
                "sls_positive": pos,
                "measurement": r.measurements.get(i).map(|m| serde_json::json!({
                    "mess": m.result.map(|x| x.mess),
                    "acs": m.result.map(|x| x.acs),
                    "pcs": m.result.map(|x| x.pcs),
                    "moffs": m.result.map(|x| x.moffs),
                    "merf": m.merf,
                    "mein": m.mein,
                })),
                "pcs_limits": ch.pcs_limits(i).map(|p| serde_json::json!({
                    "positive": p.positive, "negative": p.negative,
                    "distance_positive": p.distance_positive, "distance_negative": p.distance_negative,
                })),
            })
        })
        .collect();
    let messages: Vec<_> = r
        .messages()
        .iter()
        .map(|m| {
            serde_json::json!({
                "id": m.id,
                "severity": m.severity.to_string(),
                "text": m.text,
                "block": m.block.and_then(|b| b.number),
                "line": m.block.map(|b| b.line),
                "axis": m.axis,
            })
        })
        .collect();
    serde_json::json!({
        "program": name,
        "status": match r.status { RunStatus::Completed => "completed", RunStatus::Aborted => "aborted" },
        "cycles": r.cycles,
        "msg": r.output(),
        "messages": messages,
        "axes": axes,
        "cycle": m.cycle_summary(),
    })
}
