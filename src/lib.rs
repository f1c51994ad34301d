//! fieldprobe — a fieldbus drive-probing stack for machine builders.
//!
//! Servo drives latch an axis position when a touch probe switches. fieldprobe arms those
//! latches over the real fieldbus profiles — CiA 402 touch probe (0x60B8 … 0x60BD, 0x60D0) over
//! CANopen and CoE (CANopen over EtherCAT), SERCOS real-time bits over SoE, PROFIdrive, Beckhoff
//! Lightbus and encoder terminals — and feeds them into a CNC-style core with the behaviour of
//! the ISG kernel functional descriptions **FCT-C4 Measurement**, **FCT-A2 Software limit
//! switches** and **FCT-C14 Workspace monitoring**. The same crate is the `fieldprobe`
//! commissioning tool (feature `cli`).
//!
//! Protocol and control logic is sans-IO: adapters and the core take bytes, positions and the
//! time `now` as arguments and never touch a socket, a thread or the clock. You bring the bus
//! and the cycle; fieldprobe brings the profiles and the rules.
//!
//! # Three ways in
//!
//! Each has a runnable example that needs no hardware (it runs against the emulators) and is the
//! code to copy. [`prelude`] holds the types they share.
//!
//! | you have | you use | example |
//! |---|---|---|
//! | your own EtherCAT master: an ethercrab `MainDevice` and `SubDeviceGroup` | [`Ds402Adapter`](drive::ds402::Ds402Adapter) reads and writes your PDI slices (CiA 402 power states, CSP, touch probe); `bus::ethercat::mailbox::CoeClient` does SDOs on your `MainDevice` (segmented transfers, emergencies kept) | `examples/ethercat_touch_probe.rs` (features `sim`) |
//! | a CAN interface | `link::canopen::CanopenLink::open` on a `bus::can::CanBus` you open (`SocketCanBus`, `VirtualCan`, python-can UDP): fieldprobe's CiA 301 master (NMT, PDO remapping, SYNC, heartbeat, SDO), the same adapter on its process images | `examples/canopen_touch_probe.rs` (features `sim` for its emulated nodes; your own bus needs `canopen`, SocketCAN `socketcan`) |
//! | your own interpolator and drive layer | [`MeasurementRun`](core::measure::run::MeasurementRun) (stop request, `V.A.MERF`, missing-signal rules), [`results::compute`](core::measure::results::compute) (`V.A.MESS`, `MEAS.ACS/PCS.VALUE`, `MOFFS`) with [`Frames`](core::frames::Frames), [`SoftLimits`](core::monitor::SoftLimits) | `examples/measurement_core.rs` (no feature) |
//!
//! ```text
//! cargo run --example ethercat_touch_probe -- --probe-at 12.5 --torque-limit 40
//! cargo run --example canopen_touch_probe -- --probe-at 12.5 --torque-limit 40
//! cargo run --example measurement_core -- --probe-at 112.5
//! ```
//!
//! A fourth way is the whole CNC: [`machine::Machine`] runs NC programs (DIN 66025 with the ISG
//! `#` commands) on a machine file's axes over any link — what `fieldprobe run` does.
//!
//! # Modules by job
//!
//! | job | module |
//! |---|---|
//! | master-side drive adapters (sans-IO): CiA 402, SERCOS, PROFIdrive, Lightbus, encoder terminals; drive definition files | [`drive`], [`drive::catalogue`] |
//! | positions, increments and time | [`units`] |
//! | measurement (FCT-C4): types, signal sources, PLC interface, DC timestamps, fixed stop, results, a measuring motion without NC | [`core::measure`] |
//! | software limit switches (FCT-A2), workspace / protection areas (FCT-C14) | [`core::monitor`] |
//! | frames: G92, zero offsets, MEIN, tool length, `#CS` | [`core::frames`] |
//! | CNC messages with the ISG IDs (`P-ERR-…`) | [`messages`] |
//! | the ISG parameters (`P-AXIS-…`, `P-CHAN-…`, `P-MANU-…`), list files, machine files | [`params`] |
//! | the CNC: channel (block preparation, interpolator), NC language, axes, a machine | [`channel`], [`nc`], [`axis`], [`machine`] |
//! | the transport seam [`Link`](link::Link) and fieldprobe's links | [`link`] |
//! | EtherCAT: wire formats, CoE / SoE mailbox clients, pcap; ESI files (ETG.2000) | `bus::ethercat`, `esi` (feature `ethercat`) |
//! | CANopen: CAN transports, CiA 301 SDO / NMT / PDO / EMCY, EDS | `bus::can`, `bus::canopen` (feature `canopen`) |
//! | emulators: EtherCAT SubDevices, CANopen nodes; the plant (probe surfaces, fixed stops) | [`sim`] (emulators: feature `sim`) |
//!
//! ## Internal modules
//!
//! [`rt`] (the paced cycle of the links that leave the process), [`limits`] (caps on input
//! sizes) and the emulators' building blocks in [`sim`] are public so that the `fieldprobe`
//! binary, the integration tests, the benchmarks and the fuzz targets can use them; they are not
//! part of the surface the examples use and may change in any release.
//!
//! # Cargo features
//!
//! | feature | adds | dependencies |
//! |---|---|---|
//! | (none) | the core: [`units`], [`params`], [`messages`], [`core`], [`drive`], [`axis`], [`channel`], [`nc`], [`machine`] and [`link`] with the in-memory `sim` link | thiserror, toml_edit, serde, tracing, nalgebra; nix, thread-priority, libc on Linux |
//! | `ethercat` | `bus::ethercat`, `esi`, the `ethercrab` re-export, fieldprobe's EtherCAT link `link::ethercat` on a network interface (`ethercat:IFACE`, raw packet socket) | ethercrab, futures-lite, roxmltree, pnet_datalink |
//! | `canopen` | `bus::can` (virtual bus, python-can UDP, candump, fault injection), `bus::canopen`, fieldprobe's CANopen link `link::canopen` (`canopen-udp`) | socket2 |
//! | `socketcan` | `canopen` + the Linux SocketCAN bus and the `socketcan:IF` link (without it `SocketCanBus::open` reports the feature missing) | tokio, socketcan |
//! | `sim` | `ethercat` + `canopen` + the emulators (`sim::esc`, `sim::canopen`) and the in-process links on them (`ethercat-emu`, `canopen-emu`) | — |
//! | `cli` | everything + the `fieldprobe` binary | clap, plotters, anyhow, tracing-subscriber, serde_json |
//!
//! The default is every feature. A drive layer that only wants the CiA 402 adapter and the
//! measurement core uses `default-features = false`; with its own ethercrab master and
//! fieldprobe's CoE client, or with fieldprobe's EtherCAT link on a network interface,
//! `features = ["ethercat"]`; with fieldprobe's CANopen master, `features = ["canopen"]` (plus
//! `socketcan` on Linux). The emulators (`sim`) are only needed to run against emulated buses.
//! CI builds `--no-default-features`, `ethercat`, `canopen`, `canopen,socketcan` and `sim`, runs
//! the core's tests without features, and opens `ethercat:IFACE` and `socketcan:IF` through
//! [`link::open`] in the `ethercat` and `canopen,socketcan` builds.
//!
//! # Sources
//!
//! Doc comments cite their source: the ISG kernel functional descriptions FCT-C4 Measurement,
//! FCT-A2 Software limit switches and FCT-C14 Workspace monitoring by section (`FCT-C4 §7.3`),
//! with their parameter (`P-AXIS-00179`) and message (`P-ERR-70021`) IDs — comments that say
//! "the seeds" mean these documents; CiA 301 and CiA 402 (objects such as 0x60B8); ETG.1000.4 /
//! ETG.1000.6 (EtherCAT data link and application layer, CoE, SoE), ETG.2000 (ESI), ETG.6010
//! (CiA 402 over EtherCAT); IEC 61800-7-204 (SERCOS IDNs); the PROFIdrive profile.
//! `docs/interpretations.md` in the package lists the choices made where the documents are
//! silent.
//!
//! # Layering
//!
//! Arrows point to what a module may use.
//!
//! ```text
//! cli ──► machine ──► nc ──► channel ──► core::{measure, monitor, frames, path}
//!                      │         └────► axis ──► drive (adapters, sans-IO)
//!                      └─► link ──► bus::{ethercat, canopen, can} ──► (ethercrab, socketcan)
//! sim (emulators) ──► drive::model, esi, bus wire formats
//! params, units, messages: used by all
//! ```

pub mod axis;
pub mod bus;
pub mod channel;
pub mod core;
pub mod drive;
#[cfg(feature = "ethercat")]
pub mod esi;
pub mod limits;
pub mod link;
pub mod machine;
pub mod messages;
pub mod nc;
pub mod params;
pub mod prelude;
pub mod rt;
pub mod sim;
pub mod units;

/// ethercrab, the EtherCAT MainDevice fieldprobe's EtherCAT side is built on (`ethercat`
/// feature): use this re-export so that your `MainDevice` and fieldprobe's mailbox clients are
/// of the same version.
#[cfg(feature = "ethercat")]
pub use ethercrab;
