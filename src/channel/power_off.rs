//! The end of a run: the drives are disabled through their adapters (CiA 402 §6.3 controlword
//! "shutdown" 0x0006, transition 8 from OPERATION ENABLED to READY TO SWITCH ON, the power stage
//! off with the drive's 0x605B shutdown option code; the other families' adapters write their
//! own "off": SERCOS drive control word without drive on / enable, PROFIdrive STW1 without ON,
//! i.e. OFF1).

use super::Channel;
use crate::link::ProcessImage;
use crate::units::Nanos;

impl Channel {
    /// One cycle of the power-off at the end of a run, in place of [`Channel::cycle`]:
    /// `images` came from this cycle's exchange; every axis reads its inputs and writes
    /// "disable" (no fault reset) into its outputs, which go out with the next exchange; the
    /// set-points stay where they are. Returns the axes whose drive does not report its power
    /// stage off yet (as its family's profile defines it,
    /// [`crate::drive::DriveAdapter::power_stage_off`]; an axis whose inputs cannot be read counts as not
    /// off). An empty list: every drive is disabled.
    ///
    /// The channel does not interpolate meanwhile. A later [`Channel::program_start`] enables
    /// the drives again.
    pub fn power_off_cycle(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Vec<String> {
        let mut on = Vec::new();
        for (i, a) in self.axes.iter_mut().enumerate() {
            a.set_enable(false);
            a.set_fault_reset(false);
            let Some(img) = images.get_mut(i) else {
                on.push(a.name().to_string());
                continue;
            };
            let off = match a.read(now, &img.inputs) {
                Ok(fb) => {
                    let state = fb.state;
                    a.power_stage_off(state)
                }
                Err(_) => false,
            };
            if !off {
                on.push(a.name().to_string());
            }
            if a.write(now, &mut img.outputs).is_err() {
                // The command position does not fit the drive (it never moved there): the
                // actual position does.
                let actual = a.actual();
                a.set_command(actual);
                let _ = a.write(now, &mut img.outputs);
            }
        }
        on
    }
}
