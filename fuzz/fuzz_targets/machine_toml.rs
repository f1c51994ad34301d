//! Machine file (`MachineConfig::parse`, TOML) on arbitrary text; a parsed machine is also
//! asked for its node IDs and axis list, and `--set` assignments are applied to it.
//! Must hold: no panic.
#![no_main]
use fieldprobe::params::MachineConfig;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    // Last line as a `--set` assignment too (also applied to the default machine).
    let set = text.lines().last().unwrap_or("");
    let mut d = MachineConfig::default_machine();
    let _ = d.apply_set(set);
    if let Ok(mut cfg) = MachineConfig::parse(text, "fuzz.toml") {
        let _ = cfg.node_ids();
        let _ = cfg.axis_list();
        let _ = cfg.apply_set(set);
    }
});
