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
use super::velocity::{PlaneEstimator, PlaneLsq, VelocityUmS};
use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};
use crate::controller::{DEFAULT_WINDOW, RECOVERY_SAMPLES};
use crate::gate::{BurstOutput, DriveMode, Envelope, Gate, GateAction};
use crate::texture::compiled::{Moment, Need, Render, Request, Want};
use crate::texture::lines::MAX_LINE_LEAD_UM;
use crate::texture::FULL_AMPLITUDE;
use crate::touch::fault::AxisFault;
use crate::touch::frame::Reading;

/// Why the carrier is held off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// Edge crossings without a pulse: inside an edge's pulse and rest, a reading too late
    /// after the burst it stopped, or no room under the duty cap.
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
    /// Bit i: texture i (window i; the background's is the last) reads the velocity: the
    /// estimators update there, else rest (but near an edge, whose lead is the velocity).
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
        let update_mask = scene
            .textures
            .iter()
            .enumerate()
            .filter(|(_, t)| t.need() == Need::Velocity)
            .fold(0u16, |m, (i, _)| m | 1 << i);
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
pub struct Controller2d<V: PlaneEstimator = PlaneLsq<DEFAULT_WINDOW>> {
    timer: BurstTimer,
    sample_period_us: u32,
    active: Option<Prepared2d>,
    velocity: V,
    /// The estimators were rested on the last reading: woken before the next update.
    resting: bool,
    /// The texture in force reads the velocity: update, else rest (but in an edge's zone).
    update_velocity: bool,
    gate: Gate,
    screen: ScreenTracker,
    edges: EdgeTracker,
    /// The place rendered on the last reading (None: lifted, landing, faulty or new scene).
    place: Option<Place>,
    /// The texture index of `place`, looked up once when the place changes (the texture step
    /// reads it on every reading the window's texture renders).
    texture_index: u8,
    /// The settings the window's texture asks on every reading, when they never vary (off,
    /// constant; also a window without a texture): its texture step is then the gate's
    /// answer alone while the line already does them ([`Self::texture_step`]).
    fixed_settings: Option<Option<TimerSettings>>,
    /// Never take the short ways (a fixed texture's step, a pulse window's edge step) (tests:
    /// the reference for them).
    #[cfg(test)]
    no_short_ways: bool,
    /// Place, arming and textures were forgotten and nothing has rendered since.
    forgotten: bool,
    fault: Option<TouchFault>,
    good_run: u16,
    last_reading_us: Option<u32>,
    /// Start of the running edge pulse while in its pulse + rest window.
    edge_pulse_us: Option<u32>,
    /// A crossing whose texture's burst was stopped: its pulse goes out on the next reading.
    edge_pending: Option<PendingEdge>,
    /// The active scene's edge pulse + rest window, µs (0 without edges), copied at install.
    edge_window_us: u32,
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

impl<const N: usize> Controller2d<PlaneLsq<N>> {
    /// A controller with the default estimator (the 1D default on both axes, one clock) over
    /// an `N`-sample window.
    pub fn with_window(timer: BurstTimer, sample_period_us: u32) -> Result<Self, Config2dError> {
        let velocity = PlaneLsq::<N>::new(sample_period_us).map_err(Config2dError::Estimator)?;
        Ok(Self::with_estimators(timer, sample_period_us, velocity))
    }
}

impl<V: PlaneEstimator> Controller2d<V> {
    /// A controller with a chosen plane estimator (e.g. [`super::PlaneVelocity`] over any 1D
    /// estimator per axis), no scene (line off).
    pub fn with_estimators(timer: BurstTimer, sample_period_us: u32, velocity: V) -> Self {
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
            texture_index: 0,
            fixed_settings: None,
            #[cfg(test)]
            no_short_ways: false,
            forgotten: true,
            fault: None,
            good_run: 0,
            last_reading_us: None,
            edge_pulse_us: None,
            edge_pending: None,
            edge_window_us: 0,
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
        self.edge_window_us = prepared
            .scene
            .edges
            .as_ref()
            .map_or(0, |(_, f)| f.window_us);
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
    ///
    /// Inlined: every reading asks, and without a fault the answer is one compare; as a call it
    /// cost about 15 instructions a reading on the M4F (issue #36's profile).
    #[inline(always)]
    fn recover(&mut self, p: PointUm) -> bool {
        if self.fault.is_none() {
            return true;
        }
        self.count_recovery(p)
    }

    /// [`Self::recover`] under a fault: out of line, as faults are rare.
    #[cold]
    fn count_recovery(&mut self, p: PointUm) -> bool {
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
    ///
    /// Inlined into [`Self::on_reading`], so the `Output2d` is built where the caller wants it
    /// rather than returned through one more frame and copied (issue #36's profile).
    #[inline(always)]
    fn render(&mut self, p: PointUm, t_us: u32) -> Output2d {
        let Some(active) = self.active.as_ref() else {
            return Output2d::default();
        };
        let drive = core::mem::take(&mut self.drive_pending).then_some(active.scene.drive);
        self.forgotten = false;
        let (place, evaluated) = self.screen.track(&active.scene.screen, p);
        // Not evaluated, the place is the last reading's, which `self.place` holds: the tracker
        // is reset (and evaluates) whenever the controller forgets its place.
        if evaluated && self.place != Some(place) {
            self.note_place_change(place);
        }
        // The edges' position half first: the lead (the velocity) is read only when an armed
        // edge is within the longest lead of its line, where it could fire on this reading.
        let edges = self.active.as_ref().and_then(|a| a.scene.edges.as_ref());
        let lead_read = match edges {
            Some((edges, _)) => self.edges.locate(edges, p),
            None => false,
        };
        let velocity = if self.update_velocity || lead_read {
            if core::mem::take(&mut self.resting) {
                self.velocity.wake();
            }
            self.velocity.update(p, t_us)
        } else {
            self.velocity.rest(p, t_us);
            self.resting = true;
            None
        };
        // With the velocity known, the lead and the crossing test only where a lead of that
        // speed reaches an edge's line: most readings within the 2 mm cap are farther out.
        let lead_read = match edges {
            Some((edges, _)) if lead_read => self.edges.may_fire(edges, p, velocity),
            _ => false,
        };
        let mut out = Output2d {
            position: Some(p),
            velocity,
            place: Some(place),
            drive,
            ..Output2d::default()
        };
        if !self.edges_step(p, velocity, lead_read, t_us, &mut out) {
            self.texture_step(p, velocity, t_us, &mut out);
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
        self.texture_index = index;
        self.fixed_settings = match active.scene.textures.get(index as usize) {
            Some(t) => t.fixed_settings(),
            // `texture_step` asks nothing of a missing texture: off.
            None => Some(None),
        };
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
    ///
    /// A crossing preempts the window's texture: a running burst (or a ridge's pulse) is
    /// stopped through the gate on the reading that finds the crossing, and the edge's pulse
    /// goes out on the next reading ([`PendingEdge`]), the line low in between. The gate takes
    /// one action a reading and a `Pulse` only from off, so the stop costs one reading; the
    /// crossing is therefore looked for one reading's travel further ahead while the gate is
    /// busy ([`preempt_lead_um`]), and the pulse lands where it would over an off window.
    /// Skipped and counted (`edges_skipped`): a crossing inside an edge's pulse + rest, one
    /// whose next reading comes more than [`PENDING_READINGS`] periods after the stop, and a
    /// pulse the duty cap has no room for.
    ///
    /// `lead_read`: [`EdgeTracker::locate`] found an armed edge within the longest lead of its
    /// line on this reading; only then is the lead made and the crossing tested.
    #[inline(always)]
    fn edges_step(
        &mut self,
        p: PointUm,
        velocity: Option<VelocityUmS>,
        lead_read: bool,
        t_us: u32,
        out: &mut Output2d,
    ) -> bool {
        // Most readings: no edge within reach, no pulse window, no crossing pending. Nothing
        // below would act (no crossing to fire, none to carry): answered before the scene's
        // edges are looked up.
        #[cfg(not(test))]
        let short = true;
        #[cfg(test)]
        let short = !self.no_short_ways;
        if !lead_read && self.edge_pending.is_none() && short {
            match self.edge_pulse_us {
                None => return false,
                // Inside a pulse's pulse + rest window with no crossing to test or carry, the
                // edges own the line and do nothing more: answered here, not in `edges_act`
                // (about a third of a stroke's readings are in such a window).
                Some(start) if t_us.wrapping_sub(start) < self.edge_window_us => return true,
                Some(_) => {}
            }
        }
        self.edges_act(p, velocity, lead_read, t_us, out)
    }

    /// [`Self::edges_step`] on a reading where an edge may act: out of line.
    #[inline(never)]
    fn edges_act(
        &mut self,
        p: PointUm,
        velocity: Option<VelocityUmS>,
        lead_read: bool,
        t_us: u32,
        out: &mut Output2d,
    ) -> bool {
        let Some(active) = self.active.as_ref() else {
            return false;
        };
        let Some((edges, fire)) = active.scene.edges.as_ref() else {
            return false;
        };
        // The pulse's settings and the caps are copied out only for a pulse or a stop (most
        // readings have neither).
        let window_us = fire.window_us;
        let fired = if lead_read {
            let lead_um = edges.lead_um(velocity);
            let lead_um = if self.gate_busy(t_us) {
                preempt_lead_um(lead_um, velocity, self.sample_period_us)
            } else {
                lead_um
            };
            self.edges.fire(edges, p, lead_um)
        } else {
            None
        };
        if let Some(start) = self.edge_pulse_us {
            if t_us.wrapping_sub(start) < window_us {
                if fired.is_some() {
                    self.count_edge_skipped();
                }
                return true;
            }
            self.edge_pulse_us = None;
        }
        let edge = match (self.edge_pending.take(), fired) {
            (Some(pending), fired) => {
                let waited_us = t_us.wrapping_sub(pending.stopped_us);
                if waited_us > self.sample_period_us.saturating_mul(PENDING_READINGS) {
                    // A reading lost after the stop: the pulse would land that much late.
                    self.count_edge_skipped();
                    match fired {
                        Some(e) => e,
                        None => return false,
                    }
                } else {
                    if fired.is_some() {
                        // Another edge on the very next reading: one pulse for both.
                        self.count_edge_skipped();
                    }
                    pending.edge
                }
            }
            (None, Some(e)) => e,
            (None, None) => return false,
        };
        let Some((fire, limits)) = self
            .active
            .as_ref()
            .and_then(|a| Some((a.scene.edges.as_ref()?.1, a.limits)))
        else {
            return false;
        };
        if self.gate_busy(t_us) {
            // Stop the texture's burst (or ridge pulse) now: the gate records its on-time and
            // the line goes low at once (`GateAction::Off`); the pulse goes out next reading.
            let action = if self.gate.running().is_some() {
                self.gate.request(None, t_us, &self.timer, &limits)
            } else {
                self.gate.end_pulse(t_us, &limits)
            };
            self.count_action(action);
            if action.is_some() {
                self.edge_pending = Some(PendingEdge {
                    edge,
                    stopped_us: t_us,
                });
                out.action = action;
                return true;
            }
            // Nothing to stop after all (cannot happen: busy means running or a pulse on).
        }
        let action = self.gate.pulse(fire.pulse, t_us, &self.timer, &limits);
        self.count_action(action);
        if !matches!(action, Some(GateAction::Pulse(_))) {
            // The duty cap has no room: a pulse now would break it. The texture takes over.
            self.count_edge_skipped();
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

    /// True when the line is busy with a texture: a periodic burst, or a one-pulse still on
    /// (an ended one is caught up by the next gate call: not busy).
    fn gate_busy(&self, t_us: u32) -> bool {
        self.gate.running().is_some() || (!self.gate.steady(None) && self.gate.quiet(None, t_us))
    }

    fn count_edge_skipped(&mut self) {
        self.telemetry.edges_skipped = self.telemetry.edges_skipped.wrapping_add(1);
    }

    /// The window's texture asks; the gate answers within the caps. The window is the last
    /// place noted ([`Self::note_place_change`] keeps its texture index).
    fn texture_step(
        &mut self,
        p: PointUm,
        velocity: Option<VelocityUmS>,
        t_us: u32,
        out: &mut Output2d,
    ) {
        // An off or constant window asks the same on every reading (`Request::OFF` with its
        // settings): no clamp, nothing skipped, the full amplitude. Once that amplitude is
        // asked and the line does those settings (or a one-pulse is still on), the steps
        // below change nothing and send nothing (issue #36: most of a reading over such a
        // window).
        #[cfg(not(test))]
        let fixed = self.fixed_settings;
        #[cfg(test)]
        let fixed = self.fixed_settings.filter(|_| !self.no_short_ways);
        if let Some(settings) = fixed {
            if self.amplitude_asked == FULL_AMPLITUDE && self.gate.quiet(settings, t_us) {
                return;
            }
        }
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let limits = active.limits;
        let request = match active.scene.textures.get_mut(self.texture_index as usize) {
            Some(PlaneCompiled::Oriented(o)) => {
                o.request(p, velocity, t_us, &self.gate, &self.timer)
            }
            Some(PlaneCompiled::Plain(c)) => {
                // The kinds a plain texture may be read only the speed (material, velocity
                // synthesis) or nothing (off, constant, random); never a position. The speed
                // (a root and a rounding) is made only for a kind that reads it: near an edge
                // the velocity is there for the lead, over windows that ignore it.
                let speed = match c.need() {
                    Need::Velocity => {
                        velocity.map(|v| super::geometry::round_to_i32(v.speed_um_s()))
                    }
                    Need::Position | Need::OwnFit => None,
                };
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
        self.edge_pending = None;
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

/// An edge crossing waiting for its pulse: the texture's burst was stopped at `stopped_us`.
#[derive(Clone, Copy, Debug)]
struct PendingEdge {
    edge: u8,
    stopped_us: u32,
}

/// A pending crossing fires on the next reading if it comes within this many sample periods of
/// the stop, else it is skipped: each period later puts the pulse one more period's travel
/// past its target (the bound docs/plane.md states allows one).
const PENDING_READINGS: u32 = 2;

/// The lead while a burst must first be stopped: one more sample period's travel (the stop's
/// reading), at most [`MAX_LINE_LEAD_UM`] long, as every lead.
fn preempt_lead_um(
    lead_um: (f32, f32),
    velocity: Option<VelocityUmS>,
    sample_period_us: u32,
) -> (f32, f32) {
    let Some(v) = velocity else {
        return lead_um;
    };
    let period_s = sample_period_us as f32 * 1e-6;
    let (x, y) = (
        lead_um.0 + v.vx_um_s as f32 * period_s,
        lead_um.1 + v.vy_um_s as f32 * period_s,
    );
    // The FPU's root (correctly rounded: libm's bits).
    let len = super::geometry::sqrt_f32(x * x + y * y);
    let max = MAX_LINE_LEAD_UM as f32;
    if len > max {
        (x * max / len, y * max / len)
    } else {
        (x, y)
    }
}

/// Sends one output's changes to a burst port: drive mode, amplitude, envelope, then the line
/// (the 1D order).
pub fn apply2d<B: BurstOutput>(output: &Output2d, out: &mut B) {
    out.send(
        output.drive,
        output.amplitude_permille,
        output.envelope,
        output.action,
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::{BurstError, TEST_TIMER};
    use crate::plane::edges::EdgeError;
    use crate::plane::geometry::{Polygon, SegmentUm};
    use crate::plane::grating::OrientedGrating;
    use crate::plane::scene::{Owner, PlaneTexture, Window2d};
    use crate::plane::testing::{sigma_um, Noise, PERIOD_US};
    use crate::position::SensorFault;
    use crate::texture::{Grating, GratingRender, Material, Texture};
    use crate::touch::fault::Axis;
    use std::string::ToString;
    use std::vec::Vec as StdVec;

    fn rect(x0: i32, y0: i32, x1: i32, y1: i32) -> Polygon {
        Polygon::rectangle(PointUm::new(x0, y0), PointUm::new(x1, y1)).unwrap()
    }

    fn window(outline: Polygon, texture: PlaneTexture, edge: bool) -> Window2d {
        Window2d {
            outline,
            texture,
            edge,
        }
    }

    fn hz(hz: u32) -> PlaneTexture {
        PlaneTexture::Plain(Texture::constant_hz(hz))
    }

    const OFF: PlaneTexture = PlaneTexture::Plain(Texture::Off);

    fn config(windows: &[Window2d]) -> Config2d {
        let mut c = Config2d::default();
        for w in windows {
            c.scene.windows.push(w.clone()).unwrap();
        }
        c
    }

    fn loaded(cfg: &Config2d) -> Controller2d {
        let mut c = Controller2d::new(TEST_TIMER, PERIOD_US).unwrap();
        c.load(cfg).unwrap();
        c
    }

    fn down(p: PointUm) -> Reading {
        Reading::Down {
            x_um: p.x_um,
            y_um: p.y_um,
            r_touch_ohm: 500,
        }
    }

    /// Feeds the same readings to a controller and its reference (each with its clock) and
    /// asserts they answer alike, reading by reading, and count alike; the outputs.
    fn feed_alike(
        (c, tc): (&mut Controller2d, &mut u32),
        (r, tr): (&mut Controller2d, &mut u32),
        readings: &[Reading],
        what: &str,
    ) -> StdVec<Output2d> {
        let oc = feed(c, tc, readings.iter().copied());
        let or = feed(r, tr, readings.iter().copied());
        for k in 0..oc.len() {
            assert_eq!(oc[k], or[k], "{what}, reading {k}");
        }
        assert_eq!(c.telemetry(), r.telemetry(), "{what}");
        oc
    }

    /// Feeds readings one period apart from `*t`; returns every output.
    fn feed(
        c: &mut Controller2d,
        t: &mut u32,
        readings: impl IntoIterator<Item = Reading>,
    ) -> StdVec<Output2d> {
        readings
            .into_iter()
            .map(|r| {
                let out = c.on_reading(*t, r);
                *t += PERIOD_US;
                out
            })
            .collect()
    }

    fn at(p: PointUm, n: usize) -> impl Iterator<Item = Reading> {
        core::iter::repeat_n(down(p), n)
    }

    /// A straight stroke from `a` to `b` at `v_mm_s` (one reading per period), with `sigma`
    /// µm RMS of noise per axis.
    fn stroke(
        a: (f64, f64),
        b: (f64, f64),
        v_mm_s: f64,
        sigma: f64,
        noise: &mut Noise,
    ) -> StdVec<Reading> {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let step = v_mm_s * PERIOD_US as f64 / 1000.0;
        let n = (len / step).ceil() as usize;
        (0..=n)
            .map(|k| {
                let f = (k as f64 * step / len).min(1.0);
                down(PointUm::new(
                    (a.0 + f * (b.0 - a.0) + noise.gauss() * sigma).round() as i32,
                    (a.1 + f * (b.1 - a.1) + noise.gauss() * sigma).round() as i32,
                ))
            })
            .collect()
    }

    fn millihz(s: TimerSettings) -> u64 {
        s.produced_millihz(TEST_TIMER.clock_hz)
    }

    fn pulses(outs: &[Output2d]) -> usize {
        outs.iter()
            .filter(|o| matches!(o.action, Some(GateAction::Pulse(_))))
            .count()
    }

    /// Lift-off turns the carrier off on the very reading that says so, counts no fault, and
    /// the next touch-down renders again. (Seen failing with the lift's `force_off` removed:
    /// the reading carried no action and the 1 kHz burst ran on.)
    #[test]
    fn lift_off_turns_the_carrier_off_on_that_reading() {
        let mut c = loaded(&config(&[window(
            rect(0, 0, 20_000, 20_000),
            hz(1_000),
            false,
        )]));
        let mut t = 0;
        let outs = feed(&mut c, &mut t, at(PointUm::new(10_000, 10_000), 50));
        let Some(GateAction::Start(s)) = outs[0].action else {
            panic!("{:?}", outs[0])
        };
        assert_eq!(millihz(s), 1_000_000);
        let out = c.on_reading(t, Reading::Lifted);
        assert_eq!(out.action, Some(GateAction::Off));
        assert_eq!(out.fault, None);
        assert_eq!((out.position, out.place), (None, None));
        let tm = c.telemetry();
        assert_eq!((tm.faults, tm.lifts), (0, 1));
        // Still lifted: nothing more to do.
        t += PERIOD_US;
        assert_eq!(c.on_reading(t, Reading::Lifted).action, None);
        // Landing is off too, with the position; the touch-down renders again.
        t += PERIOD_US;
        let out = c.on_reading(
            t,
            Reading::Landing {
                x_um: 10_000,
                y_um: 10_000,
            },
        );
        assert_eq!(
            (out.action, out.position),
            (None, Some(PointUm::new(10_000, 10_000)))
        );
        t += PERIOD_US;
        let out = c.on_reading(t, down(PointUm::new(10_000, 10_000)));
        assert!(matches!(out.action, Some(GateAction::Start(_))), "{out:?}");
        // A lift while a burst runs and a landing reading (pressure eased) both cut it.
        t += PERIOD_US;
        let out = c.on_reading(
            t,
            Reading::Landing {
                x_um: 10_000,
                y_um: 10_000,
            },
        );
        assert_eq!(out.action, Some(GateAction::Off));
        assert_eq!(c.telemetry().faults, 0);
    }

    /// Two windows sharing an edge, 20 Hz and 80 Hz: a stroke across at 100 mm/s switches
    /// on the first reading band/2 past the edge, and that reading updates the burst to the
    /// new window's 80 Hz (TEST_TIMER divides both exactly); back across, 20 Hz again.
    #[test]
    fn a_window_switch_brings_the_new_windows_burst_frequency() {
        let mut c = loaded(&config(&[
            window(rect(0, 0, 20_000, 20_000), hz(20), false),
            window(rect(20_000, 0, 40_000, 20_000), hz(80), false),
        ]));
        let mut t = 0;
        let outs = feed(&mut c, &mut t, at(PointUm::new(10_000, 10_000), 10));
        assert!(matches!(outs[0].action, Some(GateAction::Start(s)) if millihz(s) == 20_000));
        let mut noise = Noise::new(1);
        for (from, to, want_place, want_mhz, past) in [
            (10_000.0, 30_000.0, 1, 80_000, 1),
            (30_000.0, 10_000.0, 0, 20_000, -1),
        ] {
            let outs = feed(
                &mut c,
                &mut t,
                stroke((from, 10_000.0), (to, 10_000.0), 100.0, 0.0, &mut noise),
            );
            let k = outs
                .iter()
                .position(|o| o.place == Some(Place::Window(want_place)))
                .unwrap();
            // band/2 = 100 µm past the shared edge (leaving window 0: more than band/2 out;
            // entering it from below: at least band/2 in), within one reading's 10 µm.
            let x = outs[k].position.unwrap().x_um;
            let beyond = (x - 20_000) * past;
            assert!((100..=110).contains(&beyond), "switched at {x} um");
            let Some(GateAction::Update(s)) = outs[k].action else {
                panic!("{:?}", outs[k])
            };
            assert_eq!(millihz(s), want_mhz);
            assert_eq!(c.gate.running().map(millihz), Some(want_mhz));
        }
        assert_eq!(c.telemetry().window_switches, 2);
    }

    /// Edge scene: off everywhere, a vertical free segment at x = 20 mm and an off window
    /// whose outline pulses.
    fn edge_scene() -> Config2d {
        let mut cfg = config(&[window(rect(40_000, 0, 60_000, 20_000), OFF, true)]);
        cfg.scene
            .free_edges
            .push(SegmentUm {
                a: PointUm::new(20_000, 0),
                b: PointUm::new(20_000, 40_000),
            })
            .unwrap();
        cfg
    }

    /// A crossing fires exactly one pulse through the gate, ahead of the edge by the lead
    /// (v × (5 ms + 50 µs) = 505 µm at 100 mm/s, so the triangle's peak lands on it), in
    /// both directions, across the free segment and a window's outline (edge 0 is its first
    /// side; the free segment comes after the outline's four). 2 LSB noise.
    #[test]
    fn an_edge_crossing_fires_exactly_one_pulse() {
        let mut noise = Noise::new(7);
        let sigma = sigma_um(2.0);
        for (from, to, edge, line) in [
            (15_000.0, 25_000.0, 4, 20_000.0),
            (25_000.0, 15_000.0, 4, 20_000.0),
            (35_000.0, 45_000.0, 3, 40_000.0),
            (45_000.0, 35_000.0, 3, 40_000.0),
        ] {
            let mut c = loaded(&edge_scene());
            let mut t = 0;
            let outs = feed(
                &mut c,
                &mut t,
                stroke((from, 10_000.0), (to, 10_000.0), 100.0, sigma, &mut noise),
            );
            assert_eq!(pulses(&outs), 1, "{from} → {to}");
            let fired: StdVec<_> = outs.iter().filter(|o| o.edge.is_some()).collect();
            assert_eq!(fired.len(), 1);
            assert_eq!(fired[0].edge, Some(edge));
            assert_eq!(fired[0].envelope, Some(Envelope::Triangular));
            let x = fired[0].position.unwrap().x_um as f64;
            let ahead = (line - x) * (to - from).signum();
            assert!((400.0..620.0).contains(&ahead), "fired {ahead} um ahead");
            assert_eq!(c.telemetry().edge_pulses, 1);
        }
    }

    /// A finger resting on an edge with 3 LSB of noise (12 µm RMS per axis) for 10 s fires
    /// nothing, whether it landed there or slid there (the slide's own crossing fires once).
    /// (Seen failing with the edge tracker's re-arm distance cut to 10 µm: the noise fires it.)
    #[test]
    fn a_resting_finger_on_an_edge_fires_nothing() {
        let sigma = sigma_um(3.0);
        let mut noise = Noise::new(11);
        let mut c = loaded(&edge_scene());
        let mut t = 0;
        let rest = |c: &mut Controller2d, t: &mut u32, noise: &mut Noise| {
            let readings: StdVec<_> = (0..100_000)
                .map(|_| {
                    down(PointUm::new(
                        (20_000.0 + noise.gauss() * sigma).round() as i32,
                        (10_000.0 + noise.gauss() * sigma).round() as i32,
                    ))
                })
                .collect();
            pulses(&feed(c, t, readings))
        };
        assert_eq!(rest(&mut c, &mut t, &mut noise), 0, "landed on it");
        // Lift, touch down 1 mm away, slide onto the edge at 50 mm/s and stay.
        let _ = c.on_reading(t, Reading::Lifted);
        let slide = stroke(
            (19_000.0, 10_000.0),
            (20_000.0, 10_000.0),
            50.0,
            sigma,
            &mut noise,
        );
        assert_eq!(
            pulses(&feed(&mut c, &mut t, slide)),
            1,
            "the slide's crossing"
        );
        assert_eq!(rest(&mut c, &mut t, &mut noise), 0, "slid onto it");
    }

    /// A refused scene changes nothing: the running burst goes on untouched (no action, and
    /// no drive mode re-sent, which an install would send), whichever part refused it — the
    /// first texture, a late part (the edges, after every texture compiled), the stale limit.
    #[test]
    fn a_bad_scene_is_refused_and_the_previous_kept() {
        let good = config(&[window(rect(0, 0, 20_000, 20_000), hz(20), false)]);
        let mut c = loaded(&good);
        let mut t = 0;
        let outs = feed(&mut c, &mut t, at(PointUm::new(10_000, 10_000), 3));
        assert!(outs[0].drive.is_some());
        assert!(matches!(outs[0].action, Some(GateAction::Start(s)) if millihz(s) == 20_000));
        let mut grating = good.clone();
        grating.scene.windows[0].texture =
            PlaneTexture::Plain(Texture::Grating(Grating::new(1_000)));
        let mut long_pulse = edge_scene();
        long_pulse.scene.edge_pulse.pulse_us = 60_000;
        let mut stale = good.clone();
        stale.stale_after_us = 100;
        let mut normal = good.clone();
        normal.scene.background = PlaneTexture::Oriented(OrientedGrating {
            grating: Grating::new(1_000),
            normal: (0, 0),
        });
        let mut band = good.clone();
        band.scene.band_um = 0;
        for (bad, want, sentence) in [
            (
                grating,
                Config2dError::GratingNeedsNormal {
                    owner: Owner::Window(0),
                },
                "window 0: a position-phase or hybrid grating needs the ridges' normal in the \
                 plane: give it as an oriented grating",
            ),
            (
                long_pulse,
                Config2dError::Edges(EdgeError::Pulse {
                    pulse_us: 60_000,
                    max_on_time_us: 50_000,
                }),
                "edge pulse 60 ms must be above 0 ms and at most the on-time cap of 50 ms",
            ),
            (
                stale,
                Config2dError::StaleLimit {
                    stale_after_us: 100,
                    min_us: 200,
                },
                "stale limit 0.1 ms must be at least two sample periods (0.2 ms) and at most \
                 1000 ms",
            ),
            (
                normal,
                Config2dError::Oriented {
                    owner: Owner::Background,
                    error: OrientedError::Normal { x: 0, y: 0 },
                },
                "the background: grating normal (0, 0) must be non-zero with components within \
                 ±1000000",
            ),
            (
                band,
                Config2dError::Screen(crate::plane::screen::ScreenError::Band { band_um: 0 }),
                "band 0 mm is outside 0.001 mm to 10 mm",
            ),
        ] {
            let e = c.load(&bad).unwrap_err();
            assert_eq!(e, want);
            assert_eq!(e.to_string(), sentence);
            let outs = feed(&mut c, &mut t, at(PointUm::new(10_000, 10_000), 3));
            assert!(
                outs.iter().all(|o| o.action.is_none() && o.drive.is_none()),
                "{want:?}: {outs:?}"
            );
            assert_eq!(c.gate.running().map(millihz), Some(20_000));
        }
        // The refusal's own burst error path names its owner too.
        let mut fast = good.clone();
        fast.scene.windows[0].texture = hz(6_000);
        assert!(matches!(
            c.load(&fast),
            Err(Config2dError::Burst {
                owner: Owner::Window(0),
                error: BurstError::AboveBoardLimit { .. }
            })
        ));
    }

    use crate::plane::grating::OrientedError;

    /// A rail fault: off on that reading and counted once; the carrier comes back after
    /// RECOVERY_SAMPLES pressed fault-free readings in a row, and a lift in between starts
    /// the run again. A stale sensor (no reading for the limit) is a fault too, from on_tick.
    #[test]
    fn faults_stop_the_carrier_and_recover_by_the_1d_rule() {
        let mut c = loaded(&config(&[window(
            rect(0, 0, 20_000, 20_000),
            hz(1_000),
            false,
        )]));
        let mut t = 0;
        let p = PointUm::new(10_000, 10_000);
        feed(&mut c, &mut t, at(p, 10));
        let rail = TouchFault::Rail(AxisFault {
            axis: Axis::X,
            fault: SensorFault::RailLow,
        });
        let fault = Reading::Fault(AxisFault {
            axis: Axis::X,
            fault: SensorFault::RailLow,
        });
        let outs = feed(&mut c, &mut t, [fault, fault]);
        assert_eq!(outs[0].action, Some(GateAction::Off));
        assert_eq!((outs[0].fault, outs[1].fault), (Some(rail), Some(rail)));
        assert_eq!(c.telemetry().faults, 1);
        let n = RECOVERY_SAMPLES as usize;
        let outs = feed(&mut c, &mut t, at(p, n - 1));
        assert!(outs
            .iter()
            .all(|o| o.action.is_none() && o.fault == Some(rail)));
        // A lift: the run starts over.
        feed(&mut c, &mut t, [Reading::Lifted]);
        let outs = feed(&mut c, &mut t, at(p, n));
        assert!(outs[..n - 1].iter().all(|o| o.action.is_none()));
        assert_eq!(outs[n - 1].fault, None);
        assert!(matches!(outs[n - 1].action, Some(GateAction::Start(_))));
        // Stale: quiet for the limit is fine, a µs more is not.
        let last = t - PERIOD_US;
        assert_eq!(c.on_tick(last + 5_000), None);
        assert_eq!(c.on_tick(last + 5_001), Some(GateAction::Off));
        assert_eq!(c.fault(), Some(TouchFault::Stale));
        assert_eq!(c.on_tick(last + 9_000), None);
        assert_eq!(c.telemetry().faults, 2);
    }

    /// Per kind: a velocity-synthesis grating given plain reads |V| (a diagonal stroke at
    /// 100 mm/s over λ = 1 mm runs at 100 Hz, though each axis moves at 70.7 mm/s); an
    /// oriented position-phase grating fires one pulse per ridge crossed along its normal and
    /// none moving along its ridges.
    #[test]
    fn plain_kinds_read_the_speed_and_oriented_gratings_the_projection() {
        let mut synth = Grating::new(1_000);
        synth.render = GratingRender::VelocitySynthesis;
        let mut c = loaded(&config(&[window(
            rect(0, 0, 40_000, 40_000),
            PlaneTexture::Plain(Texture::Grating(synth)),
            false,
        )]));
        let mut t = 0;
        let mut noise = Noise::new(3);
        feed(
            &mut c,
            &mut t,
            stroke(
                (5_000.0, 5_000.0),
                (25_000.0, 25_000.0),
                100.0,
                0.0,
                &mut noise,
            ),
        );
        let f = c.gate.running().map(millihz).unwrap() as f64;
        assert!((f - 100_000.0).abs() < 2_000.0, "{f} mHz");

        let oriented = PlaneTexture::Oriented(OrientedGrating {
            grating: Grating::new(1_000),
            normal: (1, 0),
        });
        let mut c = loaded(&config(&[window(
            rect(0, 0, 40_000, 40_000),
            oriented,
            false,
        )]));
        let mut t = 0;
        // Across the ridges: 10 mm, from 5.5 to 15.5 mm, ten ridges (6 … 15 mm).
        let across = feed(
            &mut c,
            &mut t,
            stroke(
                (5_500.0, 5_000.0),
                (15_500.0, 5_000.0),
                50.0,
                0.0,
                &mut noise,
            ),
        );
        assert_eq!(pulses(&across), 10);
        // Along them: 10 mm of y at x = 15.5 mm, none.
        let along = feed(
            &mut c,
            &mut t,
            stroke(
                (15_500.0, 5_000.0),
                (15_500.0, 15_000.0),
                50.0,
                0.0,
                &mut noise,
            ),
        );
        assert_eq!(pulses(&along), 0);
    }

    /// Per reading only what the scene needs: the estimators rest in a constant window (no
    /// velocity reported) and update in a material window; an edge adds them only where it
    /// could fire on that reading (armed, within the 2 mm lead cap of its line). Resting
    /// changes no burst.
    #[test]
    fn the_velocity_is_computed_only_where_the_scene_reads_it() {
        let material = PlaneTexture::Plain(Texture::Material(Material::fig5(0.3)));
        let windows = [
            window(rect(0, 0, 20_000, 20_000), hz(80), false),
            window(rect(20_000, 0, 40_000, 20_000), material, false),
        ];
        let mut noise = Noise::new(5);
        let s = stroke(
            (5_000.0, 10_000.0),
            (35_000.0, 10_000.0),
            100.0,
            0.0,
            &mut noise,
        );
        let mut c = loaded(&config(&windows));
        let mut t = 0;
        let outs = feed(&mut c, &mut t, s.iter().copied());
        for o in &outs[40..] {
            match o.place {
                Some(Place::Window(0)) => assert_eq!(o.velocity, None),
                Some(Place::Window(1)) => assert!(o.velocity.is_some(), "{o:?}"),
                p => panic!("{p:?}"),
            }
        }
        // The material window's first reading has its velocity at once (woken, not
        // restarted), and it is the stroke's 100 mm/s.
        let first = outs
            .iter()
            .find(|o| o.place == Some(Place::Window(1)))
            .unwrap();
        assert_eq!(
            first.velocity.map(|v| v.vx_um_s / 1_000),
            Some(100),
            "{first:?}"
        );
        // An edge across the constant window at x = 10 mm.
        let mut with_edge = config(&windows);
        with_edge
            .scene
            .free_edges
            .push(SegmentUm {
                a: PointUm::new(10_000, 0),
                b: PointUm::new(10_000, 20_000),
            })
            .unwrap();
        let mut e = loaded(&with_edge);
        let mut t = 0;
        let outs_e = feed(&mut e, &mut t, s.iter().copied());
        // The edge reads the lead (the velocity) only where it could fire: armed, and within
        // the longest lead (2 mm) of its line. Coming from the left it is armed on its left
        // from the start; it fires (the burst is stopped) 0.5 mm short of the line and is
        // disarmed; past the line it re-arms once 100 µm clear on the right. So in the
        // constant window the velocity is there on two runs of readings: from x = 8 mm (2 mm
        // and the 1 µm of rounding allowed) to the reading that finds the crossing, and from
        // the reading after the re-arm (10.1 mm) to 12 mm; nowhere else.
        let x = |k: usize| outs_e[k].position.unwrap().x_um;
        let mut runs: StdVec<(usize, usize)> = StdVec::new();
        for k in 40..outs_e.len() {
            let o = &outs_e[k];
            if o.place == Some(Place::Window(1)) {
                assert!(o.velocity.is_some(), "reading {k}: {o:?}");
                continue;
            }
            if o.velocity.is_some() {
                match runs.last_mut() {
                    Some(r) if r.1 + 1 == k => r.1 = k,
                    _ => runs.push((k, k)),
                }
            }
        }
        assert_eq!(runs.len(), 2, "{runs:?}");
        let (approach, past) = (runs[0], runs[1]);
        assert!(x(approach.0) >= 7_999 && x(approach.0 - 1) < 7_999);
        assert_eq!(outs_e[approach.1].action, Some(GateAction::Off));
        // The reading that re-arms it tests no crossing (the crossing is tested before the
        // re-arm, as in 1D lines): the lead is read from the next one.
        assert!(x(past.0 - 1) > 10_100 && x(past.0 - 2) <= 10_100);
        assert!(x(past.1) <= 12_001 && x(past.1 + 1) > 12_001);
        std::println!(
            "velocity read from x = {} to {} µm (the stop) and from {} to {} µm",
            x(approach.0),
            x(approach.1),
            x(past.0),
            x(past.1)
        );
        // The same bursts either way, but for the edge's preemption: the 80 Hz burst stopped,
        // the edge's pulse on the next reading, the same burst started again after its rest.
        let actions = |o: &[Output2d]| o.iter().map(|o| o.action).collect::<StdVec<_>>();
        let (plain, mut edged) = (actions(&outs), actions(&outs_e));
        let stop = edged
            .iter()
            .position(|a| *a == Some(GateAction::Off))
            .unwrap();
        assert!(matches!(edged[stop + 1], Some(GateAction::Pulse(_))));
        let restart = stop + 2 + edged[stop + 2..].iter().position(Option::is_some).unwrap();
        assert_eq!(edged[restart], plain[0]);
        edged[stop..=restart].fill(None);
        assert_eq!(plain, edged);
        let tm = e.telemetry();
        assert_eq!((tm.edge_pulses, tm.edges_skipped), (1, 0));
    }

    /// With the touch sensor in front: after a rail fault the carrier comes back on the
    /// sensor's own touch-down, the 16th pressed frame, not 16 readings after it (the
    /// controller counts the landing run towards its recovery; seen failing when it did not:
    /// the 16th frame still faulty). Frames are the hand-worked 1 000 Ω network of
    /// touch::frame's tests.
    #[test]
    fn behind_the_touch_sensor_a_fault_recovers_on_its_touch_down() {
        use crate::touch::calibration::{Affine, CalPoint};
        use crate::touch::fault::RailBands;
        use crate::touch::frame::{Frame, TouchSensor};
        use crate::touch::pressure::PressureConfig;
        let p = |x_code, y_code, x_um, y_um| CalPoint {
            x_code,
            y_code,
            x_um,
            y_um,
        };
        let map = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 50_000, 0, 40_000),
            ],
            &RailBands::default(),
        )
        .unwrap();
        let pressure = PressureConfig {
            r_x_plate_ohm: 600,
            ..PressureConfig::DEFAULT
        };
        let mut sensor = TouchSensor::new(pressure, RailBands::default(), map).unwrap();
        let pressed = Frame {
            x_code: 16_384,
            y_code: 30_000,
            z1_code: 7_282,
            z2_code: 55_826,
            t_us: 0,
        };
        let rail = Frame {
            y_code: 65_000,
            ..pressed
        };
        // The finger lands at (6.384, 20) mm: inside a 1 kHz window.
        let mut c = loaded(&config(&[window(
            rect(0, 0, 40_000, 40_000),
            hz(1_000),
            false,
        )]));
        let mut t = 0;
        let mut run = |c: &mut Controller2d, f: &Frame| {
            t += PERIOD_US;
            c.on_reading(t, sensor.on_frame(f))
        };
        let n = RECOVERY_SAMPLES as usize;
        let first: StdVec<_> = (0..n).map(|_| run(&mut c, &pressed)).collect();
        assert!(first[..n - 1].iter().all(|o| o.action.is_none()));
        assert!(matches!(first[n - 1].action, Some(GateAction::Start(_))));
        assert_eq!(run(&mut c, &rail).action, Some(GateAction::Off));
        let again: StdVec<_> = (0..n).map(|_| run(&mut c, &pressed)).collect();
        assert!(again[..n - 1]
            .iter()
            .all(|o| o.action.is_none() && o.fault.is_some()));
        assert_eq!(again[n - 1].fault, None);
        assert!(matches!(again[n - 1].action, Some(GateAction::Start(_))));
    }

    /// A lift forgets the place even where the screen would answer without evaluating: a
    /// finger lifted and landed again on the very point, inside a window, counts a second lift
    /// (the controller holds its place again) and renders the window's burst again. (Seen
    /// failing with the screen tracker not reset on a lift: the tracker's fast path answered
    /// the old place unevaluated, the controller's place stayed None, the second lift went
    /// uncounted: 1 lift.)
    #[test]
    fn a_landing_on_the_lifted_point_places_the_finger_again() {
        let mut c = loaded(&config(&[window(
            rect(0, 0, 20_000, 20_000),
            hz(80),
            false,
        )]));
        let p = PointUm::new(10_000, 10_000);
        let mut t = 0;
        for _ in 0..2 {
            let outs = feed(&mut c, &mut t, (0..50).map(|_| down(p)));
            assert!(outs.iter().all(|o| o.place == Some(Place::Window(0))));
            assert!(outs
                .iter()
                .any(|o| matches!(o.action, Some(GateAction::Start(_)))));
            feed(&mut c, &mut t, [Reading::Lifted]);
            feed(
                &mut c,
                &mut t,
                [Reading::Landing {
                    x_um: p.x_um,
                    y_um: p.y_um,
                }],
            );
        }
        assert_eq!(c.telemetry().lifts, 2);
    }

    /// A window's texture starts afresh on entry: an oriented grating (normal (1, 1), λ =
    /// 1 mm) left at (20.1, 5) mm and entered again at (19.9, 15) mm, after a trip through
    /// an off window, fires exactly one pulse per ridge crossed inside it after the entry
    /// (r·n from 24.68 to 18.03 mm: the six ridges 24 … 19 mm), with no crossing skipped.
    /// (Seen failing without the reset on a window change: 7 pulses, one for the 6.9 mm jump
    /// of r·n between exit and entry, which no finger crossed inside the window.)
    #[test]
    fn a_window_change_resets_the_new_windows_texture() {
        let oriented = PlaneTexture::Oriented(OrientedGrating {
            grating: Grating::new(1_000),
            normal: (1, 1),
        });
        let mut c = loaded(&config(&[
            window(rect(0, 0, 20_000, 20_000), oriented, false),
            window(rect(20_000, 0, 40_000, 20_000), OFF, false),
        ]));
        let mut t = 0;
        let mut noise = Noise::new(2);
        let mut go = |c: &mut Controller2d, a: (f64, f64), b: (f64, f64)| {
            feed(c, &mut t, stroke(a, b, 50.0, 0.0, &mut noise))
        };
        go(&mut c, (10_000.0, 5_000.0), (30_000.0, 5_000.0));
        go(&mut c, (30_000.0, 5_000.0), (30_000.0, 15_000.0));
        let skipped = c.telemetry().ridges_skipped;
        let back = go(&mut c, (30_000.0, 15_000.0), (10_500.0, 15_000.0));
        let entry = back
            .iter()
            .position(|o| o.place == Some(Place::Window(0)))
            .unwrap();
        assert_eq!(back[entry].position, Some(PointUm::new(19_900, 15_000)));
        assert_eq!(pulses(&back[..entry]), 0);
        let n = core::f64::consts::FRAC_1_SQRT_2;
        let (from, to) = ((19_900.0 + 15_000.0) * n, (10_500.0 + 15_000.0) * n);
        let ridges = (from / 1_000.0).floor() as usize - (to / 1_000.0).floor() as usize;
        assert_eq!(ridges, 6);
        assert_eq!(pulses(&back[entry..]), ridges);
        assert_eq!(c.telemetry().ridges_skipped, skipped);
    }

    /// Preemption scene: a constant 80 Hz window, (40, 20)–(60, 40) mm, whose outline pulses
    /// (sides from the lower-left corner: bottom 0, right 1, top 2, left 3), over a constant
    /// 1 kHz background: a burst runs on both sides of every side.
    fn textured_edge_scene() -> Config2d {
        let mut cfg = config(&[window(rect(40_000, 20_000, 60_000, 40_000), hz(80), true)]);
        cfg.scene.background = hz(1_000);
        cfg
    }

    /// A straight stroke as [`stroke`], with each reading's true position and its noise, µm.
    fn stroke_truth(
        a: (f64, f64),
        b: (f64, f64),
        v_mm_s: f64,
        sigma: f64,
        noise: &mut Noise,
    ) -> StdVec<(Reading, (f64, f64), (f64, f64))> {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let step = v_mm_s * PERIOD_US as f64 / 1000.0;
        let n = (len / step).ceil() as usize;
        (0..=n)
            .map(|k| {
                let f = (k as f64 * step / len).min(1.0);
                let truth = (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1));
                let e = (noise.gauss() * sigma, noise.gauss() * sigma);
                let r = down(PointUm::new(
                    (truth.0 + e.0).round() as i32,
                    (truth.1 + e.1).round() as i32,
                ));
                (r, truth, e)
            })
            .collect()
    }

    /// Over running bursts (1 kHz outside, 80 Hz inside), a stroke in and out of an outlined
    /// window fires one pulse at each side, on the side crossed: the burst is stopped (an
    /// `Off`) on the reading before the pulse and is not restarted until the pulse's rest has
    /// passed, when the texture of the place then starts again; nothing skipped. Four
    /// directions × 20/50/100/200 mm/s, noiseless (3 phases) and at 2 LSB (3 seeds).
    ///
    /// Placement: the true finger at the pulse's reading lies within docs/plane.md's fire
    /// bound of its target (the lead v × 5.05 ms ahead of the side): late by f ∈ [−E − Λ − 1,
    /// E + Λ + v·T + 1] µm, E the stroke's largest noise across the side, Λ the lead's error
    /// on the two readings before the pulse, now over 5.15 ms (the lead plus the stop's
    /// reading). Measured: −25.5 to +24.0 µm (noiseless 1.0 to 18.0 µm: 0.2 to 0.9 v·T above
    /// 20 mm/s, the target aimed at mid-reading). Seen failing (2026-11-29) without the extra reading's travel in
    /// the lead: every pulse one reading later, 81 of 192 out of the bound (noiseless at
    /// 200 mm/s 24–38 µm late against 21 µm; −25.5 to +44.0 µm in all); and, with the pulse
    /// asked at once instead of after a stop (`Gate::pulse` refuses while a burst runs), no
    /// pulse at all.
    #[test]
    fn an_edge_over_a_running_burst_stops_it_and_pulses_once_each_way() {
        use std::format;
        let (lead_s, ext_s) = (5_050e-6, 5_150e-6);
        let (mut lo, mut hi) = (f64::MAX, f64::MIN);
        let mut fired_total = 0;
        // (from, to) mm, the sides crossed in order with their coordinate along the stroke.
        let strokes: [((f64, f64), (f64, f64), [(u8, f64); 2]); 4] = [
            ((30.0, 30.0), (70.0, 30.0), [(3, 40.0), (1, 60.0)]),
            ((70.0, 30.0), (30.0, 30.0), [(1, 60.0), (3, 40.0)]),
            ((50.0, 10.0), (50.0, 50.0), [(0, 20.0), (2, 40.0)]),
            ((50.0, 50.0), (50.0, 10.0), [(2, 40.0), (0, 20.0)]),
        ];
        for (from, to, sides) in strokes {
            let along_x = from.1 == to.1;
            let dir = if along_x {
                to.0 - from.0
            } else {
                to.1 - from.1
            }
            .signum();
            let coord = |q: (f64, f64)| if along_x { q.0 } else { q.1 };
            for v in [20.0, 50.0, 100.0, 200.0] {
                for (lsb, seed) in [(0.0, 0), (0.0, 1), (0.0, 2), (2.0, 1), (2.0, 2), (2.0, 3)] {
                    let ctx = format!("{from:?} → {to:?} at {v} mm/s, {lsb} LSB seed {seed}");
                    let mut noise = Noise::new(seed);
                    // Each seed starts 0.3 of a reading's travel further back: the readings
                    // fall at other phases against the side.
                    let back_mm = seed as f64 * 0.3 * v * PERIOD_US as f64 * 1e-6;
                    let from = if along_x {
                        (from.0 - dir * back_mm, from.1)
                    } else {
                        (from.0, from.1 - dir * back_mm)
                    };
                    let s = stroke_truth(
                        (from.0 * 1e3, from.1 * 1e3),
                        (to.0 * 1e3, to.1 * 1e3),
                        v,
                        sigma_um(lsb),
                        &mut noise,
                    );
                    let e_um = s
                        .iter()
                        .map(|(_, _, e)| coord(*e).abs())
                        .fold(0.0, f64::max);
                    let mut c = loaded(&textured_edge_scene());
                    let mut t = 0;
                    let outs = feed(&mut c, &mut t, s.iter().map(|(r, _, _)| *r));
                    let fired: StdVec<usize> = (0..outs.len())
                        .filter(|&k| matches!(outs[k].action, Some(GateAction::Pulse(_))))
                        .collect();
                    assert_eq!(fired.len(), 2, "{ctx}");
                    // The line's protocol: a Pulse only from off; a burst never restarted
                    // inside an edge's pulse + rest (20 ms).
                    let mut running = false;
                    let mut last_pulse: Option<usize> = None;
                    for (k, o) in outs.iter().enumerate() {
                        match o.action {
                            Some(GateAction::Start(_)) => {
                                running = true;
                                if let Some(j) = last_pulse {
                                    assert!((k - j) as u32 * PERIOD_US >= 20_000, "{ctx}");
                                }
                            }
                            Some(GateAction::Off) => running = false,
                            Some(GateAction::Pulse(_)) => {
                                assert!(!running, "{ctx}: a pulse over a running burst");
                                last_pulse = Some(k);
                            }
                            Some(GateAction::Update(_)) => assert!(running, "{ctx}"),
                            None => {}
                        }
                    }
                    for (&k, &(side, line_mm)) in fired.iter().zip(&sides) {
                        assert_eq!(outs[k].edge, Some(side), "{ctx}");
                        assert_eq!(outs[k].envelope, Some(Envelope::Triangular), "{ctx}");
                        // Stopped on the reading before; the burst ran up to there.
                        assert_eq!(outs[k - 1].action, Some(GateAction::Off), "{ctx}");
                        assert!(
                            outs[..k - 1]
                                .iter()
                                .rev()
                                .find_map(|o| o.action)
                                .is_some_and(|a| matches!(
                                    a,
                                    GateAction::Start(_) | GateAction::Update(_)
                                )),
                            "{ctx}: no burst ran before the stop"
                        );
                        // The texture of the place after the rest starts again.
                        let restart = outs[k + 1..]
                            .iter()
                            .find(|o| o.action.is_some())
                            .unwrap_or_else(|| panic!("{ctx}: nothing after the pulse"));
                        let Some(GateAction::Start(b)) = restart.action else {
                            panic!("{ctx}: {restart:?}");
                        };
                        let inside = restart.place == Some(Place::Window(0));
                        assert_eq!(millihz(b), if inside { 80_000 } else { 1_000_000 });
                        // Placement against the target, µm late.
                        let ahead = (line_mm * 1e3 - coord(s[k].1)) * dir;
                        let late = v * 1e3 * lead_s - ahead;
                        let lam = [k - 2, k - 1]
                            .iter()
                            .map(|&j| {
                                let w = outs[j].velocity.expect("a velocity near the side");
                                let vn = if along_x { w.vx_um_s } else { w.vy_um_s } as f64 * dir;
                                (vn - v * 1e3).abs() * ext_s
                            })
                            .fold(0.0, f64::max);
                        let v_t = v * 1e3 * PERIOD_US as f64 * 1e-6;
                        let (b_lo, b_hi) = (-e_um - lam - 1.0, e_um + lam + v_t + 1.0);
                        assert!(
                            late >= b_lo && late <= b_hi,
                            "{ctx}: side {side} fired {late:.1} um late, bound [{b_lo:.1}, {b_hi:.1}]"
                        );
                        (lo, hi) = (lo.min(late), hi.max(late));
                        fired_total += 1;
                    }
                    let tm = c.telemetry();
                    assert_eq!((tm.edge_pulses, tm.edges_skipped), (2, 0), "{ctx}");
                }
            }
        }
        assert_eq!(fired_total, 192);
        std::println!("192 pulses over running bursts: {lo:.1} to {hi:.1} um late of the target");
    }

    /// The lead's bound ([`EdgeTracker::may_fire`]: no lead made, no crossing tested where
    /// no lead of the estimated speed reaches an edge's line) changes no output: a controller
    /// with it answers every reading as one that makes the lead and tests the edges in reach
    /// on every reading (the 2 mm cap's reach), over running bursts (so the preempt lead,
    /// one period longer, is the one tested) and off ground, on strokes across the window's
    /// sides along the axes, noiseless (the lead across a side is then all of its L1 length,
    /// and the bound's margin least) and at 2 LSB, and along random lines at 2 LSB, 20–400
    /// mm/s. Seen failing (2026-11-30) with the bound planted short (0.9 × its factor); the
    /// bound without the preempt lead's period passes here (the quiet room is short of the
    /// edge's by √2 − 1 of the travel on these strokes, more than the period's 10–40 µm), and
    /// `edges::tests::the_lead_bound_is_never_below_the_lead_across_an_edge` catches it.
    #[test]
    fn the_lead_bound_changes_no_output() {
        let mut cfg = textured_edge_scene();
        cfg.scene
            .windows
            .push(window(rect(0, 0, 20_000, 20_000), OFF, true))
            .unwrap();
        cfg.scene
            .free_edges
            .push(SegmentUm {
                a: PointUm::new(5_000, 45_000),
                b: PointUm::new(35_000, 55_000),
            })
            .unwrap();
        let mut noise = Noise::new(31);
        // (from, to) mm, LSB of noise.
        let mut strokes: StdVec<((f64, f64), (f64, f64), f64)> = StdVec::new();
        for (a, b) in [
            ((30.0, 30.0), (70.0, 30.0)),
            ((50.0, 10.0), (50.0, 50.0)),
            ((-5.0, 10.0), (25.0, 10.0)),
            ((10.0, 25.0), (10.0, -5.0)),
        ] {
            for lsb in [0.0, 2.0] {
                strokes.push((a, b, lsb));
                strokes.push((b, a, lsb));
            }
        }
        for _ in 0..24 {
            let mut q = || (noise.uniform() * 70.0 - 5.0, noise.uniform() * 65.0 - 5.0);
            strokes.push((q(), q(), 2.0));
        }
        let (mut readings, mut pulses, mut stops) = (0usize, 0usize, 0usize);
        for (i, &(a, b, lsb)) in strokes.iter().enumerate() {
            for v in [20.0, 100.0, 200.0, 400.0] {
                let s = stroke(
                    (a.0 * 1e3, a.1 * 1e3),
                    (b.0 * 1e3, b.1 * 1e3),
                    v,
                    sigma_um(lsb),
                    &mut noise,
                );
                let mut c = loaded(&cfg);
                let mut r = loaded(&cfg);
                r.edges.set_no_bound();
                let (mut tc, mut tr) = (0, 0);
                let what = std::format!("stroke {i} at {v} mm/s");
                let oc = feed_alike((&mut c, &mut tc), (&mut r, &mut tr), &s, &what);
                readings += oc.len();
                pulses += oc.iter().filter(|o| o.edge.is_some()).count();
                stops += (1..oc.len())
                    .filter(|&k| oc[k - 1].action == Some(GateAction::Off) && oc[k].edge.is_some())
                    .count();
            }
        }
        assert!(
            pulses > 100 && stops > 50,
            "{pulses} pulses, {stops} after a stop"
        );
        std::println!("{readings} readings: {pulses} edge pulses, {stops} of them after a stop");
    }

    /// The short ways change no output and no counter: the fixed texture's (an off or constant
    /// window's step answered by the gate alone while the line already does its settings) and
    /// the pulse window's (a reading inside an edge pulse's pulse + rest window with nothing
    /// to test or carry, answered before `edges_act`). A controller with them answers every
    /// reading as one that always asks the texture and the edges, on random
    /// strokes at 20–400 mm/s and 2 LSB over off, constant, grating and random windows and a
    /// constant background, every outline an edge (so pulses stop bursts and the line comes
    /// back), under a 40 % duty cap (bursts at its edge) and a 600 ‰ level cap (the
    /// amplitude asked anew), broken by lifts, landings, rail faults and scene reloads (the
    /// amplitude forgotten), and reloads into a scene without edges inside a pulse's window.
    /// Seen failing (2026-11-30) with the amplitude test planted out, with a constant window's
    /// settings planted as off, with every kind planted fixed, with the window's test planted
    /// one reading long (≤) or the window copied 100 µs long, and with a scene without edges
    /// keeping a window (copied as 50 ms). A window copied short (the pulse alone) is
    /// equivalent: `edges_act` answers those readings as the short way would.
    #[test]
    fn the_short_ways_change_no_output() {
        let grating = PlaneTexture::Plain(Texture::Grating(Grating {
            render: GratingRender::VelocitySynthesis,
            amplitude_permille: 500,
            ..Grating::new(1_000)
        }));
        let random = PlaneTexture::Plain(Texture::Random(crate::texture::RandomBurst {
            center_millihz: 40_000,
            spread_permille: 300,
            amplitude_permille: 500,
            amplitude_spread_permille: 200,
            duty_permille: 400,
            seed: 3,
        }));
        let mut cfg = config(&[
            window(rect(5_000, 5_000, 25_000, 25_000), OFF, true),
            window(rect(30_000, 5_000, 50_000, 25_000), hz(80), true),
            window(rect(5_000, 30_000, 25_000, 50_000), grating, true),
            window(rect(30_000, 30_000, 50_000, 50_000), random, true),
            window(rect(52_000, 5_000, 60_000, 50_000), hz(2_000), false),
        ]);
        cfg.scene.background = hz(1_000);
        cfg.limits.max_duty_permille = 400;
        cfg.limits.max_level_permille = 600;
        cfg.scene.edge_pulse.amplitude_permille = 600;
        let mut noise = Noise::new(47);
        let (mut readings, mut actions, mut reloads) = (0usize, 0usize, 0u32);
        let (mut c, mut r) = (loaded(&cfg), loaded(&cfg));
        r.no_short_ways = true;
        let (mut tc, mut tr) = (0u32, 0u32);
        for i in 0..60 {
            let mut q = || (noise.uniform() * 70.0 - 5.0, noise.uniform() * 60.0 - 5.0);
            let (a, b) = (q(), q());
            let v = [20.0, 100.0, 200.0, 400.0][i % 4];
            let mut s = stroke(
                (a.0 * 1e3, a.1 * 1e3),
                (b.0 * 1e3, b.1 * 1e3),
                v,
                sigma_um(2.0),
                &mut noise,
            );
            match i % 6 {
                1 => s.splice(0..0, [Reading::Lifted; 12]).for_each(drop),
                2 => {
                    let p = PointUm::new((a.0 * 1e3) as i32, (a.1 * 1e3) as i32);
                    s.splice(
                        0..0,
                        [Reading::Landing {
                            x_um: p.x_um,
                            y_um: p.y_um,
                        }; 8],
                    )
                    .for_each(drop);
                }
                3 => {
                    let at = s.len() / 2;
                    let f = Reading::Fault(AxisFault {
                        axis: Axis::Y,
                        fault: SensorFault::RailHigh,
                    });
                    s.splice(at..at, [f; 3]).for_each(drop);
                }
                4 => {
                    c.load(&cfg).unwrap();
                    r.load(&cfg).unwrap();
                }
                5 => {
                    // Into the same windows with no edges just after a pulse (inside its
                    // window), and back after the stroke.
                    let mut bare = cfg.clone();
                    bare.scene.windows.iter_mut().for_each(|w| w.edge = false);
                    let mut reloaded = false;
                    for (k, &rd) in s.iter().enumerate() {
                        let (oc, or) = (c.on_reading(tc, rd), r.on_reading(tr, rd));
                        (tc, tr) = (tc + PERIOD_US, tr + PERIOD_US);
                        assert_eq!(oc, or, "stroke {i}, reading {k}");
                        if oc.edge.is_some() && !reloaded {
                            c.load(&bare).unwrap();
                            r.load(&bare).unwrap();
                            reloaded = true;
                            reloads += 1;
                        }
                    }
                    c.load(&cfg).unwrap();
                    r.load(&cfg).unwrap();
                    s.clear();
                }
                _ => {}
            }
            let what = std::format!("stroke {i} at {v} mm/s");
            let oc = feed_alike((&mut c, &mut tc), (&mut r, &mut tr), &s, &what);
            readings += oc.len();
            actions += oc.iter().filter(|o| o.action.is_some()).count();
        }
        let t = c.telemetry();
        assert!(
            t.edge_pulses > 50 && t.clamped > 0 && t.faults > 0 && actions > 500 && reloads > 3,
            "{t:?}, {actions} actions, {reloads} reloads in a pulse's window"
        );
        std::println!("{readings} readings, {actions} gate actions: {t:?}");
    }

    /// With no room in the duty window (bursts at 40 % under a 40 % cap for over a window),
    /// the burst is stopped, the crossing's pulse refused by the gate, skipped and counted, and
    /// the texture takes the line back. (Seen failing with the refusal not counted.)
    #[test]
    fn an_edge_the_duty_cap_has_no_room_for_is_skipped_and_counted() {
        let mut cfg = textured_edge_scene();
        cfg.limits.max_duty_permille = 400;
        let mut c = loaded(&cfg);
        let mut t = 0;
        let mut noise = Noise::new(5);
        let outs = feed(
            &mut c,
            &mut t,
            stroke(
                (20_000.0, 30_000.0),
                (80_000.0, 30_000.0),
                50.0,
                0.0,
                &mut noise,
            ),
        );
        assert_eq!(pulses(&outs), 0);
        let tm = c.telemetry();
        assert_eq!((tm.edge_pulses, tm.edges_skipped), (0, 2));
        // Each stop is followed, later, by the texture's burst again.
        let stops: StdVec<usize> = (0..outs.len())
            .filter(|&k| outs[k].action == Some(GateAction::Off))
            .collect();
        assert_eq!(stops.len(), 2, "{stops:?}");
        for k in stops {
            assert!(outs[k + 1..]
                .iter()
                .any(|o| matches!(o.action, Some(GateAction::Start(_)))));
        }
    }

    /// A crossing whose burst was stopped waits for the next reading only if it comes within
    /// two sample periods: after a gap of three, it is skipped and counted, and the texture
    /// restarts on that reading. (Seen failing with no bound on the wait: the pulse fired
    /// 200 µs late, 40 µm past its target at 200 mm/s.)
    #[test]
    fn a_pending_edge_is_skipped_after_a_lost_reading() {
        let mut c = loaded(&textured_edge_scene());
        let mut noise = Noise::new(3);
        let s = stroke(
            (30_000.0, 30_000.0),
            (50_000.0, 30_000.0),
            200.0,
            0.0,
            &mut noise,
        );
        let mut t = 0;
        let mut stopped = false;
        for r in s {
            let out = c.on_reading(t, r);
            t += PERIOD_US;
            assert!(!matches!(out.action, Some(GateAction::Pulse(_))));
            if stopped {
                assert!(matches!(out.action, Some(GateAction::Start(_))), "{out:?}");
                break;
            }
            if out.action == Some(GateAction::Off) {
                stopped = true;
                // Two readings lost.
                t += 2 * PERIOD_US;
            }
        }
        assert!(stopped);
        let tm = c.telemetry();
        assert_eq!((tm.edge_pulses, tm.edges_skipped), (0, 1));
    }
}
