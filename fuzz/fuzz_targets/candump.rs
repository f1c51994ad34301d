//! candump log lines (`bus::can::candump::parse_line` / `parse_frame`) on arbitrary text.
//! Must hold: no panic; a parsed line formats (`format_line`) to a line that parses to the
//! same record (timestamp cut to the format's microseconds); a parsed frame is a valid classic CAN frame.
#![no_main]
use fieldprobe::bus::can::candump::{format_frame, format_line, parse_frame, parse_line};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    for line in text.lines() {
        if let Ok(rec) = parse_line(line) {
            rec.frame
                .validate()
                .unwrap_or_else(|e| panic!("{line:?} parsed to an invalid frame: {e}"));
            let out = format_line(rec.timestamp, &rec.interface, &rec.frame);
            let again = parse_line(&out).unwrap_or_else(|e| {
                panic!("formatted line {out:?} (from {line:?}) does not parse: {e}")
            });
            // The log format holds microseconds; the parser also reads finer fractions.
            let mut want = rec.clone();
            want.timestamp = std::time::Duration::new(
                rec.timestamp.as_secs(),
                rec.timestamp.subsec_micros() * 1000,
            );
            assert_eq!(again, want, "{line:?} → {out:?} changed the record");
        }
        if let Ok(frame) = parse_frame(line) {
            frame
                .validate()
                .unwrap_or_else(|e| panic!("{line:?} parsed to an invalid frame: {e}"));
            let out = format_frame(&frame);
            let again = parse_frame(&out)
                .unwrap_or_else(|e| panic!("formatted frame {out:?} does not parse: {e}"));
            assert_eq!(again, frame, "{line:?} → {out:?} changed the frame");
        }
    }
});
