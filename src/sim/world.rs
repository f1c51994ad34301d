//! One process-data cycle of the simulated world: drive models, their process images and the
//! [`Plant`] around them.
//!
//! Every link that hosts drive models — the in-memory [`SimLink`](crate::link::sim::SimLink) and
//! the emulated EtherCAT segment (`sim::esc::segment::Segment`, where the
//! models sit behind ESCs and the step runs at SYNC0) — advances them with [`World::step`], so
//! a probe surface or a fixed stop behaves the same whichever bus carries the images.
//!
//! # One step at `now`
//!
//! The step covers the cycle `[now − cycle, now]`:
//!
//! 1. the plant's fixed stops are applied to the models when they changed, and every wired
//!    input gets its surface's level at the cycle start as a static level (no edge);
//! 2. every model runs [`DriveModel::begin_step`] with its output image (RxPDO);
//! 3. the plant finds the probe-surface edges inside the cycle from the models' trajectories
//!    ([`Plant::advance`]); every edge goes to every wired `(device, input)` with
//!    [`DriveModel::input_edge`], in time order;
//! 4. every model runs [`DriveModel::finish_step`] into its input image (TxPDO).
//!
//! Devices are numbered by their position in the `ports` slice (the axis order of the machine),
//! which is the numbering of [`ProbeSurface::device`](crate::sim::plant::ProbeSurface) and
//! [`FixedStop::device`](crate::sim::plant::FixedStop).

use crate::drive::model::DriveModel;
use crate::sim::plant::Plant;
use crate::units::Nanos;

/// One device's share of a step: its model and its process images.
pub struct Port<'a> {
    /// The drive model.
    pub model: &'a mut dyn DriveModel,
    /// Output image (master → drive), in the model's layout.
    pub outputs: &'a [u8],
    /// Input image (drive → master), in the model's layout; written by the step.
    pub inputs: &'a mut [u8],
}

/// The ports of one world step, kept between steps so that a step allocates nothing: the ports
/// borrow the models only for the step; between steps the buffer is empty and keeps its
/// allocation (`Vec`'s in-place `collect` moves it from one lifetime to the other).
#[derive(Debug, Default)]
pub struct PortBuffer(Vec<Port<'static>>);

impl PortBuffer {
    /// Fill the buffer with `ports`, run `f` on them, empty it again.
    // `filter_map(|_| None)` on the empty vector only changes the element's lifetime; std
    // collects it in place, keeping the allocation (`tests/ethercat_alloc.rs` counts none).
    #[allow(clippy::unnecessary_filter_map)]
    pub fn with<'a, R>(
        &mut self,
        ports: impl Iterator<Item = Port<'a>>,
        f: impl FnOnce(&mut [Port<'a>]) -> R,
    ) -> R {
        let mut v: Vec<Port<'a>> = std::mem::take(&mut self.0)
            .into_iter()
            .filter_map(|_| None)
            .collect();
        v.extend(ports);
        let r = f(&mut v);
        v.clear();
        self.0 = v.into_iter().filter_map(|_| None).collect();
        r
    }
}

impl std::fmt::Debug for Port<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Port")
            .field("outputs", &self.outputs.len())
            .field("inputs", &self.inputs.len())
            .finish_non_exhaustive()
    }
}

/// The plant plus what the world remembers between steps.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct World {
    plant: Plant,
    /// Wall the plant last put into each model (so direct model knobs are not overridden every
    /// cycle).
    applied_stops: Vec<Option<f64>>,
}

impl World {
    /// A world around `plant`.
    pub fn new(plant: Plant) -> Self {
        World {
            plant,
            applied_stops: Vec::new(),
        }
    }

    /// The plant.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The plant, mutable; changed fixed stops reach the models at the next step.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.plant
    }

    /// Put each device's plant wall into its model when it differs from what the plant put
    /// there last.
    /// `devices` is the number of devices; `set(device, wall)` puts a wall into a model.
    pub fn apply_fixed_stops(&mut self, devices: usize, mut set: impl FnMut(usize, Option<f64>)) {
        self.applied_stops
            .resize(devices.max(self.applied_stops.len()), None);
        for device in 0..devices {
            let wanted = self.plant.fixed_stop_for(device);
            if self.applied_stops[device] != wanted {
                set(device, wanted);
                self.applied_stops[device] = wanted;
            }
        }
    }

    /// One cycle ending at `now` (see the module documentation).
    pub fn step(&mut self, now: Nanos, cycle: Nanos, ports: &mut [Port<'_>]) {
        let n = ports.len();
        self.apply_fixed_stops(n, |d, wall| ports[d].model.set_fixed_stop(wall));
        // Static level of every wired input = its surface's level at the start of the cycle.
        for (i, surface) in self.plant.probe_surfaces().iter().enumerate() {
            let level = self.plant.current_level(i);
            for &(device, input) in &surface.wired {
                if let Some(p) = ports.get_mut(device) {
                    if p.model.input_level(input) == Some(!level) {
                        p.model.set_input_level(input, level);
                    }
                }
            }
        }
        let dt = cycle.as_secs_f64();
        for p in ports.iter_mut() {
            p.model.begin_step(now, dt, p.outputs);
        }
        let start = Nanos(now.0.saturating_sub(cycle.0));
        {
            let view: &[Port<'_>] = ports;
            self.plant
                .advance(start, now, |d| view.get(d).map(|p| p.model.trajectory()));
        }
        for e in self.plant.last_edges() {
            if let Some(surface) = self.plant.probe_surfaces().get(e.probe) {
                for &(device, input) in &surface.wired {
                    if let Some(p) = ports.get_mut(device) {
                        p.model.input_edge(input, e.rising, e.at);
                    }
                }
            }
        }
        for p in ports.iter_mut() {
            p.model.finish_step(p.inputs);
        }
    }
}
