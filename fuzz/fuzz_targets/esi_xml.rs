//! ESI XML (`fieldprobe::esi::parse_bytes`) on arbitrary bytes. For every device of a parsed
//! file the SII the emulator would program is built; when it encodes, it must decode again to
//! the same content (what we write we can read).
//! Must hold: no panic; SII encode → decode round trip.
#![no_main]
use fieldprobe::esi::{self, sii, to_sii::sii_from_device};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(file) = esi::parse_bytes(data, "fuzz.xml") else {
        return;
    };
    for dev in &file.devices {
        let Ok(content) = sii_from_device(&file, dev) else {
            continue;
        };
        let Ok(image) = sii::encode(&content) else {
            continue;
        };
        let back = sii::decode(&image)
            .unwrap_or_else(|e| panic!("SII built from an ESI device does not decode: {e}"));
        assert_eq!(back, content, "SII round trip changed the content");
    }
});
