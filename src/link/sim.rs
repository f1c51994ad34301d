//! In-memory link to drive models.
//!
//! [`SimLink`] stands in for a bus: each exchange hands every axis's output image to its
//! [`Ds402Model`] and lets the model write the input image, one model step per exchange with the
//! link's cycle time. The images are laid out as the drives' PDO mappings
//! ([`Ds402Model::rx_len`] / [`Ds402Model::tx_len`]).
//!
//! Fault knobs (in the spirit of smoltcp's `FaultInjector`): [`SimLink::lose_exchange_at`] makes
//! chosen exchanges come back as [`LinkError::Lost`] with the input images untouched and the
//! models not stepped, as a lost EtherCAT frame would.

use super::{Link, LinkError, ProcessImage};
use crate::drive::model::ds402::Ds402Model;
use crate::units::Nanos;
use std::collections::BTreeSet;

/// A link whose drives are [`Ds402Model`]s in memory (sans-IO; the caller supplies `now`).
#[derive(Debug, Clone)]
pub struct SimLink {
    models: Vec<Ds402Model>,
    cycle: Nanos,
    exchanges: u64,
    lose: BTreeSet<u64>,
}

impl SimLink {
    /// A link to `models` (image `i` belongs to model `i`) stepping them by `cycle` per exchange.
    pub fn new(models: Vec<Ds402Model>, cycle: Nanos) -> Self {
        SimLink {
            models,
            cycle,
            exchanges: 0,
            lose: BTreeSet::new(),
        }
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
    pub fn models(&self) -> &[Ds402Model] {
        &self.models
    }

    /// The drive models, mutable (plant and fault knobs).
    pub fn models_mut(&mut self) -> &mut [Ds402Model] {
        &mut self.models
    }

    /// Model `i`, if there is one.
    pub fn model_mut(&mut self, i: usize) -> Option<&mut Ds402Model> {
        self.models.get_mut(i)
    }

    /// Zeroed process images sized for every model, in order.
    pub fn images(&self) -> Vec<ProcessImage> {
        self.models
            .iter()
            .map(|m| ProcessImage::new(m.rx_len(), m.tx_len()))
            .collect()
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
        let dt = self.cycle.as_secs_f64();
        for (model, image) in self.models.iter_mut().zip(images.iter_mut()) {
            model.step(now, dt, &image.outputs, &mut image.inputs);
        }
        Ok(())
    }
}
