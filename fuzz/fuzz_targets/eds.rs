//! CANopen EDS / DCF (`bus::canopen::eds::parse`) on arbitrary text (Latin-1 bytes become
//! chars, as `eds::load` reads them). A parsed file's values are encoded and decoded per
//! data type, and an emulated CANopen node is built from it (as `sim canopen --eds` does).
//! Must hold: no panic; a value that encodes decodes to the same value.
#![no_main]
use fieldprobe::bus::canopen::eds;
use fieldprobe::drive::catalogue;
use fieldprobe::sim::canopen::EmulatedNode;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text: String = match std::str::from_utf8(data) {
        Ok(s) => s.to_owned(),
        Err(_) => data.iter().map(|&b| char::from(b)).collect(),
    };
    let Ok(parsed) = eds::parse(&text, "fuzz.eds") else {
        return;
    };
    let _ = parsed.identity();
    let node_id = parsed.node_id().unwrap_or(1).clamp(1, 127);
    for index in parsed.object_lists.all().collect::<Vec<_>>() {
        for e in parsed.subs(index) {
            let _ = e.default_value(node_id);
            let _ = e.low_limit_value(node_id);
            let _ = e.high_limit_value(node_id);
            let _ = e.mapping_entry();
            if let Some(v) = e.value(node_id) {
                let ty = e.data_type;
                if let Ok(bytes) = ty.encode(&v) {
                    let back = ty.decode(&bytes).unwrap_or_else(|err| {
                        panic!("{ty:?} {v:?} encoded to {bytes:?} does not decode: {err}")
                    });
                    // Debug form: a NaN REAL reads back as NaN.
                    assert_eq!(
                        format!("{back:?}"),
                        format!("{v:?}"),
                        "{ty:?} value changed in encode → decode"
                    );
                }
            }
        }
    }
    if let Some(def) = catalogue::builtin("cia402-generic") {
        let _ = EmulatedNode::from_eds(node_id, &def, &parsed);
    }
});
