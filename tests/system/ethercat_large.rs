//! Issue 16 "Done when" (EtherCAT): a full channel with its I/O — 32 CiA 402 axes and 64
//! terminals (`examples/machines/channel32_io64.toml`: four stations of an EK1100-kind coupler,
//! eight EL5101-kind encoder terminals and seven EL1252-kind timestamp inputs) — starts, reaches
//! OP and runs seed 004's meas1 on Z, in-process (`ethercat-emu`) and over a veth pair; its
//! process image of 2616 bytes goes over two LRW datagrams in three frames, each datagram's
//! working counter checked on its own and a lost or miscounted one named; a cycle time the wire
//! cannot carry is refused.
//!
//! Expected values come from outside the code under test: the printed values from the seed text
//! (`tests/common/seed004.rs`); the process-image layout, the working counters, the frames and
//! the wire time from the ESC rules and the frame format, computed here (module `layout`) from
//! the devices' image sizes (`esi/README.md`, `drives/cia402-generic.toml`) and ethercrab's
//! documented image layout (notes `ethercat.md` §2.2: every device's inputs first in ring
//! order, then every device's outputs).
//!
//! The veth test runs both ends at the real 1 ms cycle in a private namespace (SKIP where
//! unprivileged namespaces / `ip` are missing); its bounds are those of
//! `tests/system/ethercat_iface_run.rs` (50 consecutive lost exchanges ridden through, at most 10 ‰
//! lost in all; every process bounded by `timeout`).

use fieldprobe::link::ethercat::terminals::TerminalSpec;
use fieldprobe::link::ethercat::{EthercatLink, EthercatSpec, Wire};
use fieldprobe::link::{Link, LinkError, ProcessImage};
use fieldprobe::machine::{LinkChoice, Machine};
use fieldprobe::params::MachineConfig;
use fieldprobe::units::Nanos;

use crate::common::cli;
use crate::common::seed004;
use crate::common::test_data;
use crate::common::veth;

const MACHINE: &str = "examples/machines/channel32_io64.toml";

fn machine_path() -> String {
    format!("{}/{MACHINE}", env!("CARGO_MANIFEST_DIR"))
}

fn config() -> MachineConfig {
    MachineConfig::load(std::path::Path::new(&machine_path())).expect("machine file")
}

/// The process-image layout and its datagrams, from the image sizes and the frame format.
mod layout {
    /// A SubDevice's image: (output bytes, input bytes).
    pub type Sizes = (usize, usize);
    /// `drives/cia402-generic.toml`: RxPDO 0x6040 u16, 0x607A i32, 0x6060 i8, 0x60B8 u16 = 9;
    /// TxPDO 0x6041, 0x6064, 0x60F4, 0x6061, 0x60B9, 0x60BA..0x60BD, 0x6077 = 31.
    pub const SERVO: Sizes = (9, 31);
    /// `esi/README.md`: the 6-byte images of the EL5101 kind.
    pub const EL5101: Sizes = (6, 6);
    /// `esi/README.md`: 2 × 17 input bytes.
    pub const EL1252: Sizes = (0, 34);
    /// No process data.
    pub const EK1100: Sizes = (0, 0);

    /// The segment of the machine file on `ethercat-emu`: the emulator's coupler, 32 servos,
    /// then four stations of a coupler, 8 EL5101 and 7 EL1252.
    pub fn segment() -> Vec<Sizes> {
        let mut v = vec![EK1100];
        v.extend(std::iter::repeat_n(SERVO, 32));
        for _ in 0..4 {
            v.push(EK1100);
            v.extend(std::iter::repeat_n(EL5101, 8));
            v.extend(std::iter::repeat_n(EL1252, 7));
        }
        v
    }

    /// Logical (input range, output range) of every device: inputs first, then outputs, each
    /// in ring order.
    pub fn windows(seg: &[Sizes]) -> Vec<((usize, usize), (usize, usize))> {
        let inputs: usize = seg.iter().map(|s| s.1).sum();
        let (mut i, mut o) = (0, inputs);
        seg.iter()
            .map(|&(out, inp)| {
                let w = ((i, i + inp), (o, o + out));
                i += inp;
                o += out;
                w
            })
            .collect()
    }

    fn touches(w: (usize, usize), a: usize, b: usize) -> bool {
        w.1 > w.0 && a < w.1 && w.0 < b
    }

    /// ESC rule (notes §2.1): an LRW over [a, b) counts +1 per device whose input window it
    /// touches and +2 per device whose output window it touches.
    pub fn lrw_wkc(seg: &[Sizes], a: usize, b: usize) -> u16 {
        windows(seg)
            .iter()
            .map(|&(i, o)| u16::from(touches(i, a, b)) + 2 * u16::from(touches(o, a, b)))
            .sum()
    }

    /// Ring positions an LRW over [a, b) touches, written `devices 1–32, 40`.
    pub fn devices(seg: &[Sizes], a: usize, b: usize) -> String {
        let p: Vec<usize> = windows(seg)
            .iter()
            .enumerate()
            .filter(|(_, &(i, o))| touches(i, a, b) || touches(o, a, b))
            .map(|(p, _)| p)
            .collect();
        let mut parts = Vec::new();
        let mut k = 0;
        while k < p.len() {
            let mut j = k;
            while j + 1 < p.len() && p[j + 1] == p[j] + 1 {
                j += 1;
            }
            parts.push(if j > k {
                format!("{}–{}", p[k], p[j])
            } else {
                p[k].to_string()
            });
            k = j + 1;
        }
        format!("devices {}", parts.join(", "))
    }

    /// Datagram bytes in a 1514-byte Ethernet frame: 1514 − 14 − 2.
    pub const PAYLOAD: usize = 1498;
    /// Datagram header + working counter.
    pub const DG: usize = 12;

    /// ethercrab 0.7.1 with DC (notes §2): frame 0 = FRMW (12 + 8) + an LRW filling the rest;
    /// then LRWs filling whole frames; the AL status checks (12 + 2 each, one per device) in the
    /// room left and in further frames. Returns the LRWs (start, len) and each frame's payload.
    pub fn frames(image: usize, devices: usize) -> (Vec<(usize, usize)>, Vec<usize>) {
        let (mut lrw, mut payloads) = (Vec::new(), Vec::new());
        let (mut sent, mut checks) = (0, 0);
        let mut used = DG + 8;
        loop {
            if sent < image {
                let n = (image - sent).min(PAYLOAD - used - DG);
                lrw.push((sent, n));
                sent += n;
                used += DG + n;
            }
            while checks < devices && used + DG + 2 <= PAYLOAD {
                used += DG + 2;
                checks += 1;
            }
            payloads.push(used);
            if sent == image && checks == devices {
                return (lrw, payloads);
            }
            used = 0;
        }
    }

    /// The wire time of those frames at 100 Mbit/s (80 ns per byte; each frame: 14 + 2 header
    /// bytes, the payload, FCS 4, preamble 8, inter-frame gap 12) plus 1 µs per device and
    /// frame (Beckhoff's forwarding delay figure), ns.
    pub fn wire_ns(payloads: &[usize], devices: usize) -> u64 {
        let bytes: usize = payloads.iter().map(|p| (16 + p).max(60) + 4 + 8 + 12).sum();
        bytes as u64 * 80 + payloads.len() as u64 * devices as u64 * 1000
    }
}

/// The machine file's spec for [`EthercatLink::open`], with `extra` devices the emulated
/// segment carries after it (not named in the machine).
fn spec(extra: &[&str]) -> EthercatSpec {
    let cfg = config();
    let base = std::path::Path::new(&cfg.source).parent();
    EthercatSpec {
        drives: cfg
            .axes
            .iter()
            .map(|a| std::sync::Arc::new(fieldprobe::drive::catalogue::load(&a.drive).unwrap()))
            .collect(),
        cycle: Nanos::from_micros(u64::from(cfg.cycle_time_us)),
        pcap: None,
        terminals: cfg
            .terminals
            .iter()
            .map(|t| {
                let mut s = TerminalSpec::resolve(&t.name, &t.esi, base).unwrap();
                s.after_axes = t.after_axes;
                s
            })
            .collect(),
        emulated_extra: extra
            .iter()
            .enumerate()
            .map(|(i, e)| TerminalSpec::resolve(&format!("EXTRA{i}"), e, None).unwrap())
            .collect(),
    }
}

#[test]
fn the_machine_file_declares_32_axes_and_64_terminals() {
    let _one_module = crate::gate::enter(module_path!());
    let cfg = config();
    assert_eq!(cfg.axes.len(), 32);
    assert_eq!(cfg.terminals.len(), 64);
    // All terminals stand after the 32 axes in the ring.
    assert!(cfg.terminals.iter().all(|t| t.after_axes == 32));
    let kinds = |esi: &str| cfg.terminals.iter().filter(|t| t.esi == esi).count();
    assert_eq!(
        (
            kinds("fieldprobe-ek1100"),
            kinds("fieldprobe-el5101"),
            kinds("fieldprobe-el1252")
        ),
        (4, 32, 28)
    );
    assert_eq!(
        cfg.terminal("ENCB8").map(|t| t.esi.as_str()),
        Some("fieldprobe-el5101")
    );
}

/// The link on the emulated segment: every device in OP, the image over two datagrams with the
/// working counters the layout calls for, the devices not named listed, good cycles.
#[test]
fn the_segment_reaches_op_with_its_image_over_two_datagrams() {
    let _one_module = crate::gate::enter(module_path!());
    let mut link = EthercatLink::open(
        &Wire::Emulated,
        &spec(&["fieldprobe-el5101", "fieldprobe-ek1100"]),
    )
    .unwrap();
    let mut seg = layout::segment();
    seg.push(layout::EL5101);
    seg.push(layout::EK1100);
    let n = seg.len();
    assert_eq!(n, 99);
    let s = link.segment().unwrap();
    assert_eq!(s.len(), n);
    for p in 0..n {
        assert_eq!(
            s.esc(p).unwrap().peek_u16(0x0130) & 0x0F,
            8,
            "device {p} in OP"
        );
    }
    // The layout: 2616 bytes + the extra EL5101's 12, inputs first.
    let image: usize = seg.iter().map(|s| s.0 + s.1).sum();
    assert_eq!(image, 2628);
    let (lrw, payloads) = layout::frames(image, n);
    assert_eq!(lrw.len(), 2);
    let plan: Vec<(u32, usize)> = link
        .cycle_plan()
        .lrw_datagrams()
        .map(|(_, a, l)| (a, l))
        .collect();
    let want: Vec<(u32, usize)> = lrw.iter().map(|&(a, l)| (a as u32, l)).collect();
    assert_eq!(plan, want);
    assert_eq!(link.cycle_plan().frames.len(), payloads.len());
    let wkcs: Vec<u16> = lrw
        .iter()
        .map(|&(a, l)| layout::lrw_wkc(&seg, a, a + l))
        .collect();
    assert_eq!(link.datagram_wkcs(), &wkcs[..]);
    assert_eq!(link.wire_time().total_ns(), layout::wire_ns(&payloads, n));
    // Every SubDevice with its role; the emulator's coupler and the two extras not named.
    let unnamed: Vec<usize> = link
        .bus_devices()
        .iter()
        .filter(|b| b.role == fieldprobe::link::ethercat::terminals::Role::NotNamed)
        .map(|b| b.position)
        .collect();
    assert_eq!(unnamed, vec![0, 97, 98]);
    let report = link.startup_messages();
    let listed: Vec<&str> = report
        .iter()
        .filter(|m| m.id == 900401)
        .map(|m| m.text.as_str())
        .collect();
    assert_eq!(listed.len(), 3, "{report:?}");
    assert!(
        listed[1].starts_with("EtherCAT device 97 (FP-EL5101"),
        "{listed:?}"
    );
    assert!(
        listed[1].contains("(6 output / 6 input bytes)"),
        "{listed:?}"
    );
    assert!(
        report[0].text.contains("99 SubDevices in OP"),
        "{:?}",
        report[0]
    );
    // Good cycles; a terminal's loopback (inputs = inverted outputs) through the API, in
    // either datagram.
    let mut images: Vec<ProcessImage> = (0..32).map(|_| ProcessImage::new(9, 31)).collect();
    let names = ["ENCA1", "ENCD8"];
    for name in names {
        let k = (0..64)
            .find(|&k| link.terminal_name(k) == Some(name))
            .unwrap();
        link.terminal_outputs_mut(k)
            .unwrap()
            .copy_from_slice(&[1, 2, 3, 4, 5, 6]);
    }
    for c in 1..=3 {
        link.exchange(Nanos::from_micros(1000 * c), &mut images)
            .unwrap();
    }
    for name in names {
        let k = (0..64)
            .find(|&k| link.terminal_name(k) == Some(name))
            .unwrap();
        assert_eq!(
            link.terminal_inputs(k).unwrap(),
            &[!1u8, !2, !3, !4, !5, !6],
            "{name}"
        );
    }
    let ts = (0..64)
        .find(|&k| link.terminal_name(k) == Some("TSC7"))
        .unwrap();
    assert_eq!(link.terminal_inputs(ts).unwrap().len(), 34);
}

/// A lost and a miscounted datagram of the two are named: their number, logical range and the
/// devices they cover; the inputs stay as they were; the next cycle is good again.
#[test]
fn a_lost_or_miscounted_datagram_of_a_multi_frame_cycle_is_named() {
    let _one_module = crate::gate::enter(module_path!());
    let mut link = EthercatLink::open(&Wire::Emulated, &spec(&[])).unwrap();
    let seg = layout::segment();
    let image: usize = seg.iter().map(|s| s.0 + s.1).sum();
    assert_eq!(image, 2616);
    let (lrw, _) = layout::frames(image, seg.len());
    let name = |k: usize| {
        let (a, l) = lrw[k];
        format!(
            "LRW datagram {} of 2 (logical {:#010x}..{:#010x}, {l} bytes, {})",
            k + 1,
            a,
            a + l,
            layout::devices(&seg, a, a + l)
        )
    };
    let mut images: Vec<ProcessImage> = (0..32).map(|_| ProcessImage::new(9, 31)).collect();
    let mut now = 0;
    let mut cycle = |link: &mut EthercatLink, images: &mut Vec<ProcessImage>| {
        now += 1000;
        link.exchange(Nanos::from_micros(now), images)
    };
    cycle(&mut link, &mut images).unwrap();
    for (k, fault) in [
        (1, "lost"),
        (0, "lost"),
        (1, "miscounted"),
        (0, "miscounted"),
    ] {
        let n = link.exchanges();
        if fault == "lost" {
            link.lose_datagram_at(n, k);
        } else {
            link.miscount_datagram_at(n, k);
        }
        for img in &mut images {
            img.inputs.fill(0xA5);
        }
        let reason = match cycle(&mut link, &mut images) {
            Err(LinkError::Lost { reason, .. }) => reason,
            other => panic!("{fault} datagram {k}: {other:?}"),
        };
        let (a, l) = lrw[k];
        let tail = if fault == "lost" {
            ": lost, its frame did not come back".to_string()
        } else {
            let w = layout::lrw_wkc(&seg, a, a + l);
            format!(": working counter {}, expected {w}", w - 1)
        };
        let want = format!("{}{tail}", name(k));
        assert!(reason.starts_with(&want), "{reason}\nwanted {want}");
        assert!(
            images.iter().all(|i| i.inputs.iter().all(|&b| b == 0xA5)),
            "{fault} datagram {k}: the inputs stay"
        );
        cycle(&mut link, &mut images).unwrap();
    }
    // The datagram ranges of the names: the cut at 1466 falls into a timestamp input of
    // station B (its window counts in both).
    assert_eq!(lrw, vec![(0, 1466), (1466, 1150)]);
}

/// Through the machine: a lost first datagram beyond `max_lost_cycles` is error 900012 naming
/// it; the terminals' process data by name.
#[test]
fn the_machine_names_the_datagram_in_900012_and_reaches_terminals_by_name() {
    let _one_module = crate::gate::enter(module_path!());
    let mut cfg = config();
    cfg.apply_set("max_lost_cycles=0").unwrap();
    let mut m = Machine::with_link(&cfg, &LinkChoice::new("ethercat-emu")).unwrap();
    assert_eq!(m.terminal_names().len(), 64);
    m.terminal_outputs_mut("ENCC3")
        .unwrap()
        .copy_from_slice(&[0x10, 0x20, 0x30, 0x40, 0x50, 0x60]);
    assert!(m.terminal_outputs_mut("NOPE").is_none());
    m.step();
    m.step();
    assert_eq!(
        m.terminal_inputs("ENCC3").unwrap(),
        &[!0x10u8, !0x20, !0x30, !0x40, !0x50, !0x60]
    );
    let n = m.link().exchanges();
    m.link_mut().lose_exchange_at(n);
    m.step();
    let msgs = m.channel_mut().take_messages();
    let lost = msgs
        .iter()
        .find(|e| e.id == 900012)
        .unwrap_or_else(|| panic!("{msgs:?}"));
    assert!(
        lost.text
            .contains("LRW datagram 1 of 2 (logical 0x00000000..0x000005ba, 1466 bytes,"),
        "{}",
        lost.text
    );
}

/// meas1 on Z of the 32-axis machine with its terminals prints the seed's values.
#[test]
fn meas1_on_32_axes_and_64_terminals_in_process_prints_the_seed_values() {
    let _one_module = crate::gate::enter(module_path!());
    if !test_data::seeds_present(
        "meas1_on_32_axes_and_64_terminals_in_process_prints_the_seed_values",
    ) {
        return;
    }
    let o = cli::fieldprobe(&[
        "run",
        "examples/nc/seed004/meas1.nc",
        "--machine",
        MACHINE,
        "--link",
        "ethercat-emu",
        "--probe-at",
        "Z=100",
    ]);
    let err = cli::stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{err}");
    assert_eq!(
        cli::stdout(&o).lines().collect::<Vec<_>>(),
        seed004::seed_stdout_lines("meas1"),
        "{err}"
    );
    // The start-up report: the segment, the coupler not named, the wire time.
    let seg = layout::segment();
    let image: usize = seg.iter().map(|s| s.0 + s.1).sum();
    let (_, payloads) = layout::frames(image, seg.len());
    let ns = layout::wire_ns(&payloads, seg.len());
    assert!(
        err.contains("info 900400: EtherCAT segment: 97 SubDevices in OP: 32 axis drives, 64 terminals named in the machine, 1 not named"),
        "{err}"
    );
    assert!(
        err.contains("info 900401: EtherCAT device 0 (FP-EK1100"),
        "{err}"
    );
    let wire = format!(
        "info 900402: EtherCAT wire time per cycle {:.1} µs ({} frames",
        ns as f64 / 1000.0,
        payloads.len()
    );
    assert!(err.contains(&wire), "{wire}\n{err}");
    assert_eq!(
        err.lines().filter(|l| l.starts_with("info 9004")).count(),
        3,
        "{err}"
    );
}

/// A cycle time below the wire time is refused at start-up (exit 2, error 900403 with the
/// shortest cycle the wire carries); that shortest cycle is accepted.
#[test]
fn a_cycle_time_the_wire_cannot_carry_is_refused() {
    let _one_module = crate::gate::enter(module_path!());
    let seg = layout::segment();
    let image: usize = seg.iter().map(|s| s.0 + s.1).sum();
    let (_, payloads) = layout::frames(image, seg.len());
    let shortest_us = layout::wire_ns(&payloads, seg.len()).div_ceil(1000);
    assert!((500..1000).contains(&shortest_us), "{shortest_us}");
    let dir = tempfile::tempdir().unwrap();
    let prog = dir.path().join("end.nc");
    std::fs::write(&prog, "%end\nN10 M30\n").unwrap();
    let prog = prog.to_str().unwrap();
    for (us, code) in [(500, 2), (shortest_us - 1, 2), (shortest_us, 0)] {
        let set = format!("cycle_time_us={us}");
        let o = cli::fieldprobe(&[
            "run",
            prog,
            "--machine",
            MACHINE,
            "--link",
            "ethercat-emu",
            "--set",
            &set,
        ]);
        let err = cli::stderr(&o);
        assert_eq!(o.status.code(), Some(code), "{us} µs: {err}");
        if code == 2 {
            assert!(
                err.contains("error 900403: the EtherCAT wire needs"),
                "{err}"
            );
            assert!(
                err.contains(&format!(
                    "more than the cycle time of {us} µs (cycle_time_us); the shortest cycle the wire carries is {shortest_us} µs"
                )),
                "{err}"
            );
        } else {
            assert!(err.contains("info 900402:"), "{err}");
        }
    }
}

/// The same machine over a veth pair against `fieldprobe sim ethercat` playing the same segment
/// plus one EL5101 the machine does not name: OP, meas1 with the seed's values, the extra
/// device listed.
///
/// The emulator runs `--lockstep`: its drives step once per process-data cycle of the master
/// (after the frame that completes the image, however it is split), not at SYNC0 on its own
/// clock. With its own clock, 98 emulated devices and the master — two debug-profile processes
/// on a shared two-core CI machine — lost the race against the devices' 100 ms sync-manager
/// watchdog whenever a frame waited for a descheduled process (seen in 5 of 8 runs at a load
/// average of 6); the clock behaviour itself is covered by `tests/system/ethercat_iface_run.rs` and
/// `tests/system/ethercat_rt.rs`. The master still runs its paced 1 ms cycle with the link's
/// real-interface timeouts. A reply later than 20 ms during the start-up's ten thousand frames
/// is the link's own business since issue 26 (the frame is sent again, up to ten times). One
/// failure the environment alone causes — the master itself descheduled for longer than the
/// devices' watchdog (error 900012 "the master missed") — is retried once, said on stderr; every
/// other failure, and a second one, fails the test.
#[test]
fn meas1_on_32_axes_and_64_terminals_over_a_veth_pair_prints_the_seed_values() {
    let _one_module = crate::gate::enter(module_path!());
    const NAME: &str = "meas1_on_32_axes_and_64_terminals_over_a_veth_pair_prints_the_seed_values";
    if !test_data::seeds_present(NAME) {
        return;
    }
    let station =
        " --device esi/fieldprobe-ek1100.xml --device esi/fieldprobe-el5101.xml:8 --device esi/fieldprobe-el1252.xml:7";
    let sim = format!(
        "ethercat --iface v1 --device esi/fieldprobe-ek1100.xml --device esi/fieldprobe-cia402-servo.xml:32{} --device esi/fieldprobe-el5101.xml --probe-at 3=100 --lockstep",
        station.repeat(4)
    );
    let link = format!("ethercat:v0 --machine {MACHINE} --set max_lost_cycles={MAX_LOST}");
    let mut attempt = 0;
    let (code, stdout, stderr) = loop {
        attempt += 1;
        let Some((code, stdout, stderr)) = veth::netns::meas1_against_sim(
            NAME,
            veth::veth_probe,
            &["scripts/netns.sh"],
            "",
            &sim,
            &link,
        ) else {
            return;
        };
        let environment = code == Some(1) && stderr.contains("error 900012: the master missed");
        if code != Some(0) && environment && attempt == 1 {
            eprintln!("RETRY {NAME}: the environment delayed the run:\n{stderr}");
            continue;
        }
        break (code, stdout, stderr);
    };
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    assert_eq!(
        stdout.lines().collect::<Vec<_>>(),
        seed004::seed_stdout_lines("meas1"),
        "{stderr}"
    );
    assert!(
        stderr.contains("info 900400: EtherCAT segment: 98 SubDevices in OP: 32 axis drives, 64 terminals named in the machine, 2 not named"),
        "{stderr}"
    );
    assert!(
        stderr.contains("info 900401: EtherCAT device 0 (FP-EK1100"),
        "{stderr}"
    );
    assert!(
        stderr.contains("info 900401: EtherCAT device 97 (FP-EL5101"),
        "{stderr}"
    );
    let summary = stderr
        .lines()
        .find(|l| l.starts_with("cycle: "))
        .unwrap_or_else(|| panic!("no cycle summary:\n{stderr}"));
    let number_after = |key: &str| -> u64 {
        summary
            .split(key)
            .nth(1)
            .and_then(|r| r.split(|c: char| !c.is_ascii_digit()).next())
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no {key:?} in {summary}"))
    };
    let (cycles, lost) = (number_after("cycle: "), number_after("lost "));
    eprintln!("{summary}");
    assert!(
        lost * 1000 <= cycles * LOST_PERMILLE,
        "{lost} of {cycles} exchanges lost (at most {LOST_PERMILLE} per mille): {summary}"
    );
}

/// Consecutive lost exchanges the veth run rides through (as `tests/system/ethercat_iface_run.rs`).
const MAX_LOST: u32 = 50;
/// Lost exchanges allowed in total, per mille of the cycles.
const LOST_PERMILLE: u64 = 10;
