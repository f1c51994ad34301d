//! [`VendorDevice`] from an EDS (CiA 306): data types by their CiA 301 codes, PDO directions
//! from `PDOMapping=1` with `AccessType` (`rww` / `rw` / `wo` into an RPDO, `ro` / `const` /
//! `rwr` / `rw` into a TPDO), defaults and limits from `DefaultValue`, `LowLimit`, `HighLimit`.

use super::{VendorDevice, VendorObject, OBJECTS_READ};
use crate::bus::canopen::eds::Eds;
use crate::drive::pdo::DataType;

impl VendorDevice {
    /// The device of the EDS `eds` ([`OBJECTS_READ`] from its object sections).
    pub fn from_eds(eds: &Eds) -> VendorDevice {
        let node = eds.node_id().unwrap_or(0);
        let mut objects = Vec::new();
        for &(index, sub) in OBJECTS_READ {
            let Some(e) = eds.get(index, sub) else {
                continue;
            };
            let ty = DataType::from_cia301_code(e.data_type.code());
            let bits = e.data_type.bit_len().map_or(0, u32::from);
            let access = e.access;
            let (rx, tx) = e.pdo_directions();
            objects.push(VendorObject {
                index,
                sub,
                plays: (index, sub),
                name: e.parameter_name.clone(),
                type_name: format!("{:?}", e.data_type).to_ascii_uppercase(),
                ty,
                bits,
                rx,
                tx,
                writable: access.writable(),
                default: e.default_value(node).and_then(|v| v.as_i64()),
                low: e.low_limit_value(node).and_then(|v| v.as_i64()),
                high: e.high_limit_value(node).and_then(|v| v.as_i64()),
            });
        }
        let id = eds.identity();
        let info = &eds.device_info;
        VendorDevice {
            file: eds.file.clone(),
            kind: "EDS",
            vendor: info.vendor_name.clone().unwrap_or_default(),
            vendor_id: id.vendor_id,
            product: info.product_name.clone().unwrap_or_default(),
            product_code: id.product_code,
            revision: id.revision_number,
            objects,
            plan: None,
            plan_error: None,
            reference: None,
        }
    }
}

impl super::PdoCapacity {
    /// The PDOs the EDS `eds` gives its device (CiA 306 / CiA 301): RPDO k + 1 / TPDO k + 1
    /// for each communication parameter 0x1400 + k / 0x1800 + k of the file (k < 4, the
    /// predefined connection set fieldprobe's master uses), with as many entries as its
    /// mapping parameter 0x1600 + k / 0x1A00 + k has sub-indices ≥ 1 (at most 8 counted).
    /// `[DeviceInfo] NrOfRXPDO` / `NrOfTXPDO` are not used: the objects are what a node has.
    pub fn from_eds(eds: &Eds) -> super::PdoCapacity {
        let side = |comm: u16, map: u16| -> Vec<u8> {
            (0..4u16)
                .filter(|k| eds.subs(comm + k).next().is_some())
                .map(|k| {
                    let n = eds.subs(map + k).filter(|e| e.sub >= 1).count();
                    u8::try_from(n.min(8)).unwrap_or(8)
                })
                .collect()
        };
        super::PdoCapacity {
            rx: side(0x1400, 0x1600),
            tx: side(0x1800, 0x1A00),
        }
    }
}
