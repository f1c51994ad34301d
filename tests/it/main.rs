//! Integration tests that run in process: the core, the emulators, the links on virtual time,
//! the `fieldprobe` binary on embedded and emulated inputs. One test binary (issue 29): each
//! former test file is a module here, built when the features it needs are on, so
//! `cargo test --no-default-features` runs the core's modules alone.
//!
//! Tests that use namespaces, veth pairs, the SocketCAN guest, Python peers, cargo-fuzz or the
//! wall clock are in `tests/system`; the allocation-counting checks are their own binaries
//! (`tests/ethercat_alloc.rs`, `tests/canopen_alloc.rs`).

#[path = "../common/mod.rs"]
mod common;

mod area_geom;
mod areas;
mod areas_manual;
#[cfg(feature = "cli")]
mod areas_nc;
#[cfg(feature = "sim")]
mod areas_plane;
#[cfg(feature = "cli")]
mod can_busload;
#[cfg(feature = "sim")]
mod canopen_link;
#[cfg(feature = "sim")]
mod canopen_pdo_fit;
#[cfg(feature = "canopen")]
mod canopen_sdo;
#[cfg(feature = "sim")]
mod canopen_sync_watch;
#[cfg(feature = "cli")]
mod cli_areas_plot;
#[cfg(feature = "cli")]
mod cli_canopen;
#[cfg(feature = "cli")]
mod cli_check;
#[cfg(feature = "cli")]
mod cli_esi;
#[cfg(feature = "cli")]
mod cli_ethercat;
#[cfg(feature = "cli")]
mod cli_messages;
#[cfg(feature = "cli")]
mod cli_robustness;
#[cfg(feature = "cli")]
mod cli_sdos;
#[cfg(feature = "cli")]
mod cli_seed001;
#[cfg(feature = "cli")]
mod cli_trace;
#[cfg(feature = "cli")]
mod drive_from_vendor;
mod drive_matrix;
#[cfg(feature = "cli")]
mod drive_physics;
mod ds402;
#[cfg(feature = "canopen")]
mod eds;
#[cfg(feature = "sim")]
mod emcy_flood;
#[cfg(feature = "sim")]
mod esc;
#[cfg(feature = "sim")]
mod esc_clock;
#[cfg(feature = "sim")]
mod esc_mailbox;
#[cfg(feature = "sim")]
mod esc_servo_clock;
#[cfg(feature = "sim")]
mod esc_sessions;
#[cfg(feature = "ethercat")]
mod esi;
#[cfg(feature = "cli")]
mod esi_corpus;
#[cfg(feature = "ethercat")]
mod esi_select;
#[cfg(feature = "ethercat")]
mod esi_sii;
#[cfg(feature = "sim")]
mod ethercat_link;
#[cfg(feature = "sim")]
mod ethercat_mailbox_client;
#[cfg(feature = "sim")]
mod ethercat_soe_client;
#[cfg(feature = "ethercat")]
mod ethercat_wire;
#[cfg(feature = "sim")]
mod ethercrab_inproc;
#[cfg(feature = "sim")]
mod ethercrab_servo;
#[cfg(feature = "sim")]
mod faults;
mod frames_results;
mod lightbus_terminal;
#[cfg(feature = "cli")]
mod limits;
#[cfg(feature = "sim")]
mod lost_cycles;
mod machine_files;
#[cfg(feature = "cli")]
mod measure_old_params;
mod measure_sources;
#[cfg(feature = "cli")]
mod measure_timestamp_terminal;
#[cfg(feature = "cli")]
mod measure_without_drive_latch;
mod measurement_accuracy;
#[cfg(feature = "cli")]
mod measurement_cli;
mod measurement_drive_objects;
mod measurement_dynamics;
mod measurement_faults;
#[cfg(feature = "cli")]
mod measurement_frames;
#[cfg(feature = "cli")]
mod measurement_sources;
mod measurement_types;
mod modulo_axes;
#[cfg(feature = "sim")]
mod motion_property;
mod nc_parse;
mod params;
mod path_profile;
mod profidrive;
mod run_robustness;
#[cfg(feature = "canopen")]
mod sdo_bounds;
#[cfg(all(feature = "ethercat", feature = "sim"))]
mod sdo_info_golden;
mod sercos;
#[cfg(feature = "ethercat")]
mod sii;
mod sls_messages;
mod sls_property;
mod touch_probe;
#[cfg(feature = "cli")]
mod validation_gaps;
