//! The plant: probe surfaces and fixed stops around the simulated drives.
//!
//! A [`Plant`] belongs to a [`SimLink`](crate::link::sim::SimLink), which consults it in every
//! exchange after the drive models advanced their position loops (`begin_step`) and before they
//! write their input images (`finish_step`):
//!
//! - a [`ProbeSurface`] switches whenever the actual position of its device crosses the
//!   surface's position, in either direction. The crossing time is exact: it is interpolated
//!   between the sub-samples of the device's trajectory (the same samples the drive model
//!   interpolates when it latches), so a drive latching its own axis stores the surface
//!   position. The electrical edges go to every `(device, input)` the surface is wired to, in
//!   time order, and are recorded ([`Plant::last_edges`], [`Plant::level`]).
//! - a [`FixedStop`] puts a rigid wall into a device's model
//!   ([`Ds402Model::set_fixed_stop`](crate::drive::model::ds402::Ds402Model::set_fixed_stop)).
//!
//! # Pulse per crossing
//!
//! A touch probe deflects while the axis moves through the surface and springs back; the plant
//! models this as **one pulse per crossing**: at the exact crossing time the signal goes to its
//! active level (high for `active_high`, else low) and `pulse` later (default 5 ms,
//! [`DEFAULT_PULSE`]) back to its rest level. A crossing while the pulse is still on extends it
//! (no new edge). Why not a persistent contact (active on one side of the surface)? In the seed's
//! `meas1` example (FCT-C4 §2) the axis first passes the trigger position upwards in a
//! non-measuring block and then crosses it again in the measuring block; with a persistent
//! contact the second, measuring crossing would be a *release* (the opposite edge) and a probe
//! armed for the positive edge would never latch. With one pulse per crossing every crossing
//! gives the armed edge at the crossing time, and the opposite edge `pulse` later.
//!
//! Before each cycle the link sets every wired input to its surface's level as a static level
//! (no edge), so an active-low probe rests high. One surface per input is the intended wiring;
//! with several, the last surface's level wins at the cycle start and edges are delivered as
//! they come (an edge to the level an input already has is ignored by the drive).
//!
//! Jumps of the position between two cycles (`set_actual`, a changed disturbance) are not
//! crossings: only motion inside a cycle's trajectory switches a surface.

use crate::units::Nanos;

/// Default pulse length of a probe surface (5 ms).
pub const DEFAULT_PULSE: Nanos = Nanos(5_000_000);

/// A switching probe surface (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct ProbeSurface {
    /// Device (drive on the link, image index) whose actual position trips the surface.
    pub device: usize,
    /// Surface position in increments of that device (actual position, 0x6064 units).
    pub position: f64,
    /// Digital inputs the probe signal is wired to: `(device, input 1..=4)`.
    pub wired: Vec<(usize, u8)>,
    /// The signal is high while the probe is deflected (else low while deflected).
    pub active_high: bool,
    /// How long the signal stays active after a crossing.
    pub pulse: Nanos,
}

impl ProbeSurface {
    /// A surface at `position` increments of `device`, wired to `wired`, active high, with the
    /// default pulse.
    pub fn new(device: usize, position: f64, wired: Vec<(usize, u8)>) -> Self {
        ProbeSurface {
            device,
            position,
            wired,
            active_high: true,
            pulse: DEFAULT_PULSE,
        }
    }
}

/// A mechanical stop at `position` increments of `device` (actual position).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FixedStop {
    /// Device (drive on the link).
    pub device: usize,
    /// Position of the wall in increments of that device.
    pub position: f64,
}

/// One edge of a probe surface's electrical signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ProbeEdgeEvent {
    /// Index of the surface in [`Plant::probe_surfaces`].
    pub probe: usize,
    /// The electrical level went high (else low).
    pub rising: bool,
    /// When.
    pub at: Nanos,
}

/// Switching state of one surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct SurfaceState {
    /// Deflected (signal at its active level).
    active: bool,
    /// When the pulse ends.
    release_at: Nanos,
    /// Deflected at the start of the last cycle.
    active_at_start: bool,
}

/// Probe surfaces and fixed stops (see the module documentation).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Plant {
    surfaces: Vec<ProbeSurface>,
    fixed_stops: Vec<FixedStop>,
    state: Vec<SurfaceState>,
    last_edges: Vec<ProbeEdgeEvent>,
    cycle_start: Nanos,
}

impl Plant {
    /// An empty plant.
    pub fn new() -> Self {
        Plant::default()
    }

    /// Add a probe surface; returns its index (the `probe` of [`ProbeEdgeEvent`]).
    pub fn add_probe_surface(&mut self, surface: ProbeSurface) -> usize {
        self.surfaces.push(surface);
        self.surfaces.len() - 1
    }

    /// Add a fixed stop. One wall per device: the first stop of a device counts.
    pub fn add_fixed_stop(&mut self, stop: FixedStop) {
        self.fixed_stops.push(stop);
    }

    /// The probe surfaces.
    pub fn probe_surfaces(&self) -> &[ProbeSurface] {
        &self.surfaces
    }

    /// The probe surfaces, mutable (move a surface, rewire it, change its pulse).
    pub fn probe_surfaces_mut(&mut self) -> &mut [ProbeSurface] {
        &mut self.surfaces
    }

    /// The fixed stops.
    pub fn fixed_stops(&self) -> &[FixedStop] {
        &self.fixed_stops
    }

    /// The fixed stops, mutable (add, move or remove; the link applies changes at the next
    /// exchange).
    pub fn fixed_stops_mut(&mut self) -> &mut Vec<FixedStop> {
        &mut self.fixed_stops
    }

    /// The wall for `device`: the position of its first fixed stop.
    pub fn fixed_stop_for(&self, device: usize) -> Option<f64> {
        self.fixed_stops
            .iter()
            .find(|s| s.device == device)
            .map(|s| s.position)
    }

    /// Edges of all surfaces in the last exchanged cycle, in time order.
    pub fn last_edges(&self) -> &[ProbeEdgeEvent] {
        &self.last_edges
    }

    /// Whether surface `probe` is deflected now (end of the last cycle).
    pub fn contact(&self, probe: usize) -> bool {
        self.state.get(probe).is_some_and(|s| s.active)
    }

    /// Electrical level of surface `probe` now (end of the last cycle): the active level while
    /// deflected, else the rest level. `false` for an unknown surface.
    pub fn current_level(&self, probe: usize) -> bool {
        self.surfaces
            .get(probe)
            .is_some_and(|s| self.contact(probe) == s.active_high)
    }

    /// Electrical level of surface `probe` at `at` (edges at `at` included). Known for the last
    /// cycle; earlier times read as the level at its start, later times as the level at its end.
    /// `false` for an unknown surface.
    pub fn level(&self, probe: usize, at: Nanos) -> bool {
        let Some(surface) = self.surfaces.get(probe) else {
            return false;
        };
        let start = self.state.get(probe).is_some_and(|s| s.active_at_start);
        let mut level = start == surface.active_high;
        for e in &self.last_edges {
            if e.probe == probe && e.at <= at {
                level = e.rising;
            }
        }
        level
    }

    /// Start of the last cycle.
    pub fn last_cycle_start(&self) -> Nanos {
        self.cycle_start
    }

    /// Advance the surfaces over the cycle `[start, end]`: find the crossings in the devices'
    /// trajectories (`trajectory(device)`) and the pulse ends, record them as
    /// [`last_edges`](Self::last_edges) and return them in time order.
    pub fn advance<'t>(
        &mut self,
        start: Nanos,
        end: Nanos,
        trajectory: impl Fn(usize) -> Option<&'t [(Nanos, f64)]>,
    ) -> &[ProbeEdgeEvent] {
        self.state
            .resize(self.surfaces.len(), SurfaceState::default());
        self.last_edges.clear();
        self.cycle_start = start;
        let mut crossings = Vec::new();
        for (i, surface) in self.surfaces.iter().enumerate() {
            let st = &mut self.state[i];
            st.active_at_start = st.active;
            crossings.clear();
            if let Some(traj) = trajectory(surface.device) {
                crossing_times(traj, surface.position, &mut crossings);
            }
            let level = |active: bool| active == surface.active_high;
            for &tc in &crossings {
                if st.active && st.release_at <= tc {
                    st.active = false;
                    self.last_edges.push(ProbeEdgeEvent {
                        probe: i,
                        rising: level(false),
                        at: st.release_at,
                    });
                }
                if !st.active {
                    st.active = true;
                    self.last_edges.push(ProbeEdgeEvent {
                        probe: i,
                        rising: level(true),
                        at: tc,
                    });
                }
                st.release_at = tc.saturating_add(surface.pulse);
            }
            if st.active && st.release_at <= end {
                st.active = false;
                self.last_edges.push(ProbeEdgeEvent {
                    probe: i,
                    rising: level(false),
                    at: st.release_at,
                });
            }
        }
        // Stable: edges of one surface keep their order, surfaces at the same time go by index.
        self.last_edges.sort_by_key(|e| e.at);
        &self.last_edges
    }
}

/// Times at which the sampled trajectory crosses `p` (either direction), in order. A crossing
/// is a change of `x ≥ p` between two samples; its time is interpolated linearly.
fn crossing_times(traj: &[(Nanos, f64)], p: f64, out: &mut Vec<Nanos>) {
    if !p.is_finite() {
        return;
    }
    for w in traj.windows(2) {
        let ((ta, xa), (tb, xb)) = (w[0], w[1]);
        if (xa >= p) == (xb >= p) || !(xa.is_finite() && xb.is_finite()) {
            continue;
        }
        let f = ((p - xa) / (xb - xa)).clamp(0.0, 1.0);
        let span = tb.0.saturating_sub(ta.0) as f64;
        let at = ta.0 as f64 + f * span;
        out.push(Nanos((at.round() as u64).clamp(ta.0, tb.0.max(ta.0))));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj(points: &[(u64, f64)]) -> Vec<(Nanos, f64)> {
        points.iter().map(|&(t, x)| (Nanos(t), x)).collect()
    }

    #[test]
    fn one_pulse_per_crossing() {
        let mut plant = Plant::new();
        let mut s = ProbeSurface::new(0, 10.0, vec![(0, 1)]);
        s.pulse = Nanos(100);
        plant.add_probe_surface(s);
        // Up through 10 at t = 50, back down at t = 250.
        let t = traj(&[(0, 0.0), (100, 20.0), (200, 20.0), (300, 0.0)]);
        let edges = plant
            .advance(Nanos(0), Nanos(300), |_| Some(&t[..]))
            .to_vec();
        let e = |rising, at| ProbeEdgeEvent {
            probe: 0,
            rising,
            at: Nanos(at),
        };
        assert_eq!(
            edges,
            vec![e(true, 50), e(false, 150), e(true, 250)],
            "release of the second pulse is in the next cycle"
        );
        assert!(plant.level(0, Nanos(60)) && !plant.level(0, Nanos(200)));
        assert!(!plant.level(0, Nanos(0)) && plant.level(0, Nanos(250)));
        assert!(plant.contact(0));
        let still = traj(&[(300, 0.0), (400, 0.0)]);
        let edges = plant.advance(Nanos(300), Nanos(400), |_| Some(&still[..]));
        assert_eq!(edges, &[e(false, 350)]);
        assert!(plant.level(0, Nanos(300)) && !plant.level(0, Nanos(360)));
        assert!(!plant.level(7, Nanos(0)));
    }

    #[test]
    fn retrigger_extends_and_active_low() {
        let mut plant = Plant::new();
        let mut s = ProbeSurface::new(0, 10.0, vec![]);
        s.active_high = false;
        plant.add_probe_surface(s);
        let t = traj(&[(0, 0.0), (100, 20.0), (200, 0.0)]);
        let edges = plant
            .advance(Nanos(0), Nanos(200), |_| Some(&t[..]))
            .to_vec();
        assert_eq!(
            edges,
            vec![ProbeEdgeEvent {
                probe: 0,
                rising: false,
                at: Nanos(50)
            }]
        );
        assert_eq!(
            plant.state[0].release_at,
            Nanos(150).saturating_add(DEFAULT_PULSE)
        );
    }
}
