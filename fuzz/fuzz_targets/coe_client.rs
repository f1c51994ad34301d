//! fieldprobe's own CoE (SDO over EtherCAT) client (`bus::ethercat::mailbox::CoeClient`, on
//! ethercrab's raw commands) fed hostile replies: an ethercrab MainDevice pumped in this thread
//! carries its frames to a scripted device ([`HostileMailbox`]) whose read mailbox holds what
//! the fuzz input says (SDO responses, aborts, emergencies, other protocols, lying lengths).
//! Must hold: no panic; every transfer ends (no more frames than the script can feed; a stall
//! is a failure); a result never holds more than the mailboxes read could carry.
#![no_main]
use fieldprobe::bus::ethercat::mailbox::CoeClient;
use fieldprobe_fuzz::ecat::{main_device, run, HostileMailbox};
use fieldprobe_fuzz::Bytes;
use libfuzzer_sys::fuzz_target;

const STATION: u16 = 0x1002;
const SIZES: [u16; 6] = [8, 16, 32, 128, 512, 1024];

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
        let index = b.u16();
        let sub = b.u8();
        let payload = b.take_len16(1500).to_vec();
        ops.push((op, index, sub, payload));
    }
    let script_len = b.len();
    let mut device = HostileMailbox::new(b, STATION, mbx_out, mbx_in);
    let mut client = CoeClient::new(STATION, mbx_out, mbx_in);
    let md = main_device();
    // Each mailbox round takes a handful of frames and consumes script bytes, except the
    // reply to an exhausted script, which ends the transfer.
    // A fragmented / segmented write costs frames per fragment, not script bytes.
    let payload_len: usize = ops.iter().map(|o| o.3.len()).sum();
    let max_frames = 64 + 16 * (script_len + payload_len);
    for (op, index, sub, payload) in &ops {
        let r = if op & 1 == 0 {
            run(client.sdo_upload(md, *index, *sub), &mut device, max_frames)
                .map(|r| r.map(|d| d.len()))
        } else {
            run(
                client.sdo_download(md, *index, *sub, payload),
                &mut device,
                max_frames,
            )
            .map(|r| r.map(|()| 0))
        };
        match r {
            Err(why) => panic!("CoE client did not finish: {why}"),
            Ok(Ok(n)) => assert!(
                n <= max_frames * 1024,
                "{n} bytes from at most {max_frames} mailbox reads"
            ),
            Ok(Err(_)) => {}
        }
        let _ = client.take_emergencies();
    }
});
