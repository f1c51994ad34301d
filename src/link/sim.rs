//! In-memory link to drive models.
//!
//! [`SimLink`] stands in for a bus: each exchange hands every axis's output image to its
//! [`DriveModel`] and lets the model write the input image, one model step per exchange with the
//! link's cycle time. The images are laid out as the drives' PDO mappings
//! ([`DriveModel::rx_len`] / [`DriveModel::tx_len`]).
//!
//! # One exchange at `now`
//!
//! One [`World::step`] over the cycle `[now − cycle, now]`: fixed stops and static input levels,
//! every model's `begin_step`, the plant's probe edges, every model's `finish_step` (see
//! [`crate::sim::world`]; the emulated EtherCAT segment runs the same step at SYNC0). The input
//! images the exchange returns are the ones the models wrote at the *previous* exchange: the
//! drives sample at SYNC0 and the values travel with the next frame, as on EtherCAT and with
//! CANopen synchronous PDOs. A set-point written after exchange k is thus reached at exchange
//! k + 1 and read back at exchange k + 2: the link's dead time is two cycles
//! ([`Link::dead_time_cycles`]).
//!
//! Acyclic access ([`Link::read_object`] / [`Link::write_object`]) goes straight to the model's
//! object dictionary, as an SDO / CoE mailbox transfer between two cycles would; refusals come
//! back as [`LinkError::Abort`] with the CiA 301 abort code.
//!
//! Fault knobs (in the spirit of smoltcp's `FaultInjector`): [`SimLink::lose_exchange_at`] makes
//! chosen exchanges come back as [`LinkError::Lost`] with the input images untouched and the
//! models and the plant not stepped, as a lost EtherCAT frame would.

use super::{Link, LinkError, ProcessImage};
use crate::drive::model::DriveModel;
use crate::sim::plant::Plant;
use crate::sim::world::{Port, World};
use crate::units::Nanos;
use std::collections::BTreeSet;

/// A link whose drives are [`DriveModel`]s in memory (sans-IO; the caller supplies `now`).
#[derive(Debug)]
pub struct SimLink {
    models: Vec<Box<dyn DriveModel>>,
    cycle: Nanos,
    exchanges: u64,
    lose: BTreeSet<u64>,
    world: World,
    /// Input images the models wrote at the last exchange: delivered with the next one.
    sampled: Vec<Vec<u8>>,
    /// The models' ports during a world step (kept: no allocation per exchange).
    ports: crate::sim::world::PortBuffer,
}

impl SimLink {
    /// A link to `models` (image `i` belongs to model `i`) stepping them by `cycle` per exchange,
    /// with an empty plant.
    pub fn new<M: DriveModel + 'static>(models: Vec<M>, cycle: Nanos) -> Self {
        SimLink::with_plant(models, cycle, Plant::new())
    }

    /// A link to drive models of any profile (boxed), with an empty plant.
    pub fn from_models(models: Vec<Box<dyn DriveModel>>, cycle: Nanos) -> Self {
        SimLink::boxed_with_plant(models, cycle, Plant::new())
    }

    /// A link to `models` with `plant` around them (probe surfaces, fixed stops). Fixed stops
    /// are applied to the models at once.
    pub fn with_plant<M: DriveModel + 'static>(models: Vec<M>, cycle: Nanos, plant: Plant) -> Self {
        let boxed = models
            .into_iter()
            .map(|m| Box::new(m) as Box<dyn DriveModel>)
            .collect();
        SimLink::boxed_with_plant(boxed, cycle, plant)
    }

    /// [`with_plant`](Self::with_plant) for boxed models of any profile.
    pub fn boxed_with_plant(models: Vec<Box<dyn DriveModel>>, cycle: Nanos, plant: Plant) -> Self {
        let mut link = SimLink {
            models,
            cycle,
            exchanges: 0,
            lose: BTreeSet::new(),
            world: World::new(plant),
            sampled: Vec::new(),
            ports: Default::default(),
        };
        let models = &mut link.models;
        link.world
            .apply_fixed_stops(models.len(), |d, wall| models[d].set_fixed_stop(wall));
        link
    }

    /// Lose the `n`-th exchange (0-based, counting every call that got the right number of
    /// images): it returns [`LinkError::Lost`], leaves the input images untouched and does not
    /// step the models. May be called for several `n`.
    pub fn lose_exchange_at(&mut self, n: u64) {
        self.lose.insert(n);
    }

    /// Exchanges attempted so far (including lost ones).
    pub fn exchanges(&self) -> u64 {
        self.exchanges
    }

    /// Cycle time each exchange advances the models by.
    pub fn cycle(&self) -> Nanos {
        self.cycle
    }

    /// The drive models, in image order.
    pub fn models(&self) -> &[Box<dyn DriveModel>] {
        &self.models
    }

    /// The drive models, mutable (plant and fault knobs).
    pub fn models_mut(&mut self) -> &mut [Box<dyn DriveModel>] {
        &mut self.models
    }

    /// Model `i`, if there is one.
    pub fn model_mut(&mut self, i: usize) -> Option<&mut (dyn DriveModel + 'static)> {
        self.models.get_mut(i).map(|m| m.as_mut())
    }

    /// Model `i` as its concrete type `T` (e.g. `Ds402Model`), if it is one.
    pub fn model_as<T: 'static>(&mut self, i: usize) -> Option<&mut T> {
        self.models.get_mut(i)?.as_any_mut().downcast_mut::<T>()
    }

    /// Model `i` as its concrete type `T`, shared.
    pub fn model_ref_as<T: 'static>(&self, i: usize) -> Option<&T> {
        self.models.get(i)?.as_any().downcast_ref::<T>()
    }

    /// The plant (probe surfaces, fixed stops, the last cycle's probe edges).
    pub fn plant(&self) -> &Plant {
        self.world.plant()
    }

    /// The plant, mutable; changed fixed stops reach the models at the next exchange.
    pub fn plant_mut(&mut self) -> &mut Plant {
        self.world.plant_mut()
    }

    /// Zeroed process images sized for every model, in order.
    pub fn images(&self) -> Vec<ProcessImage> {
        self.models
            .iter()
            .map(|m| ProcessImage::new(m.rx_len(), m.tx_len()))
            .collect()
    }

    fn device(&mut self, device: usize) -> Result<&mut Box<dyn DriveModel>, LinkError> {
        let n = self.models.len();
        self.models.get_mut(device).ok_or_else(|| {
            LinkError::Other(format!("device {device}: not on the link ({n} devices)"))
        })
    }
}

impl Link for SimLink {
    fn exchange(&mut self, now: Nanos, images: &mut [ProcessImage]) -> Result<(), LinkError> {
        if images.len() != self.models.len() {
            return Err(LinkError::Mismatch {
                devices: self.models.len(),
                images: images.len(),
            });
        }
        let n = self.exchanges;
        self.exchanges += 1;
        if self.lose.contains(&n) {
            tracing::debug!(target: "fieldprobe::link::sim", exchange = n, "exchange lost (injected)");
            return Err(LinkError::Lost {
                at: now,
                reason: format!("frame lost (injected at exchange {n})"),
            });
        }
        // The inputs of this exchange are what the models sampled at the previous one (the
        // end of their last step), as on a bus whose drives latch their actual values at SYNC0
        // and send them with the next frame.
        self.sampled.resize_with(images.len(), Vec::new);
        for (img, s) in images.iter_mut().zip(self.sampled.iter_mut()) {
            s.resize(img.inputs.len(), 0);
            std::mem::swap(&mut img.inputs, s);
        }
        let ports = self
            .models
            .iter_mut()
            .zip(images.iter())
            .zip(self.sampled.iter_mut())
            .map(|((m, img), s)| Port {
                model: m.as_mut(),
                outputs: &img.outputs,
                inputs: s.as_mut_slice(),
            });
        let (world, cycle) = (&mut self.world, self.cycle);
        self.ports.with(ports, |p| world.step(now, cycle, p));
        Ok(())
    }

    fn plant(&self) -> Option<&Plant> {
        Some(self.world.plant())
    }

    fn plant_mut(&mut self) -> Option<&mut Plant> {
        Some(self.world.plant_mut())
    }

    fn model(&self, device: usize) -> Option<&dyn DriveModel> {
        self.models.get(device).map(|m| m.as_ref())
    }

    fn model_mut(&mut self, device: usize) -> Option<&mut dyn DriveModel> {
        self.models
            .get_mut(device)
            .map(|m| m.as_mut() as &mut dyn DriveModel)
    }

    fn lose_exchange_at(&mut self, n: u64) {
        self.lose.insert(n);
    }

    fn exchanges(&self) -> u64 {
        self.exchanges
    }

    fn read_object(&mut self, device: usize, index: u16, sub: u8) -> Result<i64, LinkError> {
        self.device(device)?
            .read_object(index, sub)
            .map_err(|code| LinkError::Abort {
                device: super::Peer::Device(device),
                index,
                sub,
                code,
            })
    }

    fn write_object(
        &mut self,
        device: usize,
        index: u16,
        sub: u8,
        value: i64,
    ) -> Result<(), LinkError> {
        self.device(device)?
            .write_object(index, sub, value)
            .map_err(|code| LinkError::Abort {
                device: super::Peer::Device(device),
                index,
                sub,
                code,
            })
    }
}
