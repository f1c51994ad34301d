//! Capture reader (`bus::ethercat::pcap::CaptureReader`, classic pcap and pcapng) on arbitrary
//! bytes. Every record read is written again with `PcapWriter` and read back.
//! Must hold: no panic; the reader ends (at most one record per 4 input bytes plus one error);
//! a record's data lie inside the input; write → read keeps data and timestamps.
#![no_main]
use fieldprobe::bus::ethercat::pcap::{CaptureReader, PcapWriter, TimestampResolution};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(reader) = CaptureReader::new(data) else {
        return;
    };
    let _ = reader.format();
    let mut records: Vec<(Option<u64>, Vec<u8>)> = Vec::new();
    let mut n = 0usize;
    for r in reader {
        n += 1;
        assert!(
            n <= data.len() / 4 + 2,
            "reader does not end: {n} items from {} bytes",
            data.len()
        );
        match r {
            Ok(rec) => {
                let range = data.as_ptr_range();
                let dr = rec.data.as_ptr_range();
                assert!(
                    rec.data.is_empty() || (range.start <= dr.start && dr.end <= range.end),
                    "record data outside the input"
                );
                records.push((rec.timestamp_ns, rec.data.to_vec()));
            }
            Err(_) => continue,
        }
    }
    let mut w = PcapWriter::new(Vec::new(), TimestampResolution::Nano).expect("pcap header");
    // The writer refuses seconds beyond 32 bits (classic pcap) and cuts at its snap length.
    records.retain(|(ts, _)| ts.unwrap_or(0) / 1_000_000_000 <= u64::from(u32::MAX));
    for (ts, d) in &mut records {
        w.write_packet(ts.unwrap_or(0), d).expect("write to memory");
        d.truncate(65_535);
    }
    let out = w.into_inner().expect("flush to memory");
    let back: Vec<_> = CaptureReader::new(&out)
        .expect("own pcap header")
        .map(|r| r.map(|r| (r.timestamp_ns, r.data.to_vec())))
        .collect::<Result<_, _>>()
        .expect("own pcap records");
    assert_eq!(
        back.len(),
        records.len(),
        "record count changed in write → read"
    );
    for ((t0, d0), (t1, d1)) in records.iter().zip(&back) {
        assert_eq!(d0, d1, "record data changed in write → read");
        assert_eq!(
            t0.unwrap_or(0),
            t1.unwrap_or(0),
            "timestamp changed in write → read"
        );
    }
});
