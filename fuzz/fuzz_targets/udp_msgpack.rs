//! python-can `udp_multicast` datagrams (`bus::can::udp_wire::decode`, msgpack) on arbitrary
//! bytes. Must hold: no panic; a decoded frame is valid and encodes to a datagram that decodes
//! to the same frame.
#![no_main]
use fieldprobe::bus::can::udp_wire;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(Some(frame)) = udp_wire::decode(data) else {
        return;
    };
    frame
        .validate()
        .unwrap_or_else(|e| panic!("decoded an invalid frame: {e}"));
    let mut out = Vec::new();
    udp_wire::encode(&frame, 1.5, &mut out).expect("a valid frame encodes");
    let back = udp_wire::decode(&out)
        .expect("own datagram decodes")
        .expect("own datagram is classic CAN");
    assert_eq!(back, frame, "decode → encode → decode changed the frame");
});
