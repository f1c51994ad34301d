//! The application (PDI side) behind an emulated ESC: mailbox server, process data, state hooks.

use super::types::{AlState, AlStatusCode};
use crate::drive::model::DriveModel;
use crate::sim::world::Port;

/// Process-data image sizes the application currently expects (bytes), checked against the
/// process-data sync managers on PRE-OP → SAFE-OP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProcessDataSizes {
    /// Output (RxPDO, master → device) bytes; 0 = no output SM expected.
    pub outputs: u16,
    /// Input (TxPDO, device → master) bytes; 0 = no input SM expected.
    pub inputs: u16,
}

/// The firmware/application behind the PDI of an emulated ESC.
///
/// All hooks are called synchronously from [`super::Esc::process`]; the emulated PDI is
/// infinitely fast (a written mailbox is consumed in the same datagram).
pub trait EscApplication: Send {
    /// A complete mailbox message arrived in the write mailbox (SM0, full length incl. padding).
    /// Return the reply to place into the read mailbox (SM1), if any.
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        let _ = data;
        None
    }

    /// Device-initiated mailbox messages waiting to be sent (further fragments of a reply,
    /// emergencies); the ESC queues them for the read mailbox after every mailbox write and
    /// after a segment step.
    fn take_outgoing(&mut self) -> Vec<Vec<u8>> {
        Vec::new()
    }

    /// The master completed writing output SM `sm` (only called in OP).
    fn outputs_written(&mut self, sm: u8, data: &[u8]) {
        let _ = (sm, data);
    }

    /// The outputs are no longer valid: the device left OP (the master asked for a lower state,
    /// or the sync-manager watchdog expired). Put what the application acts on into its safe
    /// state; [`Self::outputs_written`] brings new outputs in OP again.
    fn outputs_invalid(&mut self) {}

    /// The device entered INIT: the mailbox sync managers are off and the mailbox session
    /// ends. Forget the master's last request counter (a master starts again at counter 1
    /// after INIT, ETG.1000.4 §5.6 mailbox repeat rule), transfers in
    /// progress and queued device-initiated messages.
    fn mailbox_reset(&mut self) {}

    /// The master is about to read input SM `sm` (SAFE-OP and OP): fill `buf`.
    fn inputs(&mut self, sm: u8, buf: &mut [u8]) {
        let _ = (sm, buf);
    }

    /// Process-data sizes the current PDO mapping needs.
    fn process_data_sizes(&self) -> ProcessDataSizes {
        ProcessDataSizes::default()
    }

    /// The drive model behind the process data, if the application hosts one.
    fn model(&self) -> Option<&dyn DriveModel> {
        None
    }

    /// The drive model, mutable.
    fn model_mut(&mut self) -> Option<&mut dyn DriveModel> {
        None
    }

    /// The CoE server answering the mailbox, if the application has one (its dictionary and
    /// SDO information; fault knobs such as [`super::sdo_info::OdDescriptions::set_fault`]).
    fn coe_mut(&mut self) -> Option<&mut super::coe::CoeServer> {
        None
    }

    /// The model with its process images (model layout) for one synchronous step of the
    /// segment's [`World`](crate::sim::world::World) (SYNC0). `None` if there is no model.
    fn port(&mut self) -> Option<Port<'_>> {
        None
    }

    /// `true`: the model is stepped by the segment at SYNC0 ([`Self::port`]) and reads of the
    /// input SM return the image of the last step. `false` (default): the application steps its
    /// model itself when the inputs are read (free-running, no plant).
    fn set_synchronized(&mut self, on: bool) {
        let _ = on;
    }

    /// A state transition passed the ESC checks; the application may refuse it with an AL
    /// status code (the ESC then stays in `from` with the error bit set).
    fn state_change(&mut self, from: AlState, to: AlState) -> Result<(), AlStatusCode> {
        let _ = (from, to);
        Ok(())
    }
}

/// Application that does nothing (no mailbox replies, no process data).
#[derive(Debug, Default, Clone)]
pub struct NullApp;

impl EscApplication for NullApp {}

/// Tiny test application: echoes every mailbox message back (with the mailbox header's
/// counter kept), keeps the last outputs and returns `inputs` (or the last outputs, inverted,
/// if `loopback` is set) as inputs.
#[derive(Debug, Default, Clone)]
pub struct EchoApp {
    /// Expected process-data sizes.
    pub sizes: ProcessDataSizes,
    /// Last outputs written by the master.
    pub outputs: Vec<u8>,
    /// Inputs returned to the master.
    pub inputs: Vec<u8>,
    /// Number of mailbox messages received.
    pub mailbox_count: usize,
    /// Return the bitwise-inverted outputs as inputs.
    pub loopback: bool,
}

impl EchoApp {
    /// Echo application with the given process-data sizes.
    pub fn new(outputs: u16, inputs: u16) -> Self {
        Self {
            sizes: ProcessDataSizes { outputs, inputs },
            outputs: vec![0; usize::from(outputs)],
            inputs: vec![0; usize::from(inputs)],
            ..Self::default()
        }
    }
}

impl EscApplication for EchoApp {
    fn mailbox_received(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        self.mailbox_count += 1;
        Some(data.to_vec())
    }

    fn outputs_written(&mut self, _sm: u8, data: &[u8]) {
        self.outputs.clear();
        self.outputs.extend_from_slice(data);
    }

    fn inputs(&mut self, _sm: u8, buf: &mut [u8]) {
        if self.loopback {
            for (b, o) in buf.iter_mut().zip(self.outputs.iter()) {
                *b = !*o;
            }
        } else {
            let n = buf.len().min(self.inputs.len());
            buf[..n].copy_from_slice(&self.inputs[..n]);
        }
    }

    fn process_data_sizes(&self) -> ProcessDataSizes {
        self.sizes
    }
}
