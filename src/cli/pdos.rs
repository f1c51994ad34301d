//! `fieldprobe pdos`: the PDO configuration read back from a device.
//!
//! ```text
//! fieldprobe pdos [--link LINK] (--device N | --node N)
//! ```
//! EtherCAT (`--device`), laid out like IgH's `ethercat pdos`: each sync manager from its
//! registers, then the PDOs assigned to it (0x1C12 / 0x1C13) and each PDO's mapping, with the
//! names the device gives over SDO Information:
//! ```text
//! SM2: PhysAddr 0x1100, DefaultSize 9, ControlRegister 0x64, Enable 1
//!   RxPDO 0x1600 "RxPDO 1 mapping"
//!     PDO entry 0x6040:00, 16 bit, "Controlword"
//! ```
//! CANopen (`--node`): RPDOs (0x1400–0x15FF communication, 0x1600–0x17FF mapping) and TPDOs
//! (0x1800–0x19FF, 0x1A00–0x1BFF) read by SDO: COB-ID, valid bit, transmission type, inhibit
//! time / event timer where present, and the mapped entries. Exit 0; 1 when the device refuses
//! an access; 2 on bad input or a bus error.

use super::bus::refused;
use super::sdo::{target, SdoTo, Target};
use super::EXIT_OK;

/// Arguments of `fieldprobe pdos`.
#[derive(Debug, clap::Args)]
pub struct PdosArgs {
    #[command(flatten)]
    to: SdoTo,
}

/// `fieldprobe pdos`.
pub fn run(a: PdosArgs) -> anyhow::Result<i32> {
    let (bus, target) = target(&a.to, "pdos")?;
    match target {
        Target::Device(d) => {
            let mut s = bus.open()?;
            let res = s.pdo_configuration(d);
            super::finish_capture(s.finish_capture());
            let (sms, pdos) = match res {
                Ok(r) => r,
                Err(e) => return refused(e),
            };
            for sm in sms {
                outln!(
                    "SM{}: PhysAddr {:#06x}, DefaultSize {}, ControlRegister {:#04x}, Enable {}",
                    sm.index,
                    sm.start,
                    sm.length,
                    sm.control,
                    u8::from(sm.enable)
                );
                for p in pdos.iter().filter(|p| p.sm == sm.index) {
                    outln!(
                        "  {}xPDO {:#06x} \"{}\"",
                        if p.rx { "R" } else { "T" },
                        p.index,
                        p.name
                    );
                    for e in &p.entries {
                        outln!(
                            "    PDO entry {:#06x}:{:02x}, {} bit, \"{}\"",
                            e.index,
                            e.sub,
                            e.bits,
                            e.name
                        );
                    }
                }
            }
            Ok(EXIT_OK)
        }
        Target::Node(n) => super::canopen_od::pdos(&bus, n),
    }
}
