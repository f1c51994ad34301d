//! Parameters of the seeds (P-AXIS-*, P-CHAN-*, P-MANU-*): registry, ISG parameter-list text and
//! the machine file.
//!
//! * The registry ([`registry()`], [`find`]): every parameter the seeds name, with the ISG name
//!   path, type, default, data range and dimension, from FCT-A2 §4 (software limit switches), FCT-C4 §8.2
//!   (measurement) and FCT-C14 §6.2 (workspace monitoring); parameters the seeds only mention
//!   (e.g. P-AXIS-00003 `getriebe[i].dynamik.a_emergency`, used by FCT-A2 §4.3 for the
//!   stop-distance check) come from the ISG online parameter documentation. [`ParamSet`] holds
//!   the values of one list; ranges that name another parameter are checked by
//!   [`ParamSet::check_cross`]. Constants for every ID are in [`id`].
//! * [`apply_list`] / [`parse_list`]: ISG list text, `kenngr.measure.signal PLC` (the
//!   parameterisation examples of FCT-C4 §3 and §6).
//! * [`MachineConfig`]: the machine TOML file and the `--set KEY=VALUE` overrides.
//!
//! Values stay in the seeds' units (0.1 µm, 0.0001°, µm/s, mm/s²); conversions live in
//! `crate::units`. Every error names file, line and key ([`ParamError`]).

mod listfile;
mod machine;
mod registry;

pub use listfile::{apply_list, parse_list};
pub use machine::{
    AxisConfig, MachineConfig, TerminalConfig, TerminalProbeWiring, ToolData,
    DEFAULT_CYCLE_TIME_US, DEFAULT_DRIVE, DEFAULT_IN_POSITION_TIMEOUT_MS,
    DEFAULT_IN_POSITION_WINDOW, DEFAULT_MAX_LOST_CYCLES, MAX_CYCLE_TIME_US, MAX_DEAD_TIME_CYCLES,
    MAX_PROBE_CHANNEL, MAX_TERMINALS, MIN_CYCLE_TIME_US,
};
pub use registry::*;
