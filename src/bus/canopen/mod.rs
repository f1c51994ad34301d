//! CANopen (CiA 301) master and node building blocks, sans-IO: SDO client and server
//! ([`sdo`]), NMT / heartbeat / SYNC / EMCY ([`nmt`]), PDO packing and remapping ([`pdo`]),
//! EDS / DCF files ([`eds`]).

pub mod eds;
pub mod nmt;
pub mod pdo;
pub mod sdo;

use crate::bus::can::CanFrame;

/// One line of CANopen meaning for a frame of the predefined connection set (for `can dump`).
pub fn describe(f: &CanFrame) -> String {
    if f.error {
        return format!("error frame (class {:#x})", f.id);
    }
    if f.extended {
        return "extended frame (not CANopen)".into();
    }
    let id = f.id as u16;
    let d = f.payload();
    let node = id & 0x7F;
    let sdo = |dir: &str| -> String {
        let Some(&cmd) = d.first() else {
            return format!("SDO {dir} node {node}: empty");
        };
        let mux = if d.len() >= 4 {
            format!(" {:#06x}:{:02x}", u16::from_le_bytes([d[1], d[2]]), d[3])
        } else {
            String::new()
        };
        let what = match cmd >> 5 {
            0 => "segment",
            1 => "download initiate",
            2 => "upload initiate",
            3 => "upload segment / download response",
            4 => "abort",
            5 => "block upload",
            6 => "block download",
            _ => "?",
        };
        if cmd >> 5 == 4 && d.len() >= 8 {
            let code = u32::from_le_bytes([d[4], d[5], d[6], d[7]]);
            return format!(
                "SDO {dir} node {node}: abort{mux} {code:#010x} ({})",
                crate::bus::abort::abort_text(code)
            );
        }
        format!("SDO {dir} node {node}: {what}{mux}")
    };
    match id {
        0x000 => match (
            d.first().copied().and_then(nmt::NmtCommand::from_code),
            d.get(1),
        ) {
            (Some(c), Some(&n)) => format!(
                "NMT {c:?} {}",
                if n == 0 {
                    "all nodes".to_string()
                } else {
                    format!("node {n}")
                }
            ),
            _ => "NMT (malformed)".into(),
        },
        0x080 => "SYNC".into(),
        0x081..=0x0FF => match nmt::Emcy::parse(f) {
            Some(e) => format!(
                "EMCY node {}: {:#06x} {} (register {:#04x})",
                e.node,
                e.code,
                e.text(),
                e.register
            ),
            None => format!("EMCY node {node} (malformed)"),
        },
        0x181..=0x57F => {
            // TPDO k: 0x180 + 0x100 (k − 1) + node; RPDO k: 0x200 + 0x100 (k − 1) + node.
            if id & 0x80 != 0 {
                format!("TPDO{} node {node}", (id - 0x180) / 0x100 + 1)
            } else {
                format!("RPDO{} node {node}", (id - 0x200) / 0x100 + 1)
            }
        }
        0x581..=0x5FF => sdo("response"),
        0x601..=0x67F => sdo("request"),
        0x701..=0x77F => match nmt::parse_heartbeat(f) {
            Some((n, nmt::NmtState::BootUp)) => format!("boot-up node {n}"),
            Some((n, s)) => format!("heartbeat node {n}: {}", s.name()),
            None => format!("NMT error control node {node} (malformed)"),
        },
        _ => String::new(),
    }
}
