//! fieldprobe's own SoE (SERCOS over EtherCAT) client (`bus::ethercat::soe::SoeClient`) fed
//! hostile replies through the same scripted device as `coe_client`: read / write of IDN
//! elements, names, attributes and values, with fragmented replies, error replies,
//! emergencies and mailbox types it did not ask for.
//! Must hold: no panic; every request ends (no stall, no more frames than the script feeds).
#![no_main]
use fieldprobe::bus::ethercat::soe::{Element, SoeClient};
use fieldprobe_fuzz::ecat::{main_device, run, HostileMailbox};
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

const STATION: u16 = 0x1003;
const SIZES: [u16; 6] = [8, 16, 32, 128, 512, 1024];
const ELEMENTS: [Element; 8] = [
    Element::DataState,
    Element::Name,
    Element::Attribute,
    Element::Unit,
    Element::Minimum,
    Element::Maximum,
    Element::Value,
    Element::Default,
];

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes::new(data);
    let cfg = b.u8();
    let out_len = SIZES[usize::from(cfg & 7) % SIZES.len()];
    let in_len = SIZES[usize::from((cfg >> 3) & 7) % SIZES.len()];
    let mbx_out = (0x1000, out_len);
    let mbx_in = (0x1400, in_len);
    let mut ops = Vec::new();
    for _ in 0..1 + (b.u8() % 4) {
        let op = b.u8();
        let drive_no = b.u8() & 7;
        let idn = b.u16();
        let value = i64::from(b.u32() as i32);
        let payload = b.take_len16(1500).to_vec();
        ops.push((op, drive_no, idn, value, payload));
    }
    let script_len = b.len();
    let mut device = HostileMailbox::new(b, STATION, mbx_out, mbx_in);
    let mut client = SoeClient::new(STATION, mbx_out, mbx_in);
    let md = main_device();
    // A fragmented / segmented write costs frames per fragment, not script bytes.
    let payload_len: usize = ops.iter().map(|o| o.4.len()).sum();
    let max_frames = 64 + 16 * (script_len + payload_len);
    for (op, drive_no, idn, value, payload) in &ops {
        let (d, i) = (*drive_no, *idn);
        let r = match op % 6 {
            0 => run(
                client.read_idn(md, d, i, ELEMENTS[usize::from(op >> 3) % 8]),
                &mut device,
                max_frames,
            )
            .map(|r| r.map(|v| v.len())),
            1 => run(client.write_idn(md, d, i, payload), &mut device, max_frames)
                .map(|r| r.map(|()| 0)),
            2 => {
                run(client.read_name(md, d, i), &mut device, max_frames).map(|r| r.map(|s| s.len()))
            }
            3 => {
                run(client.read_attribute(md, d, i), &mut device, max_frames).map(|r| r.map(|_| 0))
            }
            4 => run(client.read_value(md, d, i), &mut device, max_frames).map(|r| r.map(|_| 0)),
            _ => run(
                client.write_value(md, d, i, *value),
                &mut device,
                max_frames,
            )
            .map(|r| r.map(|()| 0)),
        };
        match r {
            Err(why) => panic!("SoE client did not finish: {why}"),
            Ok(Ok(n)) => assert!(
                n <= max_frames * 1024,
                "{n} bytes from at most {max_frames} mailbox reads"
            ),
            Ok(Err(_)) => {}
        }
        let _ = client.take_emergencies();
    }
});
