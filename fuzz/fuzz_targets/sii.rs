//! SII EEPROM images (`esi::sii`): a file's bytes through `load_image` (binary, hex dump,
//! Intel HEX) and `decode_ignoring_checksum`. A decoded image re-encodes (when it encodes at
//! all) to an image that decodes to the same content.
//! Must hold: no panic; decode → encode → decode equal.
#![no_main]
use fieldprobe::esi::sii;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = sii::header_checksum(data);
    let Ok(image) = sii::load_image(data) else {
        return;
    };
    let _ = sii::decode(&image);
    let Ok(content) = sii::decode_ignoring_checksum(&image) else {
        return;
    };
    let _ = content.check_defined_bits();
    let _ = content.general();
    let _ = content.sync_managers();
    let _ = content.tx_pdos().count() + content.rx_pdos().count();
    let Ok(again) = sii::encode(&content) else {
        return;
    };
    let back =
        sii::decode(&again).unwrap_or_else(|e| panic!("re-encoded SII does not decode: {e}"));
    assert_eq!(
        back, content,
        "SII decode → encode → decode changed the content"
    );
});
