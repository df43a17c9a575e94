//! The 2D controller (issue #36): per touch reading, the order of the plane's stages — contact
//! and faults → 2D velocity (only where the scene reads it) → window → edges, else the
//! window's texture → gate — and the fault, stale and recovery state, the scene swap and the
//! telemetry. What each stage does lives with it (plane::screen, plane::edges,
//! plane::grating, texture::compiled, gate); this file keeps the order.
//!
//! It takes `touch::frame::Reading`s, not frames: the caller owns the `TouchSensor` (pressure,
//! rail bands, calibration). Lift-off is not a fault: the carrier goes off on that reading.

use super::edges::EdgeTracker;
use super::geometry::PointUm;
use super::scene::{CompiledScene2d, Config2d, Config2dError, PlaneCompiled, MAX_STALE_US};
use super::screen::{Place, ScreenTracker};
use super::velocity::{PlaneVelocity, VelocityUmS};
use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};
use crate::controller::{WindowEstimator, DEFAULT_WINDOW, RECOVERY_SAMPLES};
use crate::gate::{BurstOutput, DriveMode, Envelope, Gate, GateAction};
use crate::texture::compiled::{Moment, Need, Render, Request, Want};
use crate::touch::fault::AxisFault;
use crate::touch::frame::Reading;
use crate::velocity::{LsqSlope, Median3, VelocityEstimator};

/// Why the carrier is held off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum TouchFault {
    /// A pressed reading with an axis on a rail (an open or shorted terminal).
    Rail(AxisFault),
    /// No reading for longer than the stale limit.
    Stale,
}

/// What one reading produced.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Output2d {
    /// The finger, µm, on a pressed, fault-free reading (landing or down).
    pub position: Option<PointUm>,
    /// The 2D velocity, on a reading whose window (or edges) read it, once both axes have a
    /// full window; None where it rests.
    pub velocity: Option<VelocityUmS>,
    /// The window under the finger, while it renders.
    pub place: Option<Place>,
    /// The action for the burst-timer port, when the line must change.
    pub action: Option<GateAction>,
    /// The new drive amplitude, ‰, when it changes.
    pub amplitude_permille: Option<u16>,
    /// The level's shape over the one-pulse of `action` (with every `Pulse`).
    pub envelope: Option<Envelope>,
    /// The drive mode, on the first rendering reading after a scene loads.
    pub drive: Option<DriveMode>,
    /// The edge crossed on this reading (its pulse fired).
    pub edge: Option<u8>,
    /// The fault in force, if any.
    pub fault: Option<TouchFault>,
}

/// Counters for the low-rate telemetry log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Telemetry2d {
    /// Readings processed.
    pub readings: u32,
    /// Fault onsets (lift-offs are not faults).
    pub faults: u32,
    /// A rendering finger lifted.
    pub lifts: u32,
    /// Window switches (background included).
    pub window_switches: u32,
    /// Gate actions issued.
    pub gate_actions: u32,
    /// Readings whose f_b was clamped to the board's limit.
    pub clamped: u32,
    /// Edge pulses fired.
    pub edge_pulses: u32,
    /// Edge crossings without a pulse, to keep the duty cap (a pulse's rest, a burst running).
    pub edges_skipped: u32,
    /// Oriented-grating ridge pulses fired.
    pub ridge_pulses: u32,
    /// Ridge crossings without a pulse.
    pub ridges_skipped: u32,
}

/// A 2D configuration validated and compiled, ready to [`Controller2d::install`].
#[derive(Clone, Debug)]
pub struct Prepared2d {
    scene: CompiledScene2d,
    limits: SafetyLimits,
    stale_after_us: u32,
    /// Bit i: texture i (window i; the background's is the last) reads the velocity, or the
    /// scene has edges (whose lead is the velocity): the estimator updates there, else rests.
    update_mask: u16,
}

impl Prepared2d {
    /// Validates and compiles `config` for this burst timer and sample period; needs no
    /// controller (a firmware compiles at low priority). All or nothing.
    pub fn compile(
        timer: &BurstTimer,
        sample_period_us: u32,
        config: &Config2d,
    ) -> Result<Prepared2d, Config2dError> {
        let min_us = sample_period_us.saturating_mul(2);
        if config.stale_after_us < min_us || config.stale_after_us > MAX_STALE_US {
            return Err(Config2dError::StaleLimit {
                stale_after_us: config.stale_after_us,
                min_us,
            });
        }
        let scene = config
            .scene
            .compile(timer, &config.limits, sample_period_us)?;
        let update_mask = if scene.edges.is_some() {
            u16::MAX
        } else {
            scene
                .textures
                .iter()
                .enumerate()
                .filter(|(_, t)| t.need() == Need::Velocity)
                .fold(0u16, |m, (i, _)| m | 1 << i)
        };
        Ok(Prepared2d {
            scene,
            limits: config.limits,
            stale_after_us: config.stale_after_us,
            update_mask,
        })
    }
}

/// The 2D control core.
#[derive(Clone, Debug)]
pub struct Controller2d<E: VelocityEstimator = WindowEstimator<DEFAULT_WINDOW>> {
    timer: BurstTimer,
    sample_period_us: u32,
    active: Option<Prepared2d>,
    velocity: PlaneVelocity<E>,
    /// The estimators were rested on the last reading: woken before the next update.
    resting: bool,
    /// The texture in force reads the velocity (or the scene has edges): update, else rest.
    update_velocity: bool,
    gate: Gate,
    screen: ScreenTracker,
    edges: EdgeTracker,
    /// The place rendered on the last reading (None: lifted, landing, faulty or new scene).
    place: Option<Place>,
    /// Place, arming and textures were forgotten and nothing has rendered since.
    forgotten: bool,
    fault: Option<TouchFault>,
    good_run: u16,
    last_reading_us: Option<u32>,
    /// Start of the running edge pulse while in its pulse + rest window.
    edge_pulse_us: Option<u32>,
    amplitude: Option<u16>,
    /// The permille last asked (u16::MAX: none since the cap changed).
    amplitude_asked: u16,
    drive_pending: bool,
    caps_pending: bool,
    telemetry: Telemetry2d,
}

impl Controller2d {
    /// A controller with the default estimator on each axis, no scene (line off).
    pub fn new(timer: BurstTimer, sample_period_us: u32) -> Result<Self, Config2dError> {
        Self::with_window(timer, sample_period_us)
    }
}

impl<const N: usize> Controller2d<WindowEstimator<N>> {
    /// A controller with the default estimator over an `N`-sample window on each axis.
    pub fn with_window(timer: BurstTimer, sample_period_us: u32) -> Result<Self, Config2dError> {
        let one = || {
            LsqSlope::<N>::new(sample_period_us)
                .map(|l| Median3::new(l, sample_period_us))
                .map_err(Config2dError::Estimator)
        };
        let velocity = PlaneVelocity::new(one()?, one()?);
        Ok(Self::with_estimators(timer, sample_period_us, velocity))
    }
}

impl<E: VelocityEstimator> Controller2d<E> {
    /// A controller with chosen estimators (one per axis), no scene (line off).
    pub fn with_estimators(
        timer: BurstTimer,
        sample_period_us: u32,
        velocity: PlaneVelocity<E>,
    ) -> Self {
        Self {
            timer,
            sample_period_us,
            active: None,
            velocity,
            resting: false,
            update_velocity: true,
            gate: Gate::default(),
            screen: ScreenTracker::default(),
            edges: EdgeTracker::default(),
            place: None,
            forgotten: true,
            fault: None,
            good_run: 0,
            last_reading_us: None,
            edge_pulse_us: None,
            amplitude: None,
            amplitude_asked: u16::MAX,
            drive_pending: false,
            caps_pending: false,
            telemetry: Telemetry2d::default(),
        }
    }

    /// Validates and compiles `config`, then makes it active. On error nothing changes: the
    /// previous scene stays.
    pub fn load(&mut self, config: &Config2d) -> Result<(), Config2dError> {
        match Prepared2d::compile(&self.timer, self.sample_period_us, config) {
            Ok(p) => {
                self.install(p);
                Ok(())
            }
            Err(e) => {
                warn!("2d scene rejected, previous kept: {}", e);
                Err(e)
            }
        }
    }

    /// Makes a compiled configuration active from the next reading: a move, no checks.
    pub fn install(&mut self, prepared: Prepared2d) {
        info!(
            "2d scene loaded: {} windows, edges {}, duty cap {} permille, on-time cap {} us",
            prepared.scene.screen.windows(),
            prepared.scene.edges.as_ref().map_or(0, |(e, _)| e.len()),
            prepared.limits.max_duty_permille,
            prepared.limits.max_on_time_us
        );
        self.active = Some(prepared);
        self.forgotten = false;
        // Places, arming and motion mean nothing in the new layout; the first reading places
        // the finger anew (a running edge pulse keeps its window: the gate may be in its rest).
        self.forget_finger(true);
        self.amplitude_asked = u16::MAX;
        self.drive_pending = true;
        self.caps_pending = true;
    }

    /// The burst timer this controller plans for.
    pub fn timer(&self) -> &BurstTimer {
        &self.timer
    }

    /// Counters, for telemetry.
    pub fn telemetry(&self) -> Telemetry2d {
        self.telemetry
    }

    /// The fault in force, if any.
    pub fn fault(&self) -> Option<TouchFault> {
        self.fault
    }

    /// Runs one reading of the touch sensor, stamped `t_us`, through every stage.
    pub fn on_reading(&mut self, t_us: u32, reading: Reading) -> Output2d {
        self.telemetry.readings = self.telemetry.readings.wrapping_add(1);
        self.last_reading_us = Some(t_us);
        self.caps_pending = false;
        if self.active.is_none() {
            // Nothing has ever driven the gate.
            return Output2d::default();
        }
        let (x_um, y_um) = match reading {
            Reading::Fault(f) => return self.enter_fault(TouchFault::Rail(f), t_us),
            Reading::Lifted => {
                // No contact says nothing of a faulty terminal: a recovery starts again.
                self.good_run = 0;
                if self.place.is_some() {
                    self.telemetry.lifts = self.telemetry.lifts.wrapping_add(1);
                }
                let action = self.release(t_us, true);
                return Output2d {
                    action,
                    fault: self.fault,
                    ..Output2d::default()
                };
            }
            Reading::Landing { x_um, y_um } => {
                let p = PointUm::new(x_um, y_um);
                self.recover(p);
                let action = self.release(t_us, false);
                // The estimators warm up on the landing run, so the touch-down has a velocity
                // sooner (resting: nobody reads it yet).
                self.velocity.rest(p, t_us);
                self.resting = true;
                return Output2d {
                    position: Some(p),
                    action,
                    fault: self.fault,
                    ..Output2d::default()
                };
            }
            Reading::Down { x_um, y_um, .. } => (x_um, y_um),
        };
        let p = PointUm::new(x_um, y_um);
        if !self.recover(p) {
            return Output2d {
                position: Some(p),
                fault: self.fault,
                ..Output2d::default()
            };
        }
        self.render(p, t_us)
    }

    /// Counts a pressed, fault-free reading towards leaving a fault; true when none is in
    /// force (the 1D rule: [`RECOVERY_SAMPLES`] in a row).
    fn recover(&mut self, p: PointUm) -> bool {
        let Some(fault) = self.fault else {
            return true;
        };
        self.good_run = self.good_run.saturating_add(1);
        if self.good_run < RECOVERY_SAMPLES {
            return false;
        }
        info!(
            "touch recovered after {:?}: {} {} um",
            fault, p.x_um, p.y_um
        );
        self.fault = None;
        true
    }

    /// A finger down at `p`, no fault: window, velocity, edges, else texture.
    fn render(&mut self, p: PointUm, t_us: u32) -> Output2d {
        let Some(active) = self.active.as_ref() else {
            return Output2d::default();
        };
        let drive = core::mem::take(&mut self.drive_pending).then_some(active.scene.drive);
        self.forgotten = false;
        let place = self.screen.update(&active.scene.screen, p);
        if self.place != Some(place) {
            self.note_place_change(place);
        }
        let velocity = if self.update_velocity {
            if core::mem::take(&mut self.resting) {
                self.velocity.wake();
            }
            self.velocity.update(p, t_us)
        } else {
            self.velocity.rest(p, t_us);
            self.resting = true;
            None
        };
        let mut out = Output2d {
            position: Some(p),
            velocity,
            place: Some(place),
            drive,
            ..Output2d::default()
        };
        if !self.edges_step(p, velocity, t_us, &mut out) {
            self.texture_step(place, p, velocity, t_us, &mut out);
        }
        out
    }

    fn note_place_change(&mut self, place: Place) {
        if self.place.is_some() {
            self.telemetry.window_switches = self.telemetry.window_switches.wrapping_add(1);
        }
        self.place = Some(place);
        let rests = self.velocity_rests();
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let index = active.scene.screen.texture(place);
        if let Some(t) = active.scene.textures.get_mut(index as usize) {
            t.reset();
        }
        let bit = 1u16.checked_shl(index as u32).unwrap_or(0);
        self.update_velocity = !rests || active.update_mask & bit != 0;
        debug!("window {:?}", place);
    }

    /// True when the estimators rest cheaper than they update (else they always update).
    fn velocity_rests(&self) -> bool {
        // Both axes are built alike; asking one asks both.
        self.velocity.rests()
    }

    /// Edges: fires a pulse on a crossing and owns the gate during the pulse and its rest.
    /// True while they own it (the window's texture is not asked).
    fn edges_step(
        &mut self,
        p: PointUm,
        velocity: Option<VelocityUmS>,
        t_us: u32,
        out: &mut Output2d,
    ) -> bool {
        let Some(active) = self.active.as_ref() else {
            return false;
        };
        let Some((edges, fire)) = active.scene.edges.as_ref() else {
            return false;
        };
        let (fire, limits) = (*fire, active.limits);
        let fired = self.edges.update(edges, p, edges.lead_um(velocity));
        if let Some(start) = self.edge_pulse_us {
            if t_us.wrapping_sub(start) < fire.window_us {
                if fired.is_some() {
                    self.telemetry.edges_skipped = self.telemetry.edges_skipped.wrapping_add(1);
                }
                return true;
            }
            self.edge_pulse_us = None;
        }
        let Some(edge) = fired else {
            return false;
        };
        let action = self.gate.pulse(fire.pulse, t_us, &self.timer, &limits);
        self.count_action(action);
        if !matches!(action, Some(GateAction::Pulse(_))) {
            // A burst runs, or the duty cap has no room: a pulse now would break it.
            self.telemetry.edges_skipped = self.telemetry.edges_skipped.wrapping_add(1);
            return false;
        }
        self.edge_pulse_us = Some(t_us);
        self.telemetry.edge_pulses = self.telemetry.edge_pulses.wrapping_add(1);
        out.action = action;
        out.edge = Some(edge);
        out.envelope = Some(fire.envelope);
        out.amplitude_permille = self.set_amplitude(fire.amplitude_permille);
        true
    }

    /// The window's texture asks; the gate answers within the caps.
    fn texture_step(
        &mut self,
        place: Place,
        p: PointUm,
        velocity: Option<VelocityUmS>,
        t_us: u32,
        out: &mut Output2d,
    ) {
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let limits = active.limits;
        let index = active.scene.screen.texture(place);
        let request = match active.scene.textures.get_mut(index as usize) {
            Some(PlaneCompiled::Oriented(o)) => {
                o.request(p, velocity, t_us, &self.gate, &self.timer)
            }
            Some(PlaneCompiled::Plain(c)) => {
                // The kinds a plain texture may be read only the speed (material, velocity
                // synthesis) or nothing (off, constant, random); never a position.
                let speed = velocity.map(|v| libm::roundf(v.speed_um_s()) as i32);
                c.request(&Moment {
                    position_um: 0,
                    velocity_um_s: speed,
                    t_us,
                    gate: &self.gate,
                    timer: &self.timer,
                })
            }
            None => Request::OFF,
        };
        if request.clamped {
            self.telemetry.clamped = self.telemetry.clamped.wrapping_add(1);
        }
        let mut skipped = request.skipped;
        out.action = match (request.want, request.settings) {
            (Want::Pulse, Some(s)) => {
                let action = self.gate.pulse(s, t_us, &self.timer, &limits);
                if matches!(action, Some(GateAction::Pulse(_))) {
                    self.telemetry.ridge_pulses = self.telemetry.ridge_pulses.wrapping_add(1);
                    out.envelope = Some(Envelope::Rectangular);
                } else {
                    skipped += 1;
                }
                self.count_action(action);
                action
            }
            (Want::EndPulse, _) => {
                let action = self.gate.end_pulse(t_us, &limits);
                self.count_action(action);
                action
            }
            _ => self.drive(request.settings, t_us, &limits),
        };
        self.telemetry.ridges_skipped = self.telemetry.ridges_skipped.wrapping_add(skipped);
        if request.amplitude != u16::MAX && request.amplitude != self.amplitude_asked {
            out.amplitude_permille = self.set_amplitude(request.amplitude);
        }
    }

    fn drive(
        &mut self,
        desired: Option<TimerSettings>,
        t_us: u32,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        if self.gate.quiet(desired, t_us) {
            return None;
        }
        let action = self.gate.request(desired, t_us, &self.timer, limits);
        self.count_action(action);
        action
    }

    /// Checks the stale watchdog at `now_us` (call it from a timer at least every few reading
    /// periods), and a new scene's caps against the burst the old one left running. Returns
    /// the off action when the line must stop.
    pub fn on_tick(&mut self, now_us: u32) -> Option<GateAction> {
        let active = self.active.as_ref()?;
        let (limits, stale_after_us) = (active.limits, active.stale_after_us);
        if core::mem::take(&mut self.caps_pending) {
            if let Some(r) = self.gate.running() {
                if !limits.allows(&self.timer, &r) {
                    let action = self.gate.force_off(now_us, &self.timer, &limits);
                    self.count_action(action);
                    return action;
                }
            }
        }
        let last = self.last_reading_us?;
        if now_us.wrapping_sub(last) > stale_after_us && self.fault != Some(TouchFault::Stale) {
            return self.enter_fault(TouchFault::Stale, now_us).action;
        }
        None
    }

    fn enter_fault(&mut self, fault: TouchFault, t_us: u32) -> Output2d {
        if self.fault != Some(fault) {
            self.telemetry.faults = self.telemetry.faults.wrapping_add(1);
            error!("touch fault {:?}: carrier off", fault);
        }
        self.fault = Some(fault);
        self.good_run = 0;
        let action = self.release(t_us, true);
        Output2d {
            action,
            fault: Some(fault),
            ..Output2d::default()
        }
    }

    /// Carrier off now, and the finger forgotten (its place, arming, textures; its motion
    /// too when `motion`): a lift, a landing, a fault.
    fn release(&mut self, t_us: u32, motion: bool) -> Option<GateAction> {
        self.forget_finger(motion);
        // A cut pulse's window means nothing more: the gate's ledger keeps the duty cap.
        self.edge_pulse_us = None;
        let limits = self.active.as_ref().map(|a| a.limits).unwrap_or_default();
        let action = self.gate.force_off(t_us, &self.timer, &limits);
        self.count_action(action);
        action
    }

    fn forget_finger(&mut self, motion: bool) {
        if motion {
            self.velocity.reset();
            self.resting = false;
        }
        // Lifted readings come every frame while nobody touches: forget once.
        if core::mem::replace(&mut self.forgotten, true) {
            return;
        }
        self.place = None;
        self.screen.reset();
        self.edges.reset();
        if let Some(a) = self.active.as_mut() {
            a.scene.textures.iter_mut().for_each(PlaneCompiled::reset);
        }
    }

    /// The level cap is the last word.
    fn set_amplitude(&mut self, permille: u16) -> Option<u16> {
        self.amplitude_asked = permille;
        let cap = self
            .active
            .as_ref()
            .map_or(1000, |a| a.limits.max_level_permille);
        let permille = permille.min(cap);
        (self.amplitude != Some(permille)).then(|| {
            self.amplitude = Some(permille);
            permille
        })
    }

    fn count_action(&mut self, action: Option<GateAction>) {
        if action.is_some() {
            self.telemetry.gate_actions = self.telemetry.gate_actions.wrapping_add(1);
        }
    }
}

/// Sends one output's changes to a burst port: drive mode, amplitude, envelope, then the line
/// (the 1D order).
pub fn apply2d<B: BurstOutput>(output: &Output2d, out: &mut B) {
    if let Some(mode) = output.drive {
        out.set_drive(mode);
    }
    if let Some(a) = output.amplitude_permille {
        out.set_amplitude(a);
    }
    if let Some(e) = output.envelope {
        out.set_envelope(e);
    }
    if let Some(action) = output.action {
        out.apply(action);
    }
}
