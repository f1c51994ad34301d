//! An emulated EtherCAT segment: an [`EscChain`] behind a frame-level entry point.
//!
//! [`Segment::process_frame`] does to an Ethernet frame what the ring of devices does on the
//! wire: every datagram passes all devices in ring order (address field updated, data read or
//! written in place, working counter incremented per the ESC rules of [`super::Esc::process`]),
//! the datagram IRQ field is ORed with the devices' event requests, and the source MAC gets its
//! U/L bit set (`frame[6] |= 0x02`) like the first device does, so a master recognises the frame
//! as returned (ETG.1000.4).
//!
//! # Stepping the drive models ([`Stepping`])
//!
//! * [`Stepping::External`] (default): the caller runs SYNC0 with [`Segment::sync0`] — the
//!   in-process link does after every exchange, on virtual time.
//! * [`Stepping::PerFrame`] ("lockstep"): the world steps once per process-data cycle, after the
//!   frame whose logical write (LWR / LRW) reaches the end of the process image written so far,
//!   model time advancing by the cycle per step. A master that splits its image over several
//!   datagrams and frames (inputs first, then outputs, as ethercrab does) thus steps the models
//!   once, with every device's outputs of the cycle in place; a master with one LRW per cycle
//!   steps them after every such frame.
//! * [`Stepping::OwnClock`]: the segment keeps time like real devices do, on a clock the caller
//!   owns (sans-IO: [`Segment::poll_timeout`] says when to call [`Segment::handle_timeout`], and
//!   [`Segment::process_frame`] gets the same clock's `now`). Every device generates SYNC0 from
//!   its own 0x0990 / 0x09A0 / 0x0981 in its DC system time ([`super::dc`]); when a device that
//!   hosts a drive model has a SYNC0, the world steps once per SYNC0 with the outputs in the
//!   devices' output SMs at that instant (several frames in one period: the last one counts;
//!   none: the same outputs again, and a device in OP counts a sync error,
//!   [`Esc::sync_errors`]). While no hosted device has a SYNC0 (a master without DC, or before
//!   the first pulse), the world steps per process-data frame as in `PerFrame` (SM-synchronous
//!   drives). The sync-manager watchdogs run ([`Esc::tick`]). With neither SYNC0 nor process
//!   data for [`FREE_RUN_AFTER_CYCLES`] cycles the world steps by itself once per cycle (a
//!   drive's control loop keeps running when the master is gone).
//!
//! What the devices did by themselves (SYNC0 activation, watchdog expiry, …) is collected as
//! [`SegmentEvent`]s ([`Segment::take_events`]) and logged with `tracing`.

use std::collections::VecDeque;

use super::{Esc, EscChain, EscEvent};
use crate::bus::ethercat::wire::{self, Command, WireError};
use crate::drive::model::DriveModel;
use crate::sim::world::{PortBuffer, World};
use crate::units::Nanos;

/// How the hosted drive models are stepped (see the module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Stepping {
    /// By the caller, with [`Segment::sync0`].
    #[default]
    External,
    /// Once per process-data cycle: after the frame whose logical write (LWR / LRW) reaches the
    /// highest logical address written so far (the end of the master's image, however it is
    /// split over datagrams and frames); model time + one cycle per step.
    PerFrame,
    /// At the devices' SYNC0 on the segment's own clock (per process-data frame while no
    /// hosted device has a SYNC0), with the sync-manager watchdogs running.
    OwnClock,
}

/// Something a device did by itself: [`EscEvent`] with the device's ring position and the
/// segment's time when it was noticed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentEvent {
    /// Ring position of the device.
    pub position: usize,
    /// The segment's time (`now` of the call that collected it), ns.
    pub at_ns: u64,
    /// What happened.
    pub event: EscEvent,
}

/// SYNC0 pulses of different devices closer than this (ns) are one SYNC0 of the segment: the
/// world steps once for them (the devices' system times differ by their propagation delays).
pub const SYNC0_GROUP_WINDOW_NS: u64 = 20_000;

/// A device's SYNC0 pulses overdue by more than this many cycles are dropped (the emulator fell
/// behind, e.g. it was stopped) and reported as [`EscEvent::Sync0Skipped`].
pub const MAX_SYNC0_BACKLOG: u64 = 1000;

/// At most this many SYNC0 / watchdog deadlines are handled per [`Segment::handle_timeout`].
const MAX_DEADLINES_PER_CALL: usize = 4096;

/// [`Stepping::OwnClock`]: a segment whose world saw neither a SYNC0 nor a process-data frame
/// for this many cycles (the master left, or asked for INIT and switched SYNC0 off) steps the
/// world on its own, once per cycle, until SYNC0 or process data come back: a drive's control
/// loop never stops, so a drive whose outputs went to their safe state on leaving OP carries
/// out its quick stop by itself (CiA 402 0x6007 option 3) instead of staying frozen in
/// OPERATION ENABLED.
pub const FREE_RUN_AFTER_CYCLES: u64 = 10;

/// At most this many [`SegmentEvent`]s are kept for [`Segment::take_events`]; older ones are
/// dropped.
const MAX_SEGMENT_EVENTS: usize = 256;

/// An emulated segment: devices in ring order plus a frame-level entry point.
#[derive(Debug)]
pub struct Segment {
    /// The devices, position 0 (nearest the master) first.
    pub chain: EscChain,
    /// Number of frames processed so far.
    pub frames: u64,
    /// Number of datagrams processed so far.
    pub datagrams: u64,
    world: Option<World>,
    cycle: Nanos,
    stepping: Stepping,
    sync_time: Nanos,
    syncs: u64,
    /// Own clock: time of the previous SYNC0 that stepped the world.
    last_world_sync0: Option<u64>,
    /// Own clock: when the world last stepped (any cause), on the caller's clock.
    last_step_at: Option<u64>,
    /// Own clock: the world is stepping by itself ([`FREE_RUN_AFTER_CYCLES`]).
    free_running: bool,
    events: VecDeque<SegmentEvent>,
    events_dropped: u64,
    drop_frames: std::collections::BTreeSet<u64>,
    /// Ranges of frame numbers dropped ([`Self::drop_frames_in`]).
    drop_ranges: Vec<std::ops::Range<u64>>,
    miscount: std::collections::BTreeSet<u64>,
    offered: u64,
    /// The hosted models' ports during a world step (kept: no allocation per step).
    ports: PortBuffer,
    /// End (exclusive) of the highest logical address a logical write has reached so far: a
    /// frame whose logical write reaches it completes a process-data cycle (per-frame stepping).
    image_end: u64,
}

impl Segment {
    /// Segment of `escs` in a line, `hop_delay_ns` forwarding delay between neighbours.
    pub fn new(escs: Vec<Esc>, hop_delay_ns: u64) -> Self {
        Self::from_chain(EscChain::new(escs, hop_delay_ns))
    }

    /// Segment around an existing chain.
    pub fn from_chain(chain: EscChain) -> Self {
        Self {
            chain,
            frames: 0,
            datagrams: 0,
            world: None,
            cycle: Nanos::ZERO,
            stepping: Stepping::External,
            sync_time: Nanos::ZERO,
            syncs: 0,
            last_world_sync0: None,
            last_step_at: None,
            free_running: false,
            events: VecDeque::new(),
            events_dropped: 0,
            drop_frames: std::collections::BTreeSet::new(),
            drop_ranges: Vec::new(),
            miscount: std::collections::BTreeSet::new(),
            offered: 0,
            ports: PortBuffer::default(),
            image_end: 0,
        }
    }

    /// Put the devices' drive models into `world` (probe surfaces, fixed stops) with cycle time
    /// `cycle`: from now on the models are stepped together by [`Self::sync0`] (the SYNC0
    /// event), not when their inputs are read. World device `i` is the `i`-th ESC (ring order)
    /// whose application hosts a drive model.
    pub fn set_world(&mut self, world: World, cycle: Nanos) {
        for esc in &mut self.chain.escs {
            esc.app_mut().set_synchronized(true);
        }
        self.world = Some(world);
        self.cycle = cycle;
    }

    /// The world, if one is installed.
    pub fn world(&self) -> Option<&World> {
        self.world.as_ref()
    }

    /// The world, mutable.
    pub fn world_mut(&mut self) -> Option<&mut World> {
        self.world.as_mut()
    }

    /// `true`: [`Stepping::PerFrame`] — step the world once per process-data cycle, after the
    /// frame whose logical write (LWR / LRW) completes the image, with the model time advancing
    /// by the cycle time per step. `false`: [`Stepping::External`].
    pub fn set_auto_sync(&mut self, on: bool) {
        self.set_stepping(if on {
            Stepping::PerFrame
        } else {
            Stepping::External
        });
    }

    /// How the world is stepped from now on.
    pub fn set_stepping(&mut self, stepping: Stepping) {
        self.stepping = stepping;
        self.last_world_sync0 = None;
        self.last_step_at = None;
        self.free_running = false;
    }

    /// How the world is stepped.
    pub fn stepping(&self) -> Stepping {
        self.stepping
    }

    /// Return the `n`-th frame (0-based count of offered frames) with the working counter of
    /// every logical datagram (LRD / LWR / LRW) one short, as if one device had not processed
    /// it. May be called for several.
    pub fn miscount_frame_at(&mut self, n: u64) {
        self.miscount.insert(n);
    }

    /// Frames offered to [`Self::process_frame`] so far (including dropped ones).
    pub fn offered_frames(&self) -> u64 {
        self.offered
    }

    /// World steps so far.
    pub fn syncs(&self) -> u64 {
        self.syncs
    }

    /// Drop the `n`-th frame (0-based count of frames offered to [`Self::process_frame`]) as a
    /// broken cable would: it is not processed and never comes back. May be called for several.
    pub fn drop_frame_at(&mut self, n: u64) {
        self.drop_frames.insert(n);
    }

    /// Drop the frames numbered in `range` (0-based, as [`Self::drop_frame_at`]); `n..u64::MAX`:
    /// a device that answered and then went silent (a pulled cable, a power loss).
    pub fn drop_frames_in(&mut self, range: std::ops::Range<u64>) {
        self.drop_ranges.push(range);
    }

    /// SYNC0 at `now`: one [`World::step`] of every hosted drive model over `[now − cycle, now]`
    /// with the outputs the master wrote last; the inputs the master reads next are the result.
    /// Device-initiated mailbox messages (e.g. an EMCY for a new fault) are queued afterwards.
    /// Without a world, nothing happens.
    pub fn sync0(&mut self, now: Nanos) {
        let cycle = self.cycle;
        self.step_world(now, cycle, None);
    }

    /// One world step at model time `now` over the cycle `[now − cycle, now]`. `clock`: the
    /// instant of the step on the caller's clock (own clock, [`Stepping::OwnClock`]); each
    /// hosted model is then told its device's DC system time at that instant
    /// ([`DriveModel::set_dc_time`]: the EL1252 stamps its edges on it). `None` (in-process,
    /// virtual time): not told.
    fn step_world(&mut self, now: Nanos, cycle: Nanos, clock: Option<u64>) {
        let Some(world) = self.world.as_mut() else {
            return;
        };
        if let Some(t) = clock {
            for esc in &mut self.chain.escs {
                let system_time = esc.system_time(t);
                if let Some(m) = esc.app_mut().model_mut() {
                    m.set_dc_time(now, system_time);
                }
            }
        }
        let ports = self
            .chain
            .escs
            .iter_mut()
            .filter_map(|e| e.app_mut().port());
        self.ports.with(ports, |p| world.step(now, cycle, p));
        for esc in &mut self.chain.escs {
            esc.poll_app_mailbox();
        }
        self.syncs += 1;
        self.sync_time = now;
    }

    /// Drive model of world device `device` (the `device`-th ESC hosting a model).
    pub fn model(&self, device: usize) -> Option<&dyn DriveModel> {
        self.chain
            .escs
            .iter()
            .filter_map(|e| e.app().model())
            .nth(device)
    }

    /// Drive model of world device `device`, mutable.
    pub fn model_mut(&mut self, device: usize) -> Option<&mut dyn DriveModel> {
        self.chain
            .escs
            .iter_mut()
            .filter_map(|e| e.app_mut().model_mut())
            .nth(device)
    }

    /// Ring position of world device `device`.
    pub fn position_of(&self, device: usize) -> Option<usize> {
        self.chain
            .escs
            .iter()
            .enumerate()
            .filter(|(_, e)| e.app().model().is_some())
            .map(|(p, _)| p)
            .nth(device)
    }

    /// World device number of the device at ring position `pos` (`None`: it hosts no model).
    pub fn world_device_at(&self, pos: usize) -> Option<usize> {
        let escs = &self.chain.escs;
        escs.get(pos)?.app().model()?;
        Some(
            escs[..pos]
                .iter()
                .filter(|e| e.app().model().is_some())
                .count(),
        )
    }

    /// Number of devices.
    pub fn len(&self) -> usize {
        self.chain.escs.len()
    }

    /// `true` if the segment has no devices.
    pub fn is_empty(&self) -> bool {
        self.chain.escs.is_empty()
    }

    /// Device at ring position `pos`.
    pub fn esc(&self, pos: usize) -> Option<&Esc> {
        self.chain.escs.get(pos)
    }

    /// Device at ring position `pos`, mutable.
    pub fn esc_mut(&mut self, pos: usize) -> Option<&mut Esc> {
        self.chain.escs.get_mut(pos)
    }

    /// Run every datagram of the Ethernet frame `frame` through the devices in place and mark
    /// the frame processed (U/L bit of the source MAC). `now_ns` is the simulation time the
    /// frame reaches the first device.
    ///
    /// An invalid frame (not EtherCAT, truncated, inconsistent lengths) is left unchanged and
    /// reported as an error — a real segment would drop it.
    ///
    /// Returns `Ok(false)` for a frame dropped on purpose ([`Self::drop_frame_at`]): the caller
    /// must not hand it back to the master.
    ///
    /// [`Stepping::OwnClock`]: SYNC0 pulses and watchdog expiries due at `now_ns` happen before
    /// the frame ([`Self::handle_timeout`]); the frame then steps the world only while no
    /// hosted device has a SYNC0. [`Stepping::PerFrame`]: a frame whose logical write reaches the
    /// end of the image written so far steps it (once per cycle however the master splits it).
    pub fn process_frame(&mut self, frame: &mut [u8], now_ns: u64) -> Result<bool, WireError> {
        let n = self.offered;
        self.offered += 1;
        if self.drop_frames.contains(&n) || self.drop_ranges.iter().any(|r| r.contains(&n)) {
            return Ok(false);
        }
        // Own clock: what fell due before the frame arrived happens first.
        self.handle_timeout(now_ns);
        let chain = &mut self.chain;
        chain.refresh_irq();
        let miscount = self.miscount.contains(&n);
        // End of this frame's logical writes (0: none).
        let mut write_end = 0u64;
        let count = wire::for_each_datagram_mut(frame, |mut dg| {
            let cmd = dg.command().code();
            let raw_addr = dg.address();
            if cmd == Command::Lwr.code() || cmd == Command::Lrw.code() {
                // A zero-length write still marks the frame as process data.
                let end = u64::from(raw_addr) + dg.data().len().max(1) as u64;
                write_end = write_end.max(end);
            }
            let mut wkc = dg.wkc();
            let (new_addr, devices_irq) =
                chain.process_raw_with_irq(cmd, raw_addr, dg.data_mut(), &mut wkc, now_ns);
            if miscount && dg.command().addressing() == wire::Addressing::Logical {
                // A device that did not take part: one count short.
                wkc = wkc.saturating_sub(1);
            }
            dg.set_address(new_addr);
            dg.set_wkc(wkc);
            let irq = dg.irq() | devices_irq;
            dg.set_irq(irq);
        })?;
        wire::mark_processed(frame);
        self.frames += 1;
        self.datagrams += count as u64;
        let per_frame = match self.stepping {
            Stepping::External => false,
            Stepping::PerFrame => true,
            Stepping::OwnClock => !self.hosted_sync0_scheduled(),
        };
        // The frame completes the cycle's image when its logical write reaches the highest end
        // written so far (the image may grow: a frame beyond it sets the new end).
        let completes = write_end > 0 && write_end >= self.image_end;
        self.image_end = self.image_end.max(write_end);
        if completes && per_frame {
            let t = self.sync_time.saturating_add(self.cycle);
            let clock = (self.stepping == Stepping::OwnClock).then_some(now_ns);
            let cycle = self.cycle;
            self.step_world(t, cycle, clock);
            self.stepped_at(now_ns);
        }
        self.collect_events(now_ns);
        Ok(true)
    }

    // ------------------------------------------------------------------ own clock

    /// Does a device hosting a drive model have a SYNC0 scheduled?
    fn hosted_sync0_scheduled(&self) -> bool {
        self.world.is_some()
            && self
                .chain
                .escs
                .iter()
                .any(|e| e.app().model().is_some() && e.sync0_unit().next_pulse().is_some())
    }

    /// [`Stepping::OwnClock`]: the next time (on the caller's clock, ns) at which
    /// [`Self::handle_timeout`] has something to do — the earliest SYNC0 pulse or
    /// sync-manager watchdog expiry of any device; `None` if there is none (or another
    /// stepping). May lie before `now` if something is overdue.
    pub fn poll_timeout(&self, now: u64) -> Option<u64> {
        if self.stepping != Stepping::OwnClock {
            return None;
        }
        self.chain
            .escs
            .iter()
            .flat_map(|e| [e.sync0_due_at(now), e.watchdog_deadline()])
            .chain([self.free_run_due()])
            .flatten()
            .min()
    }

    /// Own clock: the world stepped at `now` (caller's clock) because of SYNC0 or process data.
    fn stepped_at(&mut self, now: u64) {
        if self.stepping == Stepping::OwnClock {
            self.last_step_at = Some(now);
            self.free_running = false;
        }
    }

    /// Own clock: when the world steps by itself next ([`FREE_RUN_AFTER_CYCLES`]); `None` without
    /// a world, before its first step, or while a hosted device has a SYNC0 scheduled.
    fn free_run_due(&self) -> Option<u64> {
        if self.world.is_none() || self.cycle.0 == 0 || self.hosted_sync0_scheduled() {
            return None;
        }
        let gap = if self.free_running {
            self.cycle.0
        } else {
            self.cycle.0.saturating_mul(FREE_RUN_AFTER_CYCLES)
        };
        self.last_step_at.map(|t| t.saturating_add(gap))
    }

    /// Own clock: one step of the world by itself at `t` (see [`FREE_RUN_AFTER_CYCLES`]). A
    /// backlog (the emulator was stopped) is not caught up: time jumps to `now`.
    fn free_run_step(&mut self, t: u64, now: u64) {
        let cycle = self.cycle;
        let at = if now.saturating_sub(t) > cycle.0.saturating_mul(MAX_SYNC0_BACKLOG) {
            now
        } else {
            t
        };
        if !self.free_running {
            tracing::info!(
                "no SYNC0 and no process data for {FREE_RUN_AFTER_CYCLES} cycles: the drives run on their own clock"
            );
        }
        let model_now = self.sync_time.saturating_add(cycle);
        self.step_world(model_now, cycle, Some(at));
        self.last_step_at = Some(at);
        self.free_running = true;
    }

    /// [`Stepping::OwnClock`]: run every SYNC0 pulse and watchdog expiry due at or before
    /// `now`, in time order. At a SYNC0 every device whose pulse is due within
    /// [`SYNC0_GROUP_WINDOW_NS`] generates it ([`Esc::fire_sync0`]: the sync-error check) and,
    /// if one of them hosts a model, the world steps once, over the time since the previous
    /// such step (one cycle for the first). Nothing happens in another stepping.
    pub fn handle_timeout(&mut self, now: u64) {
        if self.stepping != Stepping::OwnClock {
            return;
        }
        for e in &mut self.chain.escs {
            e.skip_overdue_sync0(now, MAX_SYNC0_BACKLOG);
        }
        for _ in 0..MAX_DEADLINES_PER_CALL {
            let pulse = self
                .chain
                .escs
                .iter()
                .filter_map(|e| e.sync0_due_at(now))
                .min();
            let watchdog = self
                .chain
                .escs
                .iter()
                .filter_map(Esc::watchdog_deadline)
                .min();
            let free = self.free_run_due();
            // The earliest deadline first; at a tie the watchdog, then SYNC0, then the free run.
            let first = [watchdog, pulse, free]
                .into_iter()
                .flatten()
                .filter(|&t| t <= now)
                .min();
            let Some(t) = first else { break };
            if watchdog == Some(t) {
                for e in &mut self.chain.escs {
                    if e.watchdog_deadline().is_some_and(|d| d <= t) {
                        e.tick(t);
                    }
                }
            } else if pulse == Some(t) {
                self.sync0_pulse(t, now);
            } else {
                self.free_run_step(t, now);
            }
        }
        self.collect_events(now);
    }

    /// The devices' SYNC0 pulses due at `t` (within the group window) on the caller's clock.
    fn sync0_pulse(&mut self, t: u64, now: u64) {
        let limit = t.saturating_add(SYNC0_GROUP_WINDOW_NS);
        let mut step_cycle: Option<u64> = None;
        for (position, e) in self.chain.escs.iter_mut().enumerate() {
            if e.sync0_due_at(now).is_none_or(|d| d > limit) {
                continue;
            }
            let cycle = e.sync0_unit().cycle();
            if e.fire_sync0() == Some(true) {
                tracing::debug!(
                    position,
                    sync_errors = e.sync_errors(),
                    "SYNC0 without new process data: the outputs are held (sync error)"
                );
            }
            if e.app().model().is_some() && step_cycle.is_none() {
                step_cycle = Some(cycle);
            }
        }
        let Some(cycle) = step_cycle else {
            return;
        };
        if self.world.is_none() {
            return;
        }
        let nominal = if cycle > 0 {
            cycle
        } else {
            self.cycle.0.max(1)
        };
        let dt = match self.last_world_sync0 {
            Some(prev) if t > prev && t - prev <= 4 * nominal => t - prev,
            _ => nominal,
        };
        self.last_world_sync0 = Some(t);
        let model_now = self.sync_time.saturating_add(Nanos(dt));
        self.step_world(model_now, Nanos(dt), Some(t));
        self.stepped_at(t);
    }

    /// Move the devices' events into the segment's queue (and the log).
    fn collect_events(&mut self, now: u64) {
        for (position, e) in self.chain.escs.iter_mut().enumerate() {
            for event in e.take_events() {
                if self.stepping == Stepping::OwnClock {
                    match event {
                        EscEvent::WatchdogExpired { .. }
                        | EscEvent::Sync0Skipped { .. }
                        | EscEvent::Sync0(
                            super::dc::Activation::StartMissed { .. }
                            | super::dc::Activation::CycleTooShort { .. },
                        ) => tracing::warn!(position, "{event}"),
                        EscEvent::Sync0(_) => tracing::info!(position, "{event}"),
                    }
                } else {
                    tracing::debug!(position, "{event}");
                }
                if self.events.len() >= MAX_SEGMENT_EVENTS {
                    self.events.pop_front();
                    self.events_dropped += 1;
                }
                self.events.push_back(SegmentEvent {
                    position,
                    at_ns: now,
                    event,
                });
            }
        }
    }

    /// The events collected since the last call (the latest 256).
    pub fn take_events(&mut self) -> Vec<SegmentEvent> {
        self.events.drain(..).collect()
    }

    /// Events dropped because [`Self::take_events`] was not called often enough.
    pub fn events_dropped(&self) -> u64 {
        self.events_dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::ethercat::wire::{physical_address, Command, Frame, FrameBuilder};
    use crate::sim::esc::{EscConfig, NullApp};

    const SRC: [u8; 6] = [0x10; 6];

    fn segment(n: usize) -> Segment {
        let escs = (0..n)
            .map(|_| Esc::new(EscConfig::default(), Box::new(NullApp)))
            .collect();
        Segment::new(escs, 100)
    }

    fn frame(dgs: &[(Command, u32, Vec<u8>)]) -> Vec<u8> {
        let mut b = FrameBuilder::new([0xFF; 6], SRC);
        for (i, (c, a, d)) in dgs.iter().enumerate() {
            b.push_command(*c, i as u8, *a, d).unwrap();
        }
        b.build()
    }

    fn wkcs(f: &[u8]) -> Vec<u16> {
        Frame::parse(f)
            .unwrap()
            .datagrams()
            .map(|d| d.wkc)
            .collect()
    }

    #[test]
    fn brd_type_counts_all_devices_and_marks_frame() {
        let mut seg = segment(3);
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![3]);
        let p = Frame::parse(&f).unwrap();
        let dg = p.datagrams().next().unwrap();
        assert_eq!(dg.data, &[0x11]); // ET1100 type ORed
        assert_eq!(dg.adp(), 3); // ADP incremented by every device
        assert_eq!(f[6], 0x12);
        assert_eq!(seg.frames, 1);
        assert_eq!(seg.datagrams, 1);
    }

    #[test]
    fn several_datagrams_in_one_frame() {
        let mut seg = segment(3);
        // APWR station address of position 1, then FPRD it back, then BWR AL control.
        let mut f = frame(&[
            (
                Command::Apwr,
                physical_address(0u16.wrapping_sub(1), 0x0010),
                vec![0x01, 0x10],
            ),
            (Command::Fprd, physical_address(0x1001, 0x0010), vec![0, 0]),
            (Command::Bwr, physical_address(0, 0x0120), vec![0x11, 0x00]),
            (Command::Fprd, physical_address(0x4242, 0x0010), vec![0, 0]),
        ]);
        seg.process_frame(&mut f, 1_000).unwrap();
        assert_eq!(wkcs(&f), vec![1, 1, 3, 0]);
        let p = Frame::parse(&f).unwrap();
        let dgs: Vec<_> = p.datagrams().collect();
        assert_eq!(dgs[1].data, &[0x01, 0x10]);
        assert_eq!(seg.esc(1).unwrap().station_address(), 0x1001);
        assert_eq!(seg.esc(0).unwrap().station_address(), 0);
        assert_eq!(seg.datagrams, 4);
    }

    #[test]
    fn existing_wkc_is_added_to() {
        let mut seg = segment(2);
        let mut b = FrameBuilder::new([0xFF; 6], SRC);
        let mut dg = wire::Datagram::new(Command::Brd, 0, 0, &[0]);
        dg.wkc = 5;
        b.push(&dg).unwrap();
        let mut f = b.build();
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![7]);
    }

    #[test]
    fn invalid_frame_is_rejected_unchanged() {
        let mut seg = segment(1);
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        f[12] = 0x08;
        f[13] = 0x00; // IPv4 EtherType
        let before = f.clone();
        assert!(seg.process_frame(&mut f, 0).is_err());
        assert_eq!(f, before);
        assert_eq!(seg.frames, 0);
        let mut short = vec![0u8; 10];
        assert!(seg.process_frame(&mut short, 0).is_err());
    }

    /// Per-frame stepping: once per process-data cycle, however the master splits its image
    /// over datagrams and frames.
    #[test]
    fn per_frame_stepping_steps_once_per_split_cycle() {
        let mut seg = segment(3);
        seg.set_world(
            World::new(crate::sim::plant::Plant::new()),
            Nanos(1_000_000),
        );
        seg.set_stepping(Stepping::PerFrame);
        let lrw = |a: u32, n: usize| (Command::Lrw, a, vec![0u8; n]);
        // One LRW per cycle: one step per frame.
        for k in 1..=3 {
            let mut f = frame(&[lrw(0, 100)]);
            seg.process_frame(&mut f, 0).unwrap();
            assert_eq!(seg.syncs(), k);
        }
        // The image split over two frames: the step follows the second.
        for k in 0..3u64 {
            let mut f = frame(&[lrw(0, 60)]);
            seg.process_frame(&mut f, 0).unwrap();
            assert_eq!(seg.syncs(), 3 + k, "no step after the first part");
            let mut f = frame(&[lrw(60, 40)]);
            seg.process_frame(&mut f, 0).unwrap();
            assert_eq!(seg.syncs(), 4 + k, "one step after the last part");
        }
        // Two datagrams in one frame: one step; a frame without logical write: none.
        let mut f = frame(&[lrw(0, 50), lrw(50, 50)]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(seg.syncs(), 7);
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(seg.syncs(), 7);
        // The image grows to three frames: from the next cycle on, one step per cycle again.
        for part in [(0, 100), (100, 100), (200, 20)] {
            let mut f = frame(&[lrw(part.0, part.1)]);
            seg.process_frame(&mut f, 0).unwrap();
        }
        let grown = seg.syncs();
        for k in 1..=2 {
            for part in [(0, 100), (100, 100), (200, 20)] {
                let mut f = frame(&[lrw(part.0, part.1)]);
                seg.process_frame(&mut f, 0).unwrap();
            }
            assert_eq!(seg.syncs(), grown + k);
        }
    }

    #[test]
    fn empty_segment_passes_frames() {
        let mut seg = segment(0);
        assert!(seg.is_empty());
        let mut f = frame(&[(Command::Brd, 0, vec![0])]);
        seg.process_frame(&mut f, 0).unwrap();
        assert_eq!(wkcs(&f), vec![0]);
    }
}
