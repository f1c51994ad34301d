//! Issue 16, item 2 "Bus load on CAN" (docs/canopen.md "Bus load", "On the wire"):
//!
//! * the bus-load figures of the default machine (X, Y, Z on `cia402-generic`, node ids 1 … 3)
//!   at 1 Mbit/s and 500 kbit/s, computed here from the CAN frame format and this file's own
//!   list of the PDOs the machine maps, equal the link's — and the PDOs the nodes really carry
//!   (read back by SDO) are that list;
//! * a configuration above 100 % is refused (exit 2, the load, the frames per cycle and the
//!   shortest cycle that fits in the message), one above 70 % is warned about (900070), a bit
//!   rate CiA 301 does not have is bad input;
//! * on the virtual bus every frame takes its wire time: after the SYNC, the frames follow one
//!   another back to back in the order of their identifiers, so a TPDO's reception time minus
//!   the SYNC's is the sum of the wire times of the frames that won arbitration before it —
//!   each wire time counted here bit by bit (CRC-15, stuff bits); an overloaded cycle runs into
//!   the next SYNC.
//!
//! Frame format (ISO 11898-1, base format): SOF 1, identifier 11, RTR 1, IDE 1, r0 1, DLC 4,
//! data 8 n, CRC 15 — stuffed — then CRC delimiter 1, ACK 2, EOF 7, intermission 3. Worst case:
//! one stuff bit per 4 bits after the first of the stuffed 34 + 8 n.

use std::sync::Arc;

use fieldprobe::bus::can::{Bitrate, CanBus, CanFrame, Delivery, VirtualCan, VirtualEndpoint};
use fieldprobe::drive::catalogue;
use fieldprobe::link::canopen::{plan_bus_load, CanopenLink};
use fieldprobe::link::{Link, ProcessImage};
use fieldprobe::sim::canopen::{CanopenSegment, EmulatedNode};
use fieldprobe::units::Nanos;

use crate::common::cli;
use cli::{fieldprobe, stderr, stdout};

// ---------------------------------------------------------------------------------------------
// The frame format, independently of the crate
// ---------------------------------------------------------------------------------------------

/// Worst-case bit times of a base-format data frame with `n` data bytes, intermission included.
fn worst_bits(n: u64) -> u64 {
    let stuffed = 34 + 8 * n;
    stuffed + 13 + (stuffed - 1) / 4
}

/// The exact bit times of a base-format data frame: its bits from SOF to the end of the CRC,
/// their stuff bits, the 13 bits after.
fn exact_bits(f: &CanFrame) -> u64 {
    let mut bits: Vec<u8> = vec![0]; // SOF
    let field = |bits: &mut Vec<u8>, v: u32, n: u32| {
        for k in (0..n).rev() {
            bits.push(((v >> k) & 1) as u8);
        }
    };
    field(&mut bits, f.id, 11);
    field(&mut bits, 0, 3); // RTR, IDE, r0: dominant
    field(&mut bits, u32::from(f.len), 4);
    for &b in f.payload() {
        field(&mut bits, u32::from(b), 8);
    }
    // CRC-15, generator 0x4599.
    let mut crc: u32 = 0;
    for &b in &bits {
        let top = (crc >> 14) & 1;
        crc = (crc << 1) & 0x7FFF;
        if u32::from(b) ^ top == 1 {
            crc ^= 0x4599;
        }
    }
    field(&mut bits, crc, 15);
    let mut stuff = 0;
    let (mut last, mut run) = (2u8, 0);
    for &b in &bits {
        if b == last {
            run += 1;
        } else {
            last = b;
            run = 1;
        }
        if run == 5 {
            stuff += 1;
            last ^= 1;
            run = 1;
        }
    }
    bits.len() as u64 + stuff + 13
}

// ---------------------------------------------------------------------------------------------
// The default machine's PDOs, as this test counts them
// ---------------------------------------------------------------------------------------------

/// Data bytes of the PDOs of one default-machine node (`drives/cia402-generic.toml` with the
/// master's layout, docs/canopen.md "PDO layout"), by CiA 402 object sizes: every frame of the
/// worst cycle — RPDO 1 controlword 2 + target position 4 + touch probe function 2, RPDO 2
/// modes of operation 1 (on change, may go in any cycle), the cyclic TPDOs statusword 2 +
/// modes display 1 + touch probe status 2 + torque 2 and position 4 + following error 4, and
/// one touch-probe TPDO of 8 (positive and negative edge position of the one armed probe).
const NODE_FRAMES: [u64; 5] = [8, 1, 7, 8, 8];

/// Objects per PDO as the nodes must carry them: (mapping index, [(object, bytes)]).
const MAPPING: [(u16, &[(u16, u32)]); 6] = [
    (0x1600, &[(0x6040, 2), (0x607A, 4), (0x60B8, 2)]),
    (0x1601, &[(0x6060, 1)]),
    (0x1A00, &[(0x60BA, 4), (0x60BB, 4)]),
    (0x1A01, &[(0x60BC, 4), (0x60BD, 4)]),
    (
        0x1A02,
        &[(0x6041, 2), (0x6061, 1), (0x60B9, 2), (0x6077, 2)],
    ),
    (0x1A03, &[(0x6064, 4), (0x60F4, 4)]),
];

/// Bit times of one cycle of `nodes` default-machine nodes: SYNC and the nodes' frames.
fn cycle_bits(nodes: u64) -> u64 {
    worst_bits(0) + nodes * NODE_FRAMES.iter().map(|&n| worst_bits(n)).sum::<u64>()
}

/// The load (docs/canopen.md): cycle bits / (rate × cycle) + heartbeats (1 byte every 100 ms
/// per node) + the 10 % reserve.
fn load(nodes: u64, bps: f64, cycle_s: f64) -> f64 {
    cycle_bits(nodes) as f64 / (bps * cycle_s)
        + nodes as f64 * worst_bits(1) as f64 / (bps * 0.1)
        + 0.10
}

fn generic() -> Arc<catalogue::DriveDefinition> {
    Arc::new(catalogue::load("cia402-generic").unwrap())
}

#[test]
fn default_machine_bus_load_at_1_mbit_and_500_kbit_matches_the_frame_format() {
    // The worst case of the frame format, by hand: 135 bits for 8 bytes, 55 for a SYNC.
    assert_eq!((worst_bits(8), worst_bits(0)), (135, 55));
    let drives = vec![generic(); 3];
    for (bps, cycles_us) in [
        (1_000_000u32, [1000u64, 2000, 3000, 4000]),
        (500_000, [2000, 4000, 6000, 8000]),
    ] {
        let rate = Bitrate::new(bps).unwrap();
        for us in cycles_us {
            let l = plan_bus_load(&drives, &[1, 2, 3], rate, Nanos::from_micros(us)).unwrap();
            let want = load(3, f64::from(bps), us as f64 * 1e-6);
            assert_eq!(l.frames, 1 + 3 * NODE_FRAMES.len(), "{bps} {us}");
            assert_eq!(l.bits, cycle_bits(3), "{bps} {us}");
            assert!(
                (l.load() - want).abs() < 1e-12,
                "{bps} {us}: {} vs {want}",
                l.load()
            );
        }
    }
    // The figures of the issue: the default 1 ms cycle is far beyond the bus (about 200 %).
    let at_1ms = load(3, 1e6, 1e-3);
    assert!(at_1ms > 1.9 && at_1ms < 2.0, "{at_1ms}");
    // The link that runs has the same figure, and its nodes carry exactly the PDOs counted.
    for (bps, us) in [(1_000_000u32, 4000u64), (500_000, 8000)] {
        let rate = Bitrate::new(bps).unwrap();
        let mut link =
            CanopenLink::emulated_at(&drives, Nanos::from_micros(us), rate, None).unwrap();
        let want = load(3, f64::from(bps), us as f64 * 1e-6);
        assert!((link.bus_load().load() - want).abs() < 1e-12);
        assert!(want < 0.70, "{bps} at {us} µs: {want}");
        for device in 0..3 {
            for (index, objects) in MAPPING {
                let n = link.read_object(device, index, 0).unwrap();
                assert_eq!(n as usize, objects.len(), "{index:#06x}");
                for (j, &(object, bytes)) in objects.iter().enumerate() {
                    let v = link.read_object(device, index, j as u8 + 1).unwrap() as u32;
                    assert_eq!(
                        (v >> 16, v & 0xFF),
                        (u32::from(object), 8 * bytes),
                        "{index:#06x}:{}",
                        j + 1
                    );
                }
            }
            // On change: transmission type 0 for the touch probe TPDOs, 1 for the others.
            for (comm, ty) in [(0x1800u16, 0), (0x1801, 0), (0x1802, 1), (0x1803, 1)] {
                assert_eq!(
                    link.read_object(device, comm, 2).unwrap(),
                    ty,
                    "{comm:#06x}"
                );
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Refusal and warning on the command line
// ---------------------------------------------------------------------------------------------

/// The shortest cycle (µs) at which `nodes` default-machine nodes load the bus `limit`.
fn shortest_us(nodes: u64, bps: f64, limit: f64) -> u64 {
    let room = limit - nodes as f64 * worst_bits(1) as f64 / (bps * 0.1) - 0.10;
    (cycle_bits(nodes) as f64 / (bps * room) * 1e6).ceil() as u64
}

#[test]
fn a_cycle_the_bus_cannot_carry_is_refused_and_a_loaded_one_warned_about() {
    for (sets, bps, us) in [
        (vec![], 1e6, 1000u64),
        (
            vec!["--set", "can.bitrate=500k", "--set", "cycle_time_us=4000"],
            5e5,
            4000,
        ),
    ] {
        let mut args = vec!["run", "examples/nc/hello.nc", "--link", "canopen-emu"];
        args.extend(&sets);
        let o = fieldprobe(&args);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{e}");
        let l = load(3, bps, us as f64 * 1e-6);
        for want in [
            format!("CAN bus load {:.1} %", 100.0 * l),
            format!("{} frames per cycle", 1 + 3 * NODE_FRAMES.len()),
            format!(
                "the shortest cycle that fits is {} µs",
                shortest_us(3, bps, 1.0)
            ),
            "<default>".to_string(),
            "cycle_time_us".to_string(),
        ] {
            assert!(e.contains(&want), "{want:?} in {e}");
        }
        assert!(stdout(&o).is_empty());
    }
    // Between 70 % and 100 %: the run goes, with warning 900070 first.
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--link",
        "canopen-emu",
        "--set",
        "cycle_time_us=3000",
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(0), "{e}");
    let l = load(3, 1e6, 3e-3);
    assert!(l > 0.70 && l < 1.0, "{l}");
    assert!(
        e.starts_with(&format!("warning 900070: CAN bus load {:.1} %", 100.0 * l)),
        "{e}"
    );
    // The example machine for CAN runs without it.
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--link",
        "canopen-emu",
        "--machine",
        "examples/machines/canopen_xyz.toml",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(!stderr(&o).contains("900070"), "{}", stderr(&o));
}

#[test]
fn a_bit_rate_cia_301_does_not_have_is_bad_input_naming_file_line_and_the_rates() {
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--link",
        "canopen-emu",
        "--set",
        "can.bitrate=400k",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("bitrate = 400k") && e.contains("10k, 20k, 50k, 125k, 250k, 500k, 800k, 1M"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("m.toml");
    std::fs::write(
        &file,
        "[channel]\ncycle_time_us = 8000\n[can]\nbitrate = 100000\n[[axis]]\nname = \"X\"\n",
    )
    .unwrap();
    let f = file.to_str().unwrap();
    let o = fieldprobe(&[
        "run",
        "examples/nc/hello.nc",
        "--machine",
        f,
        "--link",
        "canopen-emu",
    ]);
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains(&format!("{f}:4")) && e.contains("bitrate = 100000"),
        "{e}"
    );
    // 125k is one: one node at 8 ms runs — at 75.5 % (650 bit times of 1000, heartbeat 0.5 %,
    // reserve 10 %) with warning 900070.
    std::fs::write(
        &file,
        "[channel]\ncycle_time_us = 8000\n[can]\nbitrate = \"125k\"\n[[axis]]\nname = \"X\"\n",
    )
    .unwrap();
    let hello = dir.path().join("x.nc");
    std::fs::write(&hello, "N10 G01 X1 F1000\nN20 M30\n").unwrap();
    let o = fieldprobe(&[
        "run",
        hello.to_str().unwrap(),
        "--machine",
        f,
        "--link",
        "canopen-emu",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    let l = load(1, 125e3, 8e-3);
    assert!(l > 0.70 && l < 1.0, "{l}");
    assert!(
        stderr(&o).contains(&format!(
            "warning 900070: CAN bus load {:.1} % at 125 kbit/s",
            100.0 * l
        )),
        "{}",
        stderr(&o)
    );
}

// ---------------------------------------------------------------------------------------------
// Timing on the virtual bus
// ---------------------------------------------------------------------------------------------

fn is(f: &CanFrame, id: u32) -> bool {
    f.id == id && !f.extended && !f.rtr
}

/// The frames of one exchange from the SYNC on, checked: back to back, each taking its exact
/// wire time, in identifier order among those queued together; returns them.
#[track_caller]
fn check_after_sync(trace: &[Delivery], bit_ns: u64) -> Vec<Delivery> {
    let s = trace
        .iter()
        .position(|d| is(&d.frame, 0x080))
        .expect("a SYNC");
    let after: Vec<Delivery> = trace[s..].to_vec();
    for d in &after {
        assert_eq!(
            d.at.0 - d.start.0,
            exact_bits(&d.frame) * bit_ns,
            "{:03X} {:02X?}",
            d.frame.id,
            d.frame.payload()
        );
    }
    // The TPDOs of the SYNC, and what came with them.
    let tpdos: Vec<&Delivery> = after[1..]
        .iter()
        .take_while(|d| (0x181..=0x4FF).contains(&d.frame.id) && d.frame.id & 0x80 != 0)
        .collect();
    assert!(!tpdos.is_empty(), "{after:?}");
    for (k, d) in tpdos.iter().enumerate() {
        // Reception time minus the SYNC's = the wire times of the frames before it.
        let before: u64 = tpdos[..=k]
            .iter()
            .map(|x| exact_bits(&x.frame) * bit_ns)
            .sum();
        assert_eq!(d.at.0 - after[0].at.0, before, "TPDO {:03X}", d.frame.id);
        if k > 0 {
            assert!(tpdos[k - 1].frame.id < d.frame.id, "arbitration order");
        }
    }
    after
}

#[test]
fn sync_to_tpdo_time_is_the_wire_time_of_the_frames_before_it() {
    for (bps, cycle_us) in [(1_000_000u32, 4000u64), (500_000, 8000)] {
        let bit_ns = 1_000_000_000 / u64::from(bps);
        let d = generic();
        let mut link = CanopenLink::emulated_at(
            &vec![d.clone(); 3],
            Nanos::from_micros(cycle_us),
            Bitrate::new(bps).unwrap(),
            None,
        )
        .unwrap();
        let (_, epoch) = link.bus_clock().unwrap();
        let mut images = vec![ProcessImage::new(d.rxpdo.len(), d.txpdo.len()); 3];
        link.trace_bus(true);
        for k in 1..=3u64 {
            link.exchange(Nanos::from_micros(k * cycle_us), &mut images)
                .unwrap();
            let trace = link.take_bus_trace();
            let after = check_after_sync(&trace, bit_ns);
            // The bus was idle at the SYNC's time: it starts then.
            assert_eq!(after[0].start, Nanos(epoch.0 + k * cycle_us * 1000));
            // Every node's two cyclic TPDOs came (plus, at the first SYNC, the four on-change
            // ones per node).
            let cyclic = after
                .iter()
                .filter(|x| (0x381..=0x4FF).contains(&x.frame.id))
                .count();
            let on_change = after
                .iter()
                .filter(|x| (0x181..=0x2FF).contains(&x.frame.id))
                .count();
            assert_eq!(cyclic, 6);
            assert_eq!(on_change, if k == 1 { 6 } else { 0 }, "exchange {k}");
            // The RPDOs of the next exchange went before this SYNC and after the previous
            // exchange's TPDOs: all of them before the SYNC, none after.
            let s = trace.iter().position(|x| is(&x.frame, 0x080)).unwrap();
            let rpdos = trace[..s]
                .iter()
                .filter(|x| (0x201..=0x57F).contains(&x.frame.id) && x.frame.id & 0x80 == 0)
                .count();
            assert!(rpdos >= 3, "exchange {k}: {rpdos} RPDOs before the SYNC");
        }
    }
}

/// Run `hub` to `t`: every completed frame goes to the nodes at its end, their answers onto
/// the bus; the completed frames are returned.
fn run_nodes_to(
    hub: &VirtualCan,
    node_side: &mut VirtualEndpoint,
    seg: &mut CanopenSegment,
    t: Nanos,
) -> Vec<Delivery> {
    let mut done = Vec::new();
    while let Some(x) = hub.advance(t) {
        done.push(x);
        while let Some((f, at)) = node_side.recv_timed() {
            let mut out = Vec::new();
            seg.receive(&f, at, at, &mut |a| out.push(a));
            for a in out {
                node_side.send(&a).unwrap();
            }
        }
    }
    done
}

#[test]
fn an_overloaded_cycle_runs_into_the_next_sync_on_the_virtual_bus() {
    // Three nodes with the drive file's layout as they boot (2 RPDOs and 4 TPDOs each,
    // transmission type 1) at 1 ms on 1 Mbit/s; the master of this test sends a SYNC on the
    // 1 ms grid regardless. 12 TPDOs of ≥ 111 bit times per SYNC (≥ 1.3 ms) do not fit 1 ms:
    // from the second SYNC on each one is late — it waits for the frame on the wire.
    let d = generic();
    let hub = VirtualCan::with_bitrate(Bitrate::DEFAULT);
    let mut master = hub.endpoint();
    let mut node_side = hub.endpoint();
    let nodes = (1..=3u8)
        .map(|id| EmulatedNode::new(id, &d).unwrap())
        .collect();
    let mut seg = CanopenSegment::new(nodes, Nanos::from_micros(1000));
    // Boot-up, then NMT start of all nodes.
    let mut out = Vec::new();
    seg.poll(Nanos::ZERO, &mut |a| out.push(a));
    for a in out {
        node_side.send(&a).unwrap();
    }
    master
        .send_at(&CanFrame::new(0, &[0x01, 0x00]).unwrap(), Nanos::ZERO)
        .unwrap();
    run_nodes_to(&hub, &mut node_side, &mut seg, Nanos::from_micros(900));
    let sync = CanFrame::new(0x080, &[]).unwrap();
    let mut late = Vec::new();
    let mut tpdos = 0;
    for k in 1..=5u64 {
        let due = Nanos::from_micros(1000 * k);
        master.send_at(&sync, due).unwrap();
        let done = run_nodes_to(&hub, &mut node_side, &mut seg, Nanos(due.0 + 999_999));
        for x in &done {
            if is(&x.frame, 0x080) {
                late.push(x.start.0 - due.0);
            }
            tpdos += usize::from((0x181..=0x4FF).contains(&x.frame.id) && x.frame.id & 0x80 != 0);
        }
    }
    assert_eq!(late.len(), 5, "{late:?}");
    assert_eq!(late[0], 0, "{late:?}");
    assert!(late[1..].iter().all(|&l| l > 0), "{late:?}");
    // And the TPDOs fall behind: fewer completed than 12 per SYNC sent.
    assert!(tpdos < 5 * 12, "{tpdos}");
    while master.recv_timed().is_some() {}
}
