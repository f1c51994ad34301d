//! NC program parser (`fieldprobe::nc::parser::parse`) on arbitrary text.
//! Must hold: no panic; parsing is deterministic; an error names a line inside the program.
#![no_main]
use fieldprobe::nc::parser;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(src) = std::str::from_utf8(data) else {
        return;
    };
    let first = parser::parse(src);
    let second = parser::parse(src);
    assert_eq!(
        format!("{first:?}"),
        format!("{second:?}"),
        "parse not deterministic"
    );
    if let Err(e) = first {
        let lines = src.split('\n').count() as u32;
        let span = e.span();
        assert!(
            span.line >= 1 && span.line <= lines.max(1),
            "error line {} outside the program's {} lines: {e:?}",
            span.line,
            lines
        );
    }
    let _ = parser::parse_expr(src);
});
