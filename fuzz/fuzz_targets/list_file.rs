//! Parameter list files (`.lis`, `params::listfile`) on arbitrary text, in every scope, and
//! applied on top of a parsed list. Must hold: no panic; parsing is deterministic.
#![no_main]
use fieldprobe::params::Scope;
use fieldprobe::params::{apply_list, parse_list};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for scope in [Scope::Axis, Scope::Channel, Scope::Manual] {
        let a = parse_list(text, "fuzz.lis", scope);
        let b = parse_list(text, "fuzz.lis", scope);
        assert_eq!(a.is_ok(), b.is_ok(), "parse not deterministic");
        if let Ok(mut set) = a {
            let _ = apply_list(&mut set, text, "fuzz.lis");
        }
    }
});
