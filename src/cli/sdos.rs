//! `fieldprobe sdos`: list a device's object dictionary, laid out like IgH's `ethercat sdos`.
//!
//! ```text
//! fieldprobe sdos [--link LINK] (--device N | --node N) [--eds FILE.eds]
//! ```
//! EtherCAT (`--device`): the CoE SDO Information service (ETG.1000.6 §5.6.3) — Get OD List,
//! then each object's and entry's description:
//! ```text
//! SDO 0x6040, "Controlword"
//!   0x6040:00, rwrwrw, uint16, 16 bit, "Controlword"
//! ```
//! (access letters: read / write in PREOP, SAFEOP, OP). CANopen (`--node`, CiA 301 has no SDO
//! information service): the objects of the node's EDS (`--eds`, or the EDS of an emulated
//! node on `canopen-emu`), each checked by an SDO upload of sub-index 0, plus an SDO scan of
//! the CiA 301 communication area and the CiA 402 objects fieldprobe knows
//! ([`fieldprobe::bus::canopen::dictionary`]); every line says where it came from. Exit 0; 1
//! when the device refuses the service, or fails to describe some objects or entries (the
//! others are listed, each failure named on stderr); 2 on bad input or a bus error.

use super::bus::refused;
use super::sdo::{target, SdoTo, Target};
use super::EXIT_OK;
use fieldprobe::bus::ethercat::sdo_info::{access, data_type_name};

/// Arguments of `fieldprobe sdos`.
#[derive(Debug, clap::Args)]
pub struct SdosArgs {
    #[command(flatten)]
    to: SdoTo,
    /// CANopen: the node's EDS file, listed and checked against the node (default on
    /// canopen-emu: the emulated node's own dictionary).
    #[arg(long, value_name = "FILE.eds")]
    eds: Option<std::path::PathBuf>,
}

/// `fieldprobe sdos`.
pub fn run(a: SdosArgs) -> anyhow::Result<i32> {
    let (bus, target) = target(&a.to, "sdos")?;
    match target {
        Target::Device(d) => {
            if let Some(p) = &a.eds {
                anyhow::bail!(
                    "--eds {}: an EDS describes a CANopen node (--node); an EtherCAT SubDevice describes itself over SDO Information",
                    p.display()
                );
            }
            let mut s = bus.open()?;
            let res = s.sdo_dictionary(d);
            super::finish_capture(s.finish_capture());
            let dictionary = match res {
                Ok(o) => o,
                Err(e) => return refused(e),
            };
            for o in dictionary.objects {
                outln!("SDO {:#06x}, \"{}\"", o.object.index, o.object.name);
                for e in o.entries {
                    outln!(
                        "  {:#06x}:{:02x}, {}, {}, {} bit, \"{}\"",
                        e.index,
                        e.sub,
                        access::letters(e.access),
                        data_type_name(e.data_type),
                        e.bit_len,
                        e.name
                    );
                }
            }
            // One object or entry the device did not describe does not end the listing; each
            // is named, and the exit code says the listing is incomplete.
            for f in &dictionary.failed {
                let what = match f.sub {
                    None => format!("object {:#06x}", f.index),
                    Some(sub) => format!("entry {:#06x}:{sub:02x}", f.index),
                };
                eprintln!(
                    "fieldprobe: sdos --device {d}: {what} not described ({}); the other objects are listed",
                    f.error
                );
            }
            Ok(if dictionary.failed.is_empty() {
                EXIT_OK
            } else {
                super::EXIT_CNC_ERROR
            })
        }
        Target::Node(n) => super::canopen_od::sdos(&bus, n, a.eds.as_deref()),
    }
}
