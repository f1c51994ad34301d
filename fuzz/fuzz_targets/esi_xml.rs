//! ESI XML (`fieldprobe::esi::parse_bytes`) on arbitrary bytes. Every device of a parsed file
//! is resolved with its default modules (`Device::resolve`) and selected by position, type name
//! and product code / revision (`esi::resolve`), and the SII the emulator would program is
//! built from the resolved device; when it encodes, it must decode again to the same content
//! (what we write we can read). Every warning formats.
//! Must hold: no panic; SII encode → decode round trip.
#![no_main]
use fieldprobe::esi::{self, sii, to_sii::sii_from_device, Selector};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(file) = esi::parse_bytes(data, "fuzz.xml") else {
        return;
    };
    for w in &file.warnings {
        let _ = w.to_string();
    }
    for (i, dev) in file.devices.iter().enumerate() {
        for sel in [
            format!("@{}", i + 1),
            dev.type_name.clone(),
            format!("{:#x}/{:#x}", dev.product_code, dev.revision_no),
        ] {
            if let Ok(sel) = sel.parse::<Selector>() {
                let _ = esi::resolve(&file, Some(&sel));
            }
        }
        let _ = (dev.is_cia402(), dev.is_mdp_servo(), dev.device_type());
        let Ok(dev) = dev.resolve(&[]) else {
            continue;
        };
        let Ok(content) = sii_from_device(&file, &dev) else {
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
