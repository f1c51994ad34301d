//! Drive definition files (`drives/*.toml`, `drive::catalogue::parse`) on arbitrary text; a
//! parsed definition's scaled functions and IDN mappings are exercised with extreme values.
//! Must hold: no panic; a value that encodes decodes to a finite number.
#![no_main]
use fieldprobe::drive::catalogue;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(def) = catalogue::parse(text, "fuzz.toml") else {
        return;
    };
    for f in &def.functions {
        for v in [
            0.0,
            1.0,
            -1.0,
            1e300,
            -1e300,
            f64::NAN,
            f64::INFINITY,
            f64::MIN_POSITIVE,
        ] {
            if let Some(raw) = f.encode(v) {
                let back = f.decode(raw);
                assert!(!back.is_nan(), "encode({v}) = {raw} decodes to NaN");
            }
        }
        for raw in [0, 1, -1, i64::MAX, i64::MIN] {
            let _ = f.decode(raw);
        }
    }
    for (idx, sub) in [(0x6040u16, 0u8), (0x60B8, 0), (0x1A00, 1), (0xFFFF, 0xFF)] {
        let _ = def.object_type(idx, sub);
    }
});
