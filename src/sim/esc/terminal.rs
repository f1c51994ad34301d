//! Emulated I/O terminals: a SubDevice built from its ESI device that is not a drive.
//!
//! [`emulated_terminal`] picks the application by what the device is:
//! * an EL1252-kind timestamp input (ESI type name contains `EL1252`):
//!   [`emulated_el1252`], two channels, continuous latching, the
//!   default DC clock; it hosts a model, so a segment with a world steps it at SYNC0;
//! * a device without process data (a coupler): no application;
//! * any other device with process data: [`EchoApp`] in loopback (its inputs are its outputs,
//!   bit-inverted), sized by the PDOs the ESI assigns to its sync managers by default.
//!
//! `fieldprobe sim ethercat` and the in-process link (`ethercat-emu`) build terminals alike.

use super::device::{emulated_el1252, ServoError};
use super::{EchoApp, Esc, EscApplication, EscConfig, NullApp};
use crate::esi::{sii, to_sii, Device, EsiFile, Pdo, SmKind};

/// What an emulated terminal plays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TerminalKind {
    /// EL1252-kind timestamp input (hosts a model).
    Timestamp,
    /// No process data (a coupler).
    Passive,
    /// Inputs = inverted outputs.
    Loopback,
}

/// Is the ESI device an EL1252-kind timestamp input (by its type name)?
pub fn is_el1252(device: &Device) -> bool {
    device.type_name.to_ascii_uppercase().contains("EL1252")
}

/// Process-data sizes (outputs, inputs) in bytes: the PDOs the ESI assigns by default to the
/// output and input sync managers.
pub fn default_pd_sizes(device: &Device) -> (u16, u16) {
    let bytes = |pdos: &[Pdo], kind: SmKind| -> u16 {
        let bits: u32 = pdos
            .iter()
            .filter(|p| {
                p.sm.and_then(|n| device.sync_managers.get(usize::from(n)))
                    .is_some_and(|sm| sm.kind == kind)
            })
            .map(|p| p.bit_len())
            .sum();
        u16::try_from(bits.div_ceil(8)).unwrap_or(u16::MAX)
    };
    (
        bytes(&device.rx_pdos, SmKind::Outputs),
        bytes(&device.tx_pdos, SmKind::Inputs),
    )
}

/// What [`emulated_terminal`] makes of `device`.
pub fn terminal_kind(device: &Device) -> TerminalKind {
    if is_el1252(device) {
        TerminalKind::Timestamp
    } else if default_pd_sizes(device) == (0, 0) {
        TerminalKind::Passive
    } else {
        TerminalKind::Loopback
    }
}

/// The emulated terminal of ESI `device` of `file` (module documentation).
pub fn emulated_terminal(file: &EsiFile, device: &Device) -> Result<Esc, ServoError> {
    if terminal_kind(device) == TerminalKind::Timestamp {
        return emulated_el1252(
            file,
            device,
            2,
            crate::drive::el1252::LatchMode::Continuous,
            crate::core::measure::timestamp::DcClock::default(),
        );
    }
    let content = to_sii::sii_from_device(file, device)?;
    let image = sii::encode_padded(&content)?;
    let app: Box<dyn EscApplication> = match default_pd_sizes(device) {
        (0, 0) => Box::new(NullApp),
        (o, i) => {
            let mut app = EchoApp::new(o, i);
            app.loopback = true;
            Box::new(app)
        }
    };
    Ok(Esc::new(EscConfig::from_sii(image), app))
}
