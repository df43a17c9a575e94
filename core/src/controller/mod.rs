//! Controller: runs the stages in order for each sample and owns the fault state.
//!
//! Loading a configuration is a compile step: everything is validated and each region's
//! texture compiled (texture::compiled) before anything is replaced, so a bad configuration
//! changes nothing and the per-sample path computes only what the active region's texture
//! needs. Per sample: map → fault check → velocity → region → lines, else the region's texture
//! → gate. What a texture does lives with the texture; this file only keeps the order, the
//! fault state, the swap and the telemetry.

use core::cell::Cell;

use heapless::Vec;

use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};
use crate::fmt::LogLimit;
pub use crate::fmt::LOG_INTERVAL_US;
use crate::gate::{BurstOutput, DriveMode, Envelope, Gate, GateAction};
use crate::position::{PositionMapper, SensorFault};
use crate::region::{RegionMap, MAX_REGIONS};
use crate::sample::{PositionSource, Sample};
use crate::scene::Config;
use crate::texture::compiled::{CompileError, Compiled, Moment, Need, Render, Request, Want};
use crate::texture::lines::{LinePulses, LineStep, LineTracker};
use crate::velocity::{LsqSlope, Median3, VelocityEstimator};

mod error;
mod telemetry;

pub use error::ConfigError;
use error::MAX_STALE_US;
pub use telemetry::{Output, Telemetry};

/// Samples in the default least-squares window: 3.2 ms at 10 kHz, 1.55 ms group delay.
pub const DEFAULT_WINDOW: usize = 32;
/// The default velocity estimator: the least-squares slope behind a median-of-3 pre-filter.
/// Chosen on the bench (docs/estimators.md): the median costs 0.1 ms of lag and 5 % of noise,
/// and cuts the worst error under single-sample outliers and drops from 130 to 22 mm/s.
pub type DefaultEstimator = WindowEstimator<DEFAULT_WINDOW>;
/// Consecutive good samples needed to leave a sensor fault (1.6 ms at 10 kHz): a wiper bouncing
/// on a worn track must not flash the carrier on between bounces.
pub const RECOVERY_SAMPLES: u16 = 16;

/// A validated, compiled configuration.
#[derive(Clone, Debug)]
struct Active {
    mapper: PositionMapper,
    regions: RegionMap,
    compiled: Vec<Compiled, MAX_REGIONS>,
    /// The scene's lines, when it draws any.
    lines: Option<LinePulses>,
    limits: SafetyLimits,
    stale_after_us: u32,
    drive: DriveMode,
    /// Bit r set: region r's texture reads only the position ([`Need::Position`]) or its own
    /// fit ([`Need::OwnFit`]) and the scene draws no lines, so the estimator rests there (the
    /// sample path's contract, docs/sample-contract.md).
    rest_mask: u32,
    /// Bit r set: region r's texture has a fit of its own that gives the velocity
    /// ([`Need::OwnFit`]) and the scene draws no lines: there the estimator may sleep (no work
    /// at all) and be seeded from that fit on leaving.
    own_fit_mask: u32,
}

/// A configuration validated and compiled, ready to [`Controller::install`].
#[derive(Clone, Debug)]
pub struct Prepared {
    active: Active,
    /// For the load log line.
    lines: usize,
    hysteresis_um: u32,
}

impl Prepared {
    /// Validates and compiles `config` for a controller with this burst timer and sample
    /// period. Needs no controller: the firmware runs it at low priority.
    pub fn compile(
        timer: &BurstTimer,
        sample_period_us: u32,
        config: &Config,
    ) -> Result<Prepared, ConfigError> {
        let mapper = PositionMapper::new(config.calibration).map_err(ConfigError::Calibration)?;
        let scene = &config.scene;
        if scene.textures.len() != scene.boundaries_um.len() + 1 {
            return Err(ConfigError::TextureCount {
                textures: scene.textures.len(),
                boundaries: scene.boundaries_um.len(),
            });
        }
        let length_um = mapper.length_um();
        let regions = RegionMap::new(
            scene.textures.len(),
            &scene.boundaries_um,
            length_um,
            scene.hysteresis_um,
        )
        .map_err(ConfigError::Region)?;
        config.limits.validate().map_err(ConfigError::Limits)?;
        let min_stale_us = 2 * sample_period_us;
        if config.stale_after_us < min_stale_us || config.stale_after_us > MAX_STALE_US {
            return Err(ConfigError::StaleLimit {
                stale_after_us: config.stale_after_us,
                min_us: min_stale_us,
            });
        }
        let mut compiled = Vec::new();
        for (i, texture) in scene.textures.iter().enumerate() {
            let region = i as u8;
            let (c, capped) =
                Compiled::compile(texture, timer, &config.limits, length_um, sample_period_us)
                    .map_err(|e| match e {
                        CompileError::Params(error) => ConfigError::TextureParams { region, error },
                        CompileError::Burst(error) => ConfigError::Texture { region, error },
                    })?;
            if capped {
                warn!(
                    "region {}: on-time capped to {} us",
                    i, config.limits.max_on_time_us
                );
            }
            // Cannot fail: the region map holds at most MAX_REGIONS.
            let _ = compiled.push(c);
        }
        let lines = LinePulses::compile(
            &scene.lines,
            timer,
            &config.limits,
            length_um,
            sample_period_us,
        )
        .map_err(|e| match e {
            CompileError::Params(e) => ConfigError::Lines(e),
            CompileError::Burst(e) => ConfigError::LinePulse(e),
        })?;
        for (i, t) in scene.textures.iter().enumerate() {
            debug!("region {}: {}", i, t.kind());
        }
        // Lines overlay every region and fire ahead by the velocity: a scene with lines needs
        // it everywhere.
        let mask = |needs: &[Need]| {
            if lines.is_some() {
                return 0;
            }
            compiled
                .iter()
                .enumerate()
                .filter(|(_, c)| needs.contains(&c.need()))
                .fold(0u32, |m, (i, _)| m | 1 << i)
        };
        let rest_mask = mask(&[Need::Position, Need::OwnFit]);
        let own_fit_mask = mask(&[Need::OwnFit]);
        Ok(Prepared {
            active: Active {
                mapper,
                regions,
                compiled,
                lines,
                limits: config.limits,
                stale_after_us: config.stale_after_us,
                drive: scene.drive,
                rest_mask,
                own_fit_mask,
            },
            lines: scene.lines.positions_um.len(),
            hysteresis_um: scene.hysteresis_um,
        })
    }
}

/// What a sample does with the velocity estimator in the region in force (the sample path's
/// contract, docs/sample-contract.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SampleMode {
    /// The region reads the velocity: update.
    Update,
    /// It reads only the position: rest (window and sums kept, the slope skipped).
    Rest,
    /// Its texture's own fit gives the velocity: nothing; seeded from that fit on leaving.
    Sleep,
}

/// The control core.
#[derive(Clone, Debug)]
pub struct Controller<E: VelocityEstimator = DefaultEstimator> {
    timer: BurstTimer,
    sample_period_us: u32,
    active: Option<Active>,
    estimator: E,
    /// The estimator was rested on the last sample (a region that reads no velocity): it is
    /// woken before its next update.
    resting: bool,
    /// The velocity the last awake sample computed (None while resting: see
    /// [`Self::velocity_um_s`]).
    velocity_um_s: Option<i32>,
    /// Update the estimator on every sample whatever the region needs (host analyses that
    /// read the velocity of every sample; see [`Self::velocity_every_sample`]).
    velocity_every_sample: bool,
    /// The regions where the estimator rests now: the active scene's
    /// [`Active::rest_mask`], 0 with [`Self::velocity_every_sample`] or an estimator that
    /// cannot rest.
    rest_mask: u32,
    /// The regions where the estimator sleeps: the active scene's [`Active::own_fit_mask`]
    /// where the estimator rests there and can be seeded, else 0.
    sleep_mask: u32,
    /// What the sample path does with the estimator in the region in force, worked out when
    /// the region (or a setting) changes, so a sample tests one byte (M4F instruction counts).
    sample_mode: SampleMode,
    gate: Gate,
    region: Option<u8>,
    fault: Option<SensorFault>,
    good_run: u16,
    last_sample_us: Option<u32>,
    region_log: LogLimit,
    clamp_log: LogLimit,
    lines: LineTracker,
    amplitude: Option<u16>,
    /// The permille last asked of [`Self::set_amplitude`], before the cap (`u16::MAX`: none
    /// since the cap last changed). A texture asks for the same amplitude on almost every
    /// sample: one compare settles it then, instead of capping and comparing again.
    amplitude_asked: u16,
    /// The active scene's level cap, ‰ (a copy: read once per sample where the amplitude is
    /// set; fetched from the scene there instead, it cost every scene ~20 instructions per
    /// sample on the M4 in spilled registers).
    level_cap_permille: u16,
    drive_pending: bool,
    /// A scene was installed and no sample has run since: its caps are checked against the
    /// burst the old scene left running at the next tick (see [`Controller::on_tick`]).
    caps_pending: bool,
    telemetry: Telemetry,
    /// The running burst's frequency as [`Controller::telemetry`] last worked it out, keyed by
    /// the period it came from, (psc, arr, mHz): the firmware's stream asks at every record, and
    /// the u64 division (~170 instructions on the M4, `__aeabi_uldivmod`) is paid once per
    /// period, not per record (the board model's stream-cost check: +10 % → +2 % per sample).
    burst_memo: Cell<Option<(u16, u32, u32)>>,
    /// When the last two one-pulses (ridges, lines) fired, µs, older first: the only work the
    /// sample path does for the pulse rate [`Controller::telemetry`] reports (two stores per
    /// pulse, none per sample). The last is forgotten (a `Cell`, from `telemetry`) once the
    /// pulses have stopped, so a stale pair never comes back when the µs clock wraps.
    pulse_us: [Cell<Option<u32>>; 2],
}

impl Controller<DefaultEstimator> {
    /// A controller with the default estimator, no configuration loaded (line off).
    pub fn new(timer: BurstTimer, sample_period_us: u32) -> Result<Self, ConfigError> {
        Self::with_window(timer, sample_period_us)
    }
}

/// The default estimator at a board's window ([`DEFAULT_WINDOW`] samples on the F446, fewer
/// where the acquisition's noise allows: `saw_boards::BoardDef::velocity_window`).
pub type WindowEstimator<const N: usize> = Median3<LsqSlope<N>>;

impl<const N: usize> Controller<WindowEstimator<N>> {
    /// A controller with the default estimator over an `N`-sample window, no configuration
    /// loaded (line off).
    pub fn with_window(timer: BurstTimer, sample_period_us: u32) -> Result<Self, ConfigError> {
        let lsq = LsqSlope::<N>::new(sample_period_us).map_err(ConfigError::Estimator)?;
        let estimator = Median3::new(lsq, sample_period_us);
        Ok(Self::with_estimator(timer, sample_period_us, estimator))
    }
}

impl<E: VelocityEstimator> Controller<E> {
    /// A controller with a chosen estimator, no configuration loaded (line off).
    pub fn with_estimator(timer: BurstTimer, sample_period_us: u32, estimator: E) -> Self {
        Self {
            timer,
            sample_period_us,
            active: None,
            level_cap_permille: 1000,
            estimator,
            resting: false,
            velocity_um_s: None,
            velocity_every_sample: false,
            rest_mask: 0,
            sleep_mask: 0,
            sample_mode: SampleMode::Update,
            gate: Gate::default(),
            region: None,
            fault: None,
            good_run: 0,
            last_sample_us: None,
            region_log: LogLimit::default(),
            clamp_log: LogLimit::default(),
            lines: LineTracker::default(),
            amplitude: None,
            amplitude_asked: u16::MAX,
            drive_pending: false,
            caps_pending: false,
            telemetry: Telemetry {
                position_um: -1,
                region: u8::MAX,
                ..Telemetry::default()
            },
            burst_memo: Cell::new(None),
            pulse_us: [Cell::new(None), Cell::new(None)],
        }
    }

    /// Validates and compiles `config`, then makes it active. On error nothing changes.
    pub fn load(&mut self, config: &Config) -> Result<(), ConfigError> {
        match Prepared::compile(&self.timer, self.sample_period_us, config) {
            Ok(p) => {
                self.install(p);
                Ok(())
            }
            Err(e) => {
                // `{}`: the sentence on a host (`log`), the same defmt `Format` on target.
                warn!("scene rejected, previous kept: {}", e);
                Err(e)
            }
        }
    }

    /// Makes a configuration compiled by [`Prepared::compile`] active from the next sample:
    /// a move, no checks and no compile on the sample path (the firmware compiles in its link
    /// task and hands the result over).
    pub fn install(&mut self, prepared: Prepared) {
        // An estimator asleep in the old scene's region is seeded from that region's fit
        // before the scene goes (the next region's needs are the new scene's).
        self.leave_sleep();
        let active = prepared.active;
        info!(
            "scene loaded: {} regions, {} lines, hysteresis {} um, duty cap {} permille, on-time cap {} us",
            active.regions.len(),
            prepared.lines,
            prepared.hysteresis_um,
            active.limits.max_duty_permille,
            active.limits.max_on_time_us
        );
        self.level_cap_permille = active.limits.max_level_permille;
        // The same ask may give another level under the new cap.
        self.amplitude_asked = u16::MAX;
        self.active = Some(active);
        // The first sample finds its region anew (a region change), which wakes the estimator
        // if that region reads the velocity.
        self.region = None;
        self.update_rest_mask();
        // The old region index and line arming mean nothing in the new layout (a running line
        // pulse keeps its window: the gate may be in its rest).
        self.region = None;
        self.lines.reset();
        // Pulses of the old scene say nothing about the new one's rate.
        self.pulse_us = [Cell::new(None), Cell::new(None)];
        self.drive_pending = true;
        self.caps_pending = true;
    }

    /// Updates the velocity estimator on every sample, also in regions whose texture reads
    /// only the position, so [`Output::velocity_um_s`] carries it on every sample (a host
    /// simulation's velocity figures). Off by default: per sample the controller computes only
    /// what the region in force needs, and the stream reads [`Self::velocity_um_s`] at its own
    /// rate. Changes no burst: the estimate a texture sees is the same either way.
    pub fn velocity_every_sample(&mut self, on: bool) {
        self.velocity_every_sample = on;
        self.update_rest_mask();
        if on {
            self.wake_estimator();
        }
    }

    /// [`Self::rest_mask`] and [`Self::sleep_mask`] from the active scene and the settings,
    /// and the region in force's mode from them.
    fn update_rest_mask(&mut self) {
        (self.rest_mask, self.sleep_mask) = match self.active.as_ref() {
            Some(a) if !self.velocity_every_sample && self.estimator.rests() => (
                a.rest_mask,
                if self.estimator.window_samples() > 0 {
                    a.own_fit_mask
                } else {
                    0
                },
            ),
            _ => (0, 0),
        };
        let mode = self.region.map_or(SampleMode::Update, |r| self.mode_of(r));
        if mode != SampleMode::Sleep {
            self.leave_sleep();
        }
        self.sample_mode = mode;
    }

    /// What the sample path does with the estimator in `region`.
    fn mode_of(&self, region: u8) -> SampleMode {
        let bit = 1u32.checked_shl(region as u32).unwrap_or(0);
        if self.sleep_mask & bit != 0 {
            SampleMode::Sleep
        } else if self.rest_mask & bit != 0 {
            SampleMode::Rest
        } else {
            SampleMode::Update
        }
    }

    /// Ends a sleep: the estimator is fed the newest positions of the fit of the region it
    /// slept in (its window's worth, O(window) once), so it answers as one fed all along
    /// would have over those samples (docs/sample-contract.md, "Sleep"). No-op when awake.
    fn leave_sleep(&mut self) {
        if core::mem::replace(&mut self.sample_mode, SampleMode::Update) != SampleMode::Sleep {
            return;
        }
        self.resting = false;
        let k = self.estimator.window_samples();
        match (self.active.as_ref(), self.region) {
            (Some(a), Some(r)) => match a.compiled.get(r as usize) {
                Some(c) => c.seed(&mut self.estimator, k),
                None => self.estimator.reset(),
            },
            _ => self.estimator.reset(),
        }
    }

    /// Makes a resting estimator whole (its next update answers as if it had never rested).
    fn wake_estimator(&mut self) {
        if core::mem::take(&mut self.resting) {
            self.estimator.wake();
        }
    }

    /// The velocity after the last sample, µm/s (None without a full window): what the
    /// estimator answered, or, in a region where it rests, what it would have answered, made now
    /// from its running sums (O(1): for a stream record or telemetry, not per sample).
    // Inlined into the firmware's stream tap (the board model's stream-cost check: a call here
    // took the G474's tap at every sample from +8.4 % to +11.5 % of the sample path).
    #[inline]
    pub fn velocity_um_s(&self) -> Option<i32> {
        // Asleep: the region's own fit is the velocity.
        if self.sample_mode == SampleMode::Sleep {
            return self.own_velocity_um_s();
        }
        // An estimator that rests answers for itself, resting or not (awake, its last answer).
        if self.estimator.rests() {
            self.estimator.estimate()
        } else {
            self.velocity_um_s
        }
    }

    /// The velocity of the region in force's own fit (the hybrid's line), µm/s.
    #[inline(never)]
    fn own_velocity_um_s(&self) -> Option<i32> {
        let c = self.active.as_ref()?.compiled.get(self.region? as usize)?;
        c.own_velocity_um_s()
    }

    /// The burst timer this controller plans for.
    pub fn timer(&self) -> &BurstTimer {
        &self.timer
    }

    /// Counters and last values, for telemetry.
    pub fn telemetry(&self) -> Telemetry {
        Telemetry {
            burst_millihz: self.burst_millihz(),
            velocity_um_s: self.velocity_um_s().unwrap_or(0),
            ..self.telemetry
        }
    }

    /// The burst frequency in force, mHz: [`Telemetry::burst_millihz`] alone, for a stream
    /// record (the firmware reads it per streamed sample; the whole telemetry's copy costs
    /// instructions the sample path's tap budget has not got).
    pub fn burst_millihz(&self) -> u32 {
        // The running burst's frequency is worked out here, when asked, not on every gate
        // action (a u64 division per changed sample for a velocity-driven texture). Every
        // state change of the gate goes through `count_action`, which used to fill it from
        // `gate.running()` the same way, so the figure is the same.
        match self.gate.running() {
            None => self.pulse_rate_millihz(),
            Some(s) => match self.burst_memo.get() {
                Some((psc, arr, millihz)) if (psc, arr) == (s.psc, s.arr) => millihz,
                _ => {
                    let millihz = s.produced_millihz(self.timer.clock_hz) as u32;
                    self.burst_memo.set(Some((s.psc, s.arr, millihz)));
                    millihz
                }
            },
        }
    }

    /// The rate of one-pulses (a ridge crossed by the position or hybrid grating, a line),
    /// mHz: 1 / the interval between the last two, while they keep coming — 0 once the finger
    /// is still (the velocity estimate 0) or no pulse has come for 1.5 intervals since the last
    /// (a crossing at constant speed lands a sample early or late, so one interval may be a
    /// sample period longer than the one before). A crossing the duty cap skipped fired no
    /// pulse: the rate is what was produced, not what was crossed.
    fn pulse_rate_millihz(&self) -> u32 {
        let [prev, last] = [self.pulse_us[0].get(), self.pulse_us[1].get()];
        let (Some(prev), Some(last), Some(now)) = (prev, last, self.last_sample_us) else {
            return 0;
        };
        let interval_us = last.wrapping_sub(prev);
        let since_us = now.wrapping_sub(last);
        if since_us > interval_us.saturating_add(interval_us / 2) {
            // Stopped: forget the pair, so a µs clock that wraps never revives it.
            self.pulse_us[1].set(None);
            return 0;
        }
        if self.velocity_um_s().unwrap_or(0) == 0 || interval_us == 0 {
            return 0;
        }
        // 10^9 µs·mHz / interval: 1 mHz at 10^9 µs, 10^9 mHz at 1 µs; fits u32.
        1_000_000_000 / interval_us
    }

    /// A one-pulse fired at `t_us`: kept for [`Self::pulse_rate_millihz`].
    #[inline(always)]
    fn note_pulse(&mut self, t_us: u32) {
        self.pulse_us[0].set(self.pulse_us[1].get());
        self.pulse_us[1].set(Some(t_us));
    }

    /// The position mapper of the active configuration.
    pub fn mapper(&self) -> Option<&PositionMapper> {
        self.active.as_ref().map(|a| &a.mapper)
    }

    /// Runs one sample through every stage.
    pub fn on_sample(&mut self, sample: Sample) -> Output {
        self.telemetry.samples = self.telemetry.samples.wrapping_add(1);
        self.last_sample_us = Some(sample.t_us);
        // This sample plans under the installed scene's caps.
        self.caps_pending = false;
        let t_us = sample.t_us;
        // Without a scene nothing has ever driven the gate (a load only replaces a scene), so
        // there is nothing to switch off.
        let Some(active) = self.active.as_ref() else {
            return Output::default();
        };
        let position_um = match active.mapper.position_um(&sample) {
            Ok(p) => p,
            Err(fault) => return self.enter_fault(fault, t_us),
        };
        if let Some(fault) = self.fault {
            self.good_run += 1;
            if self.good_run < RECOVERY_SAMPLES {
                return Output {
                    position_um: Some(position_um),
                    fault: Some(fault),
                    ..Output::default()
                };
            }
            info!("sensor recovered after {:?}: {} um", fault, position_um);
            self.fault = None;
        }
        let drive = core::mem::take(&mut self.drive_pending).then_some(active.drive);
        // The region first (position only), then what it needs: a region whose texture reads
        // no velocity rests the estimator (its window kept, the sums not), and the first
        // sample of one that reads it wakes it whole (docs/sample-contract.md).
        let region = match self.region {
            None => active.regions.lookup(position_um),
            Some(r) => active.regions.track(r, position_um),
        };
        if self.region != Some(region) {
            // Wakes a resting estimator: off the per-sample path, which then tests one bit.
            self.note_region_change(region, position_um, t_us);
        }
        let velocity_um_s = match self.sample_mode {
            SampleMode::Update => self.estimator.update(position_um, t_us),
            SampleMode::Rest => {
                self.estimator.rest(position_um, t_us);
                self.resting = true;
                None
            }
            SampleMode::Sleep => None,
        };
        let mut out = Output {
            position_um: Some(position_um),
            velocity_um_s,
            region: Some(region),
            drive,
            ..Output::default()
        };
        // Lines overlay every region: inside a line pulse or its rest the pulse owns the gate.
        if !self.lines_step(position_um, velocity_um_s, t_us, &mut out) {
            self.texture_step(region, position_um, velocity_um_s, t_us, &mut out);
        }
        self.velocity_um_s = velocity_um_s;
        let t = &mut self.telemetry;
        t.position_um = position_um;
        t.region = region;
        out
    }

    /// Lines: fires a pulse on a crossing, and owns the gate and the amplitude during a pulse
    /// and its rest. True while they own them (the region's texture is not asked).
    #[inline(always)]
    fn lines_step(
        &mut self,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        out: &mut Output,
    ) -> bool {
        let Some(active) = self.active.as_ref() else {
            return false;
        };
        let Some(lines) = active.lines.as_ref() else {
            return false;
        };
        let limits = active.limits;
        let envelope = lines.envelope();
        match self.lines.step(lines, position_um, velocity_um_s, t_us) {
            LineStep::Free => false,
            LineStep::Window { skipped } => {
                // The port plays the pulse's envelope by itself; nothing to send.
                if skipped {
                    self.telemetry.lines_skipped = self.telemetry.lines_skipped.wrapping_add(1);
                    debug!("line crossed during a pulse's rest: skipped to keep the duty cap");
                }
                true
            }
            LineStep::Fire {
                line,
                pulse,
                amplitude_permille,
            } => {
                let action = self.gate.pulse(pulse, t_us, &self.timer, &limits);
                self.count_action(action);
                if !matches!(action, Some(GateAction::Pulse(_))) {
                    // A burst is running or resting: a pulse now would break the duty cap.
                    self.telemetry.lines_skipped = self.telemetry.lines_skipped.wrapping_add(1);
                    debug!(
                        "line {} crossed at {} um while the duty cap is spent: skipped",
                        line, position_um
                    );
                    return false;
                }
                self.lines.started(t_us);
                self.note_pulse(t_us);
                self.telemetry.line_pulses = self.telemetry.line_pulses.wrapping_add(1);
                debug!("line {} crossed at {} um: pulse", line, position_um);
                out.action = action;
                out.line = Some(line);
                out.envelope = Some(envelope);
                out.amplitude_permille = self.set_amplitude(amplitude_permille);
                true
            }
        }
    }

    /// The region's texture asks; the gate answers within the caps.
    #[inline(always)]
    fn texture_step(
        &mut self,
        region: u8,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        out: &mut Output,
    ) {
        let Some(active) = self.active.as_mut() else {
            return;
        };
        let now = Moment {
            position_um,
            velocity_um_s,
            t_us,
            gate: &self.gate,
            timer: &self.timer,
        };
        let request = match active.compiled.get_mut(region as usize) {
            Some(c) => c.request(&now),
            None => Request::OFF,
        };
        if request.clamped {
            self.telemetry.clamped = self.telemetry.clamped.wrapping_add(1);
            if self.clamp_log.due(t_us) {
                warn!(
                    "region {}: f_b above the board limit {} Hz, clamped ({} more)",
                    region,
                    self.timer.max_burst_hz,
                    self.clamp_log.take_suppressed()
                );
            }
        }
        let mut skipped = request.skipped;
        out.action = match (request.want, request.settings) {
            (Want::Pulse, Some(p)) => {
                let limits = self.limits();
                let action = self.gate.pulse(p, t_us, &self.timer, &limits);
                if matches!(action, Some(GateAction::Pulse(_))) {
                    self.telemetry.ridge_pulses = self.telemetry.ridge_pulses.wrapping_add(1);
                    self.note_pulse(t_us);
                    out.envelope = Some(Envelope::Rectangular);
                } else {
                    // Inside the duty cap's rest after the previous pulse.
                    skipped += 1;
                }
                self.count_action(action);
                action
            }
            (Want::EndPulse, _) => {
                let action = self.gate.end_pulse(t_us, &self.limits());
                self.count_action(action);
                action
            }
            _ => self.drive(request.settings, t_us),
        };
        if skipped > 0 {
            self.telemetry.ridges_skipped = self.telemetry.ridges_skipped.wrapping_add(skipped);
            debug!(
                "region {}: {} ridge crossings without a pulse",
                region, skipped
            );
        }
        // u16::MAX leaves the amplitude as it is; the same ask as the last changes nothing.
        if request.amplitude != u16::MAX && request.amplitude != self.amplitude_asked {
            out.amplitude_permille = self.set_amplitude(request.amplitude);
        }
    }

    /// Checks the stale-sensor watchdog at `now_us`; call it from a timer at least every few
    /// sample periods. Returns the off action when the sensor has gone quiet.
    pub fn on_tick(&mut self, now_us: u32) -> Option<GateAction> {
        let active = self.active.as_ref()?;
        let stale_after = active.stale_after_us;
        // A scene installed since the last sample may have tightened the caps. The burst the
        // old scene left running reloads its settings every period until a sample re-plans it,
        // which a dropout can put off for up to the stale limit: stop it now if the new caps
        // do not allow it (the soak found 200 µs pulses running on under a 38 µs cap).
        if core::mem::take(&mut self.caps_pending) {
            let limits = active.limits;
            if let Some(r) = self.gate.running() {
                if !limits.allows(&self.timer, &r) {
                    let action = self.gate.force_off(now_us, &self.timer, &limits);
                    self.count_action(action);
                    return action;
                }
            }
        }
        let last = self.last_sample_us?;
        if now_us.wrapping_sub(last) > stale_after && self.fault != Some(SensorFault::Stale) {
            return self.enter_fault(SensorFault::Stale, now_us).action;
        }
        None
    }

    /// Polls a position source once and applies the result to a burst output.
    pub fn poll<P: PositionSource, B: BurstOutput>(
        &mut self,
        source: &mut P,
        out: &mut B,
    ) -> Option<Output> {
        let sample = source.next_sample()?;
        let output = self.on_sample(sample);
        apply(&output, out);
        Some(output)
    }

    fn enter_fault(&mut self, fault: SensorFault, t_us: u32) -> Output {
        if self.fault != Some(fault) {
            self.telemetry.faults = self.telemetry.faults.wrapping_add(1);
            error!("sensor fault {:?}: carrier off", fault);
        }
        self.fault = Some(fault);
        self.good_run = 0;
        self.estimator.reset();
        self.resting = false;
        // The textures' fits are reset below: nothing to seed from, the region is found anew.
        self.sample_mode = SampleMode::Update;
        self.velocity_um_s = None;
        self.region = None;
        self.lines.cut();
        if let Some(active) = self.active.as_mut() {
            active.compiled.iter_mut().for_each(Render::reset);
        }
        self.telemetry.position_um = -1;
        self.telemetry.region = u8::MAX;
        // No pulse while the sensor is faulty: the rate starts again from two new pulses.
        self.pulse_us[1].set(None);
        let limits = self.limits();
        let action = self.gate.force_off(t_us, &self.timer, &limits);
        self.count_action(action);
        Output {
            action,
            fault: Some(fault),
            ..Output::default()
        }
    }

    fn note_region_change(&mut self, region: u8, position_um: i32, t_us: u32) {
        // Leaving a region where the estimator slept: seeded from that region's fit, O(window).
        self.leave_sleep();
        // Whatever the new region needs: a wake is exact, idempotent and O(1).
        self.wake_estimator();
        if self.region.is_some() {
            self.telemetry.region_switches = self.telemetry.region_switches.wrapping_add(1);
        }
        self.region = Some(region);
        self.sample_mode = self.mode_of(region);
        if let Some(c) = self
            .active
            .as_mut()
            .and_then(|a| a.compiled.get_mut(region as usize))
        {
            c.reset();
        }
        if self.region_log.due(t_us) {
            info!(
                "region {} at {} um ({} changes not logged)",
                region,
                position_um,
                self.region_log.take_suppressed()
            );
        }
    }

    /// The level cap is the last word: full drive and the top of a random spread play at it.
    fn set_amplitude(&mut self, permille: u16) -> Option<u16> {
        self.amplitude_asked = permille;
        let permille = permille.min(self.level_cap_permille);
        (self.amplitude != Some(permille)).then(|| {
            self.amplitude = Some(permille);
            permille
        })
    }

    /// The active caps (the defaults before any scene loads).
    fn limits(&self) -> SafetyLimits {
        self.active.as_ref().map(|a| a.limits).unwrap_or_default()
    }

    fn drive(&mut self, desired: Option<TimerSettings>, t_us: u32) -> Option<GateAction> {
        // The common cases, a burst running unchanged, the line idle and staying so, or a
        // one-pulse still on, before the caps are even fetched.
        if self.gate.quiet(desired, t_us) {
            return None;
        }
        let limits = self.limits();
        let action = self.gate.request(desired, t_us, &self.timer, &limits);
        self.count_action(action);
        action
    }

    fn count_action(&mut self, action: Option<GateAction>) {
        if action.is_some() {
            self.telemetry.gate_actions = self.telemetry.gate_actions.wrapping_add(1);
        }
    }
}

/// Sends one output's changes to a burst port: drive mode first, then amplitude and envelope,
/// then the line.
pub fn apply<B: BurstOutput>(output: &Output, out: &mut B) {
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
    use crate::burst::{BurstCommand, BurstError};
    use crate::position::Calibration;
    use crate::position::CalibrationError;
    use crate::region::RegionError;
    use crate::scene::default_config;
    use crate::texture::TextureError;
    use crate::texture::{GratingRender, Texture};
    use crate::velocity::EstimatorError;

    const TIMER: BurstTimer = crate::burst::TEST_TIMER;

    fn loaded() -> Controller {
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&default_config()).unwrap();
        c
    }

    fn code_at(c: &Controller, um: f32) -> u16 {
        c.mapper().unwrap().code_at_um(um) as u16
    }

    /// Feeds `n` samples at `um`, returns the last output and every action seen.
    fn feed(c: &mut Controller, um: f32, t0: &mut u32, n: usize) -> (Output, usize) {
        let code = code_at(c, um);
        let mut last = Output::default();
        let mut actions = 0;
        for _ in 0..n {
            last = c.on_sample(Sample { code, t_us: *t0 });
            actions += last.action.is_some() as usize;
            *t0 += 100;
        }
        (last, actions)
    }

    #[test]
    fn nothing_runs_before_a_scene_loads() {
        let mut c = Controller::new(TIMER, 100).unwrap();
        // Telemetry says "no position, no region" (-1, 255), not "at 0 µm in region 0".
        let t = c.telemetry();
        assert_eq!((t.position_um, t.region), (-1, u8::MAX));
        let out = c.on_sample(Sample {
            code: 30_000,
            t_us: 0,
        });
        assert_eq!(out.action, None);
        assert_eq!(out.region, None);
    }

    /// Telemetry's burst frequency follows the running burst through every region and back
    /// (the default scene's 20 / 80 / 1000 Hz; TEST_TIMER's 90 MHz divides each exactly), and
    /// reads 0 with the line off: the memo of the last division is keyed by the period, so a
    /// stale figure from the previous region would show here.
    #[test]
    fn telemetry_follows_the_running_burst() {
        let mut c = loaded();
        let mut t = 0;
        assert_eq!(c.telemetry().burst_millihz, 0);
        for (um, millihz) in [
            (5_000.0, 20_000),
            (30_000.0, 80_000),
            (55_000.0, 1_000_000),
            (30_000.0, 80_000),
            (5_000.0, 20_000),
            (55_000.0, 1_000_000),
        ] {
            // Long enough at each spot for the duty window to let the burst start.
            let _ = feed(&mut c, um, &mut t, 3_000);
            assert_eq!(c.telemetry().burst_millihz, millihz, "at {um} um");
            // Asked twice, the same figure (the memo's path).
            assert_eq!(c.telemetry().burst_millihz, millihz, "at {um} um, again");
        }
        let mut cfg = default_config();
        cfg.scene.textures[2] = Texture::Off;
        c.load(&cfg).unwrap();
        let _ = feed(&mut c, 55_000.0, &mut t, 10);
        assert_eq!(c.telemetry().burst_millihz, 0);
    }

    /// The telemetry's gate-action counter counts every action the controller hands the port:
    /// starts and changes through every region, the fault's off, and the recovery's start
    /// (counted here from the outputs themselves).
    #[test]
    fn telemetry_counts_every_gate_action() {
        let mut c = loaded();
        let mut t = 0;
        let mut seen = 0;
        for um in [5_000.0, 30_000.0, 55_000.0, 30_000.0] {
            seen += feed(&mut c, um, &mut t, 3_000).1;
        }
        // A rail fault turns the line off; the sensor comes back and the burst starts again.
        for _ in 0..3 {
            let out = c.on_sample(Sample { code: 0, t_us: t });
            seen += out.action.is_some() as usize;
            t += 100;
        }
        seen += feed(&mut c, 5_000.0, &mut t, 3_000).1;
        assert!(
            seen >= 6,
            "{seen} actions: a start per region, the off and the restart"
        );
        assert_eq!(c.telemetry().gate_actions as usize, seen);
    }

    #[test]
    fn region_drives_the_gate() {
        let mut c = loaded();
        let mut t = 0;
        let (out, _) = feed(&mut c, 5_000.0, &mut t, 1);
        assert_eq!(out.region, Some(0));
        let Some(GateAction::Start(s)) = out.action else {
            panic!("{out:?}")
        };
        assert_eq!(s.produced_millihz(TIMER.clock_hz), 20_000);
        let (out, _) = feed(&mut c, 30_000.0, &mut t, 1);
        let Some(GateAction::Update(s)) = out.action else {
            panic!("{out:?}")
        };
        assert_eq!(s.produced_millihz(TIMER.clock_hz), 80_000);
    }

    #[test]
    fn rail_turns_the_line_off_on_the_same_sample_and_recovers_after_a_run() {
        let mut c = loaded();
        let mut t = 0;
        feed(&mut c, 5_000.0, &mut t, 40);
        let fault_t = t;
        let out = c.on_sample(Sample { code: 0, t_us: t });
        t += 100;
        assert_eq!(out.action, Some(GateAction::Off));
        assert_eq!(out.fault, Some(SensorFault::RailLow));
        let tm = c.telemetry();
        assert_eq!((tm.position_um, tm.region), (-1, u8::MAX));
        // Good samples shorter than the recovery run keep it off.
        let (out, actions) = feed(&mut c, 5_000.0, &mut t, RECOVERY_SAMPLES as usize - 1);
        assert_eq!(actions, 0);
        assert_eq!(out.fault, Some(SensorFault::RailLow));
        // While recovering the position is reported (the sensor reads again), nothing else.
        let p = out.position_um.expect("position while recovering");
        assert!((4_900..=5_100).contains(&p), "{p} um");
        assert_eq!((out.region, out.velocity_um_s), (None, None));
        let (out, _) = feed(&mut c, 5_000.0, &mut t, 1);
        assert_eq!(out.fault, None);
        // The 20 Hz region's burst ran 4 ms before the fault, recorded as 40 % of it plus the
        // 60 % of its 20 ms on-time a partial period may add: 1.6 + 12 = 13.6 ms. A restart's
        // own worst partial period is 12 ms again, and 13.6 + 12 ≤ 30 ms, the slack a 40 %
        // burst leaves under a 50 % cap in a 300 ms window: it restarts with the first sample
        // out of the fault (the per-pulse rule made it wait 20 ms).
        assert!(matches!(out.action, Some(GateAction::Start(_))), "{out:?}");
        assert_eq!(t - 100 - fault_t, 1_600);
        assert_eq!(c.telemetry().faults, 1);
    }

    #[test]
    fn stale_sensor_turns_the_line_off() {
        let mut c = loaded();
        let mut t = 0;
        feed(&mut c, 5_000.0, &mut t, 10);
        let last = t - 100;
        assert_eq!(c.on_tick(t + 1_000), None);
        // Stale after exactly 5 ms of silence: not at 5 ms, at 5 ms + 1 µs.
        assert_eq!(c.on_tick(last + 5_000), None);
        assert_eq!(c.on_tick(last + 5_001), Some(GateAction::Off));
        assert_eq!(c.on_tick(t + 7_000), None);
        assert_eq!(c.telemetry().faults, 1);
    }

    /// A scene with a tighter on-time cap, installed while no samples come (a dropout shorter
    /// than the stale limit), stops the burst the old scene left running at the next tick
    /// instead of letting it reload its 20 ms pulses until a sample arrives; a scene whose caps
    /// allow the running burst leaves it alone, and a tick after a sample has nothing to redo.
    #[test]
    fn tighter_caps_stop_the_running_burst_at_the_next_tick() {
        let mut c = loaded();
        let mut t = 0;
        let (out, _) = feed(&mut c, 5_000.0, &mut t, 3);
        let Some(running) = c.gate.running() else {
            panic!("no burst running: {out:?}")
        };
        assert_eq!(running.on_clocks(), TIMER.clock_hz as u64 / 50);
        let mut loose = default_config();
        loose.limits.max_on_time_us = 30_000;
        c.load(&loose).unwrap();
        assert_eq!(
            c.on_tick(t),
            None,
            "the running burst is inside the new caps"
        );
        let mut tight = default_config();
        tight.limits.max_on_time_us = 10_000;
        c.load(&tight).unwrap();
        assert_eq!(c.on_tick(t + 10), Some(GateAction::Off));
        assert_eq!(c.gate.running(), None);
        assert_eq!(c.on_tick(t + 20), None);
        // After a sample the new scene's own plan runs: nothing left for a tick to stop.
        c.load(&default_config()).unwrap();
        feed(&mut c, 5_000.0, &mut t, 1);
        c.load(&tight).unwrap();
        feed(&mut c, 5_000.0, &mut t, 1);
        assert_eq!(c.on_tick(t), None);
    }

    /// The ports: `poll` takes one sample from a source, runs it and applies the action to the
    /// output, and returns what `on_sample` would have (the same as a second controller fed
    /// directly); with no sample ready it does nothing.
    #[test]
    fn poll_joins_the_ports() {
        struct Source(std::vec::Vec<Sample>);
        impl PositionSource for Source {
            fn next_sample(&mut self) -> Option<Sample> {
                (!self.0.is_empty()).then(|| self.0.remove(0))
            }
        }
        #[derive(Default)]
        struct Out(std::vec::Vec<GateAction>);
        impl BurstOutput for Out {
            fn apply(&mut self, action: GateAction) {
                self.0.push(action);
            }
        }
        let mut direct = loaded();
        let code = code_at(&direct, 5_000.0);
        let samples: std::vec::Vec<Sample> = (0..100)
            .map(|i| Sample {
                code,
                t_us: i * 100,
            })
            .collect();
        let mut polled = loaded();
        let mut src = Source(samples.clone());
        let mut out = Out::default();
        for s in &samples {
            assert_eq!(polled.poll(&mut src, &mut out), Some(direct.on_sample(*s)));
        }
        assert_eq!(polled.poll(&mut src, &mut out), None);
        // The 20 Hz region starts once, and that is all the output saw.
        assert_eq!(out.0.len(), 1);
        assert!(matches!(out.0[0], GateAction::Start(_)));
    }

    /// Each bad configuration is rejected with its own error and the running scene is untouched.
    #[test]
    fn bad_configs_rejected_previous_kept() {
        let mut c = loaded();
        let mut t = 0;
        let (before, _) = feed(&mut c, 30_000.0, &mut t, 1);
        let good = default_config();
        let mut cases: heapless::Vec<(Config, ConfigError), 16> = heapless::Vec::new();
        let mut cfg = good.clone();
        cfg.calibration = Calibration {
            code_at_start: good.calibration.code_at_end,
            code_at_end: good.calibration.code_at_start,
            ..good.calibration
        };
        let swapped = CalibrationError::EndsSwapped {
            code_at_start: good.calibration.code_at_end,
            code_at_end: good.calibration.code_at_start,
        };
        let _ = cases.push((cfg, ConfigError::Calibration(swapped)));
        let mut cfg = good.clone();
        cfg.calibration.code_at_end = cfg.calibration.code_at_start + 100;
        let _ = cases.push((
            cfg,
            ConfigError::Calibration(CalibrationError::EndsTooClose {
                span_code: 100,
                min_span_code: crate::position::MIN_SPAN_CODE,
            }),
        ));
        let mut cfg = good.clone();
        cfg.scene.boundaries_um[1] = cfg.scene.boundaries_um[0] - 1;
        let unsorted = RegionError::Unsorted {
            index: 1,
            at_um: good.scene.boundaries_um[0] - 1,
            previous_um: good.scene.boundaries_um[0],
        };
        let _ = cases.push((cfg, ConfigError::Region(unsorted)));
        for (hz_milli, duty, err) in [
            (0, 400, BurstError::ZeroFrequency),
            (
                5_000_001,
                400,
                BurstError::AboveBoardLimit {
                    burst_millihz: 5_000_001,
                    max_millihz: 5_000_000,
                },
            ),
            (80_000, 0, BurstError::BadDuty { duty_permille: 0 }),
            (
                80_000,
                501,
                BurstError::DutyAboveCap {
                    duty_permille: 501,
                    cap_permille: 500,
                },
            ),
        ] {
            let mut cfg = good.clone();
            cfg.scene.textures[1] = Texture::Constant(BurstCommand {
                burst_millihz: hz_milli,
                duty_permille: duty,
            });
            let _ = cases.push((
                cfg,
                ConfigError::Texture {
                    region: 1,
                    error: err,
                },
            ));
        }
        let mut cfg = good.clone();
        cfg.limits.max_duty_permille = 1001;
        let _ = cases.push((
            cfg,
            ConfigError::Limits(BurstError::BadDuty {
                duty_permille: 1001,
            }),
        ));
        // The stale-sensor limit: at least two sample periods (200 µs here), at most 1 s.
        for stale_after_us in [199, 1_000_001] {
            let mut cfg = good.clone();
            cfg.stale_after_us = stale_after_us;
            let _ = cases.push((
                cfg,
                ConfigError::StaleLimit {
                    stale_after_us,
                    min_us: 200,
                },
            ));
        }
        for (cfg, err) in cases.iter() {
            assert_eq!(c.load(cfg), Err(*err));
            // Same input, same output: the old scene is still the one running.
            let out = c.on_sample(Sample {
                code: code_at(&c, 30_000.0),
                t_us: t,
            });
            t += 100;
            assert_eq!(out.region, before.region);
            assert_eq!(out.action, None, "gate changed after rejected {err:?}");
        }
        assert_eq!(c.telemetry().burst_millihz, 80_000);
        for stale_after_us in [200, 1_000_000] {
            let mut cfg = good.clone();
            cfg.stale_after_us = stale_after_us;
            assert_eq!(c.load(&cfg), Ok(()), "stale_after_us {stale_after_us}");
        }
    }

    /// A one-region scene with `texture` (and optional lines).
    fn single(texture: Texture, lines: &[u32]) -> Controller {
        single_with(texture, lines, Envelope::Triangular)
    }

    fn single_with(texture: Texture, lines: &[u32], envelope: Envelope) -> Controller {
        let mut cfg = default_config();
        cfg.scene.lines.envelope = envelope;
        cfg.scene.boundaries_um.clear();
        cfg.scene.textures.clear();
        let _ = cfg.scene.textures.push(texture);
        for &l in lines {
            let _ = cfg.scene.lines.positions_um.push(l);
        }
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&cfg).unwrap();
        c
    }

    /// Moves at `speed_um_s` from `from_um` for `n` samples; returns every output.
    fn stroke(
        c: &mut Controller,
        from_um: f32,
        speed_um_s: f32,
        t: &mut u32,
        n: usize,
    ) -> std::vec::Vec<Output> {
        (0..n)
            .map(|i| {
                let um = from_um + speed_um_s * i as f32 * 1e-4;
                let out = c.on_sample(Sample {
                    code: code_at(c, um),
                    t_us: *t,
                });
                *t += 100;
                out
            })
            .collect()
    }

    fn last_settings(outs: &[Output]) -> Option<TimerSettings> {
        outs.iter().rev().find_map(|o| match o.action {
            Some(GateAction::Start(s) | GateAction::Update(s)) => Some(s),
            _ => None,
        })
    }

    /// A grating rendered by velocity synthesis.
    /// A random texture around 100 Hz (±10 %), full amplitude, 40 % duty, seed 7.
    fn random_100hz() -> Texture {
        Texture::Random(crate::texture::RandomBurst {
            center_millihz: 100_000,
            spread_permille: 100,
            amplitude_permille: 1000,
            amplitude_spread_permille: 0,
            duty_permille: 400,
            seed: 7,
        })
    }

    fn synth(wavelength_um: u32) -> Texture {
        Texture::Grating(crate::texture::Grating {
            render: GratingRender::VelocitySynthesis,
            ..crate::texture::Grating::new(wavelength_um)
        })
    }

    #[test]
    fn grating_frequency_follows_speed_and_rests_silent() {
        for speed in [20_000.0f32, 50_000.0, 150_000.0] {
            let mut c = single(synth(1_000), &[]);
            let mut t = 0;
            let outs = stroke(&mut c, 5_000.0, speed, &mut t, 200);
            let s = last_settings(&outs).expect("bursts while moving");
            let hz = s.produced_millihz(TIMER.clock_hz) as f32 / 1000.0;
            // f = V/λ with V in mm/s and λ = 1 mm; 1 µm code quantization bounds the error.
            assert!(
                (hz - speed / 1000.0).abs() / (speed / 1000.0) < 0.02,
                "{speed}: {hz} Hz"
            );
        }
        let mut c = single(synth(1_000), &[]);
        let mut t = 0;
        let outs = stroke(&mut c, 30_000.0, 0.0, &mut t, 10_000);
        assert!(outs.iter().all(|o| o.action.is_none()), "bursts at rest");
    }

    #[test]
    fn material_follows_stick_slip_model() {
        let m = crate::texture::Material::fig5(0.3);
        let mut c = single(Texture::Material(m), &[]);
        let mut t = 0;
        let outs = stroke(&mut c, 5_000.0, 40_000.0, &mut t, 400);
        let s = last_settings(&outs).unwrap();
        let hz = s.produced_millihz(TIMER.clock_hz) as f32 / 1000.0;
        // [N] eq. 10–12 by hand, fig. 5's finger (P = 1 N, m = 1 g, k = 500 N/m), Δμ = 0.3,
        // U = 40 mm/s = 0.04 m/s:
        //   ω0 = √(500/0.001) = √500 000 = 707.107 rad/s
        //   R  = Δμ P/(m ω0 U) = 0.3/(0.001 · 707.107 · 0.04) = 0.3/0.028284 = 10.6066
        //   atan R = π/2 − atan(1/R) = 1.570796 − 0.094003 = 1.476793
        //   π − atan R + R = 3.141593 − 1.476793 + 10.606602 = 12.271401
        //   f⁻¹ = (2/ω0)(π − atan R + R) = 0.0028284 · 12.271401 = 0.0347088 s → f = 28.811 Hz
        let want = 28.811f32;
        assert!((hz - want).abs() / want < 0.02, "{hz} vs {want}");
    }

    #[test]
    fn random_bursts_stay_in_spread_and_reproduce() {
        let r = crate::texture::RandomBurst {
            center_millihz: 80_000,
            spread_permille: 250,
            amplitude_permille: 800,
            amplitude_spread_permille: 200,
            duty_permille: 400,
            seed: 11,
        };
        let run = || {
            let mut c = single(Texture::Random(r), &[]);
            let mut t = 0;
            stroke(&mut c, 30_000.0, 0.0, &mut t, 20_000)
        };
        let a = run();
        assert_eq!(a, run());
        let mut changes = 0;
        for o in &a {
            if let Some(GateAction::Start(s) | GateAction::Update(s)) = o.action {
                let hz = s.produced_millihz(TIMER.clock_hz) as f32 / 1000.0;
                assert!((59.9..=100.1).contains(&hz), "{hz}");
                changes += 1;
            }
            if let Some(amp) = o.amplitude_permille {
                assert!((640..=960).contains(&amp), "{amp}");
            }
        }
        // 2 s at ~80 Hz: one draw per burst.
        assert!((140..=180).contains(&changes), "{changes}");
        // Between draws the running burst is kept: the line never goes off.
        let offs = a
            .iter()
            .filter(|o| o.action == Some(GateAction::Off))
            .count();
        assert_eq!(offs, 0, "the line went off between draws");
    }

    #[test]
    fn lines_fire_once_per_crossing_and_faults_cut_pulses() {
        let mut c = single(Texture::Off, &[20_000, 40_000]);
        let mut t = 0;
        // 100 mm/s from 10 mm to 50 mm and back.
        let mut outs = stroke(&mut c, 10_000.0, 100_000.0, &mut t, 4_000);
        outs.extend(stroke(&mut c, 50_000.0, -100_000.0, &mut t, 4_000));
        let pulses = outs
            .iter()
            .filter(|o| matches!(o.action, Some(GateAction::Pulse(_))))
            .count();
        assert_eq!(pulses, 4);
        let fired: std::vec::Vec<u8> = outs.iter().filter_map(|o| o.line).collect();
        assert_eq!(fired, [0, 1, 1, 0]);
        // Each is the scene's 10 ms pulse: 900 000 clocks of the 90 MHz timer, one tick low.
        for o in &outs {
            if let Some(GateAction::Pulse(s)) = o.action {
                assert_eq!((s.psc, s.arr, s.ccr), (0, 900_000, 900_000));
            }
        }
        // Outputs carry the estimate: 100 mm/s mid-stroke (within the 16 µm quantization).
        let v = outs[2_000].velocity_um_s.expect("velocity mid-stroke");
        assert!((95_000..=105_000).contains(&v), "{v} um/s");
        // Arriving on a line is a crossing (one pulse); resting there fires nothing more.
        let rest = stroke(&mut c, 20_000.0, 0.0, &mut t, 5_000);
        assert_eq!(rest[0].line, Some(0));
        assert!(rest[1..].iter().all(|o| o.line.is_none()));
        // A rail fault in the middle of a pulse cuts it.
        let mut c = single(Texture::Off, &[20_000]);
        let mut t = 0;
        let outs = stroke(&mut c, 19_000.0, 100_000.0, &mut t, 120);
        assert!(outs
            .iter()
            .any(|o| matches!(o.action, Some(GateAction::Pulse(_)))));
        let out = c.on_sample(Sample { code: 0, t_us: t });
        assert_eq!(out.action, Some(GateAction::Off));
    }

    /// A line's pulse owns the enable line for its window: the 10 ms pulse plus the cap's
    /// 10 ms rest (50 %). The pulse goes out with its level and its envelope (the port plays
    /// it); inside the window nothing more is sent — no 100 µs staircase —
    /// and a second line crossed is skipped and counted; crossed at exactly 20 ms it fires.
    #[test]
    fn line_window_holds_the_envelope_and_skips_inside_it() {
        for (cross_at_us, fires) in [(19_900u32, false), (20_000, true)] {
            // Rectangles fire on the crossing itself (a triangle fires ahead by the velocity,
            // which these position jumps make meaningless).
            let mut c = single_with(Texture::Off, &[20_000, 21_000], Envelope::Rectangular);
            let mut outs = std::vec::Vec::new();
            // Below line 0 (arming both), over it at 1 ms, then between the lines until the
            // second crossing `cross_at_us` after the first.
            for t in (0..=40_000u32).step_by(100) {
                let um = match t {
                    0..1_000 => 19_500.0,
                    _ if t < 1_000 + cross_at_us => 20_500.0,
                    _ => 21_100.0,
                };
                outs.push(c.on_sample(Sample {
                    code: code_at(&c, um),
                    t_us: t,
                }));
            }
            let at = |t_us: u32| outs[(t_us / 100) as usize];
            assert_eq!(at(1_000).line, Some(0));
            assert!(matches!(at(1_000).action, Some(GateAction::Pulse(_))));
            assert_eq!(at(1_000).envelope, Some(Envelope::Rectangular));
            // The first sample (the texture's) already set full drive: the peak is no change.
            assert!(outs[..10]
                .iter()
                .any(|o| o.amplitude_permille == Some(1000)));
            let window = &outs[(1_000 + 100) / 100..(1_000 + 19_900) / 100];
            assert!(window
                .iter()
                .all(|o| o.amplitude_permille.is_none() && o.envelope.is_none()));
            let second = at(1_000 + cross_at_us);
            let tm = c.telemetry();
            if fires {
                assert_eq!(second.line, Some(1));
                assert_eq!((tm.line_pulses, tm.lines_skipped), (2, 0));
            } else {
                assert_eq!(second.line, None);
                assert_eq!((tm.line_pulses, tm.lines_skipped), (1, 1));
            }
        }
    }

    /// The pulses of `outs` as (sample index, on-time in µs): the timer's length, or less when
    /// an Off came first.
    fn pulses(outs: &[Output]) -> std::vec::Vec<(usize, f32)> {
        outs.iter()
            .enumerate()
            .filter_map(|(i, o)| match o.action {
                Some(GateAction::Pulse(s)) => {
                    let timer_us = s.on_clocks() as f32 * 1e6 / TIMER.clock_hz as f32;
                    let cut_us = outs[i + 1..]
                        .iter()
                        .position(|o| o.action.is_some())
                        .filter(|&j| outs[i + 1 + j].action == Some(GateAction::Off))
                        .map_or(f32::MAX, |j| (j + 1) as f32 * 100.0);
                    Some((i, timer_us.min(cut_us)))
                }
                _ => None,
            })
            .collect()
    }

    /// The default scene cut to two regions split at 30 mm.
    fn two_config(below: Texture, above: Texture) -> Config {
        let mut cfg = default_config();
        cfg.scene.boundaries_um.clear();
        cfg.scene.textures.clear();
        let _ = cfg.scene.boundaries_um.push(30_000);
        let _ = cfg.scene.textures.push(below);
        let _ = cfg.scene.textures.push(above);
        cfg
    }

    /// Two regions split at 30 mm.
    fn two(below: Texture, above: Texture) -> Controller {
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&two_config(below, above)).unwrap();
        c
    }

    /// A hybrid grating of λ = 1 mm.
    fn hybrid_1mm() -> Texture {
        Texture::Grating(crate::texture::Grating {
            render: GratingRender::Hybrid,
            ..crate::texture::Grating::new(1_000)
        })
    }

    /// Up from 20 to 50 mm at 50 mm/s and back, one position (µm) per 100 µs sample.
    fn up_and_back() -> impl Iterator<Item = f32> {
        (0..1_200).map(|k| 20_000.0 + 50.0 * (600 - (k as i32 - 600).abs()) as f32)
    }

    /// The sample path's contract (docs/sample-contract.md): below 30 mm an `off` region, where
    /// the estimator rests (no velocity in the output), above it a velocity-synthesis grating,
    /// where it runs. A stroke up and back at 50 mm/s: every output but the velocity field is
    /// the one of a controller updating the estimator on every sample; the velocity is there
    /// wherever a texture reads it, the same figure, and asked for (`velocity_um_s`) anywhere;
    /// the grating's bursts follow |V|/λ from its first sample on (no warm-up on entry).
    #[test]
    fn the_estimator_rests_where_no_velocity_is_read_and_wakes_whole() {
        let mut rests = two(Texture::Off, synth(1_000));
        let mut always = two(Texture::Off, synth(1_000));
        always.velocity_every_sample(true);
        let (mut rested, mut computed, mut t) = (0, 0, 0u32);
        for um in up_and_back() {
            let code = code_at(&rests, um);
            let a = rests.on_sample(Sample { code, t_us: t });
            let b = always.on_sample(Sample { code, t_us: t });
            t += 100;
            assert_eq!(
                Output {
                    velocity_um_s: None,
                    ..a
                },
                Output {
                    velocity_um_s: None,
                    ..b
                },
                "{um} µm"
            );
            assert_eq!(rests.velocity_um_s(), b.velocity_um_s, "{um} µm: asked");
            assert_eq!(rests.telemetry(), always.telemetry(), "{um} µm");
            match a.region {
                Some(0) if b.velocity_um_s.is_some() => {
                    assert_eq!(a.velocity_um_s, None, "{um} µm: rested");
                    rested += 1;
                }
                Some(1) => {
                    assert_eq!(a.velocity_um_s, b.velocity_um_s, "{um} µm");
                    assert!(a.velocity_um_s.is_some(), "{um} µm: warm on entry");
                    computed += 1;
                }
                _ => {}
            }
        }
        // 20 → 50 → 20 mm: 200 samples each way below the boundary, 400 above it.
        assert!(
            rested > 300 && computed > 700,
            "{rested} rested, {computed} computed"
        );
        // Telling it to update on every sample wakes it: nothing rests from then on.
        rests.velocity_every_sample(true);
        let (o, _) = feed(&mut rests, 25_000.0, &mut t, 40);
        assert_eq!(o.velocity_um_s, Some(0));
    }

    /// The hybrid's region lets the estimator sleep (its own line is the velocity) and seeds it
    /// from that line's newest positions on leaving: below 30 mm a hybrid grating, above it a
    /// velocity-synthesis grating, a stroke up and back at 50 mm/s. Every output but the
    /// velocity field is the one of a controller updating the estimator on every sample, and
    /// above 30 mm the velocity is the same figure from the first sample on (the seed is the
    /// window an estimator fed all along holds); below, the velocity asked for is the hybrid's
    /// line's, within 1 mm/s of the estimator's on this steady stroke.
    #[test]
    fn a_sleeping_estimator_is_seeded_whole_from_the_hybrids_line() {
        let mut sleeps = two(hybrid_1mm(), synth(1_000));
        let mut always = two(hybrid_1mm(), synth(1_000));
        always.velocity_every_sample(true);
        let (mut slept, mut entries, mut t) = (0, 0, 0u32);
        let (mut last_region, mut refilling) = (None, 0);
        for um in up_and_back() {
            let code = code_at(&sleeps, um);
            let a = sleeps.on_sample(Sample { code, t_us: t });
            let b = always.on_sample(Sample { code, t_us: t });
            t += 100;
            let strip = |o: Output| Output {
                velocity_um_s: None,
                ..o
            };
            assert_eq!(strip(a), strip(b), "{um} µm");
            match a.region {
                Some(0) if b.velocity_um_s.is_some() => {
                    assert_eq!(a.velocity_um_s, None, "{um} µm: asleep");
                    // The line has a velocity once its 64-sample window is full; until then
                    // the asked velocity is None where a resting estimator would answer.
                    match sleeps.velocity_um_s() {
                        Some(own) => {
                            let est = b.velocity_um_s.unwrap_or(0);
                            assert!(own.abs_diff(est) <= 1_000, "{um} µm: own {own}, est {est}");
                            slept += 1;
                        }
                        None => refilling += 1,
                    }
                }
                Some(1) => {
                    if last_region == Some(0) {
                        entries += 1;
                    }
                    assert_eq!(a.velocity_um_s, b.velocity_um_s, "{um} µm: seeded");
                    assert!(a.velocity_um_s.is_some(), "{um} µm: warm on entry");
                }
                _ => {}
            }
            last_region = a.region;
        }
        // 200 samples each way below 30 mm, less the line's 64-sample fill after each entry.
        assert!(
            slept > 250 && entries == 1,
            "{slept} asleep, {entries} entries"
        );
        // Asleep, not resting: the velocity asked is the line's, None while it refills (its 64
        // samples after the turn back into the region, less the estimator's 34 it had).
        assert!(
            refilling >= 25,
            "{refilling} samples without the line's velocity"
        );
    }

    /// An estimator that rests but cannot be seeded (`window_samples` 0) rests in the hybrid's
    /// region instead of sleeping, so it is whole on leaving it: the same stroke as above, the
    /// velocity region's every velocity that of a controller updating on every sample.
    #[test]
    fn an_estimator_without_a_window_rests_where_it_would_sleep() {
        #[derive(Clone, Debug)]
        struct NoWindow(DefaultEstimator);
        impl VelocityEstimator for NoWindow {
            fn update(&mut self, p: i32, t: u32) -> Option<i32> {
                self.0.update(p, t)
            }
            fn reset(&mut self) {
                self.0.reset()
            }
            fn group_delay_us(&self) -> u32 {
                self.0.group_delay_us()
            }
            fn rests(&self) -> bool {
                self.0.rests()
            }
            fn rest(&mut self, p: i32, t: u32) {
                self.0.rest(p, t)
            }
            fn wake(&mut self) {
                self.0.wake()
            }
            fn estimate(&self) -> Option<i32> {
                self.0.estimate()
            }
        }
        let cfg = two_config(hybrid_1mm(), synth(1_000));
        let est = NoWindow(DefaultEstimator::new(LsqSlope::new(100).unwrap(), 100));
        let mut rests = Controller::with_estimator(TIMER, 100, est);
        rests.load(&cfg).unwrap();
        let mut always = two(hybrid_1mm(), synth(1_000));
        always.velocity_every_sample(true);
        let (mut t, mut above) = (0u32, 0);
        for um in up_and_back() {
            let code = code_at(&always, um);
            let a = rests.on_sample(Sample { code, t_us: t });
            let b = always.on_sample(Sample { code, t_us: t });
            t += 100;
            if a.region == Some(1) {
                assert_eq!(a.velocity_um_s, b.velocity_um_s, "{um} µm");
                assert!(a.velocity_um_s.is_some(), "{um} µm: whole on entry");
                above += 1;
            }
        }
        assert!(above > 700, "{above}");
    }

    /// What each texture kind declares, seen from outside: on a 40 mm/s stroke a region whose
    /// texture reads only the position (off, constant, random) or its own fit (the hybrid
    /// grating) computes no velocity, one that reads the estimator's (position phase,
    /// velocity synthesis, material) computes it on every sample once the window is full;
    /// lines make every region compute it. The velocity asked for is there in every case.
    #[test]
    fn each_kind_rests_the_estimator_or_not() {
        let random = random_100hz();
        let hybrid = hybrid_1mm();
        let kinds = [
            ("off", Texture::Off, &[][..], true),
            ("constant", Texture::constant_hz(80), &[], true),
            ("random", random, &[], true),
            ("hybrid", hybrid, &[], true),
            (
                "position",
                Texture::Grating(crate::texture::Grating::new(1_000)),
                &[],
                false,
            ),
            ("synthesis", synth(1_000), &[], false),
            (
                "material",
                Texture::Material(crate::texture::Material::fig5(0.3)),
                &[],
                false,
            ),
            ("off with a line", Texture::Off, &[40_000], false),
        ];
        for (name, texture, lines, rests) in kinds {
            let mut c = single(texture, lines);
            let mut t = 0;
            let outs = stroke(&mut c, 20_000.0, 40_000.0, &mut t, 400);
            let computed = outs[40..]
                .iter()
                .filter(|o| o.velocity_um_s.is_some())
                .count();
            assert_eq!(computed, if rests { 0 } else { 360 }, "{name}");
            let v = c.velocity_um_s().unwrap_or(0);
            assert!((35_000..=45_000).contains(&v), "{name}: asked {v} µm/s");
            assert_eq!(c.telemetry().velocity_um_s, v, "{name}: telemetry");
        }
    }

    /// Entering a region starts its speed threshold over: having moved at 20 mm/s (above the
    /// 15 mm/s threshold) in a velocity region, left it and come back at 10 mm/s (above half
    /// the threshold, below the threshold), the region stays silent. Both velocity kinds.
    #[test]
    fn motion_threshold_starts_over_on_region_entry() {
        let material = crate::texture::Material {
            min_speed_um_s: 15_000,
            ..crate::texture::Material::fig5(0.3)
        };
        for texture in [synth(1_000), Texture::Material(material)] {
            let mut c = two(texture, Texture::Off);
            let mut t = 0;
            // 25 → 33 mm at 20 mm/s: bursts below 30 mm.
            let out = stroke(&mut c, 25_000.0, 20_000.0, &mut t, 4_000);
            assert!(last_settings(&out[..2_000]).is_some(), "{texture:?}");
            // 33 → 27 mm at 10 mm/s: back in the region below half way.
            let back = stroke(&mut c, 33_000.0, -10_000.0, &mut t, 6_000);
            assert_eq!(back.last().unwrap().region, Some(0));
            assert_eq!(last_settings(&back), None, "{texture:?}");
        }
    }

    /// Entering a random region draws at once: the burst of the region left behind is not
    /// kept until the random texture's next draw.
    #[test]
    fn random_region_draws_anew_on_entry() {
        let random = random_100hz();
        let mut c = two(random, Texture::constant_hz(500));
        let mut t = 0;
        let hz = |outs: &[Output]| {
            last_settings(outs).map(|s| s.produced_millihz(TIMER.clock_hz) as f32 / 1000.0)
        };
        let mut outs = std::vec::Vec::new();
        // 40 mm (500 Hz), 20 mm (a draw), 40 mm again, and back to 20 mm 0.3 ms later, well
        // inside the ~10 ms of the first draw's period.
        for (um, n) in [(40_000.0, 50), (20_000.0, 5), (40_000.0, 3)] {
            outs.extend((0..n).map(|_| feed(&mut c, um, &mut t, 1).0));
        }
        assert_eq!(hz(&outs), Some(500.0));
        let back = feed(&mut c, 20_000.0, &mut t, 1).0;
        let f = hz(&[back]).expect("a new draw on entry");
        assert!((90.0..=110.0).contains(&f), "{f} Hz");
    }

    /// The level cap: an amplitude of a region's or the lines' own above it is refused with a
    /// sentence naming both and the scene key, and the previous scene keeps running; full
    /// drive (a constant region) plays at the cap, and no sample ever sends more.
    #[test]
    fn the_level_cap_refuses_explicit_amplitudes_and_caps_full_drive() {
        let mut c = loaded();
        let before = c.telemetry();
        let mut cfg = default_config();
        cfg.limits.max_level_permille = 500;
        let mut g = crate::texture::Grating::new(2_000);
        g.amplitude_permille = 600;
        cfg.scene.textures[1] = Texture::Grating(g);
        let e = c.load(&cfg).unwrap_err();
        let text = std::format!("{e}");
        assert!(
            text.contains("region 1: amplitude 60 % is above the level cap of 50 % (limits.max_level_percent)"),
            "{text}"
        );
        assert_eq!(c.telemetry(), before, "nothing changed");
        // A random region's central amplitude too; a grating exactly at the cap loads.
        let mut r = cfg.clone();
        r.scene.textures[1] = Texture::Random(crate::texture::RandomBurst {
            center_millihz: 100_000,
            spread_permille: 100,
            amplitude_permille: 501,
            amplitude_spread_permille: 100,
            duty_permille: 400,
            seed: 1,
        });
        let text = std::format!("{}", c.load(&r).unwrap_err());
        assert!(
            text.contains("region 1: amplitude 50.1 % is above"),
            "{text}"
        );
        g.amplitude_permille = 500;
        cfg.scene.textures[1] = Texture::Grating(g);
        c.load(&cfg).unwrap();
        // The lines' amplitude too.
        let mut cfg = default_config();
        cfg.limits.max_level_permille = 500;
        let _ = cfg.scene.lines.positions_um.push(20_000);
        cfg.scene.lines.amplitude_permille = 501;
        let text = std::format!("{}", c.load(&cfg).unwrap_err());
        assert!(
            text.contains("amplitude 50.1 % is above the level cap of 50 %"),
            "{text}"
        );
        // At the cap it loads; the default scene's constant regions ask for full drive and get
        // the cap, over a whole stroke.
        cfg.scene.lines.amplitude_permille = 500;
        c.load(&cfg).unwrap();
        let mut t = 0;
        let outs = stroke(&mut c, 1_000.0, 100_000.0, &mut t, 6_000);
        let sent: std::vec::Vec<u16> = outs.iter().filter_map(|o| o.amplitude_permille).collect();
        assert!(!sent.is_empty());
        assert!(sent.iter().all(|&a| a == 500), "{sent:?}");
    }

    /// A new level cap re-applies the amplitude the texture keeps asking for: the ask is the
    /// same (full drive), the level under the new cap is not, and it is sent on the first
    /// sample after the load — and not again while nothing changes.
    #[test]
    fn a_new_level_cap_reapplies_an_unchanged_ask() {
        let mut c = loaded();
        let mut t = 0;
        let outs = stroke(&mut c, 1_000.0, 2_000.0, &mut t, 200);
        let sent: std::vec::Vec<u16> = outs.iter().filter_map(|o| o.amplitude_permille).collect();
        assert_eq!(sent, [1000]);
        let mut cfg = default_config();
        cfg.limits.max_level_permille = 500;
        c.load(&cfg).unwrap();
        let outs = stroke(&mut c, 2_000.0, 3_000.0, &mut t, 200);
        let sent: std::vec::Vec<u16> = outs.iter().filter_map(|o| o.amplitude_permille).collect();
        assert_eq!(sent, [500]);
    }

    /// A fault ends a line pulse's window with the pulse: after recovering inside what would
    /// have been the window, the region's texture owns the amplitude again (full drive for
    /// `off`), not the envelope of a pulse no longer running; the next line crossed gets its
    /// pulse, since the cut pulse's on-time fits the duty window (the per-pulse rule skipped it).
    #[test]
    fn a_fault_ends_the_line_window() {
        let mut cfg = default_config();
        cfg.scene.boundaries_um.clear();
        cfg.scene.textures.clear();
        let _ = cfg.scene.textures.push(Texture::Off);
        for l in [20_000, 22_000] {
            let _ = cfg.scene.lines.positions_um.push(l);
        }
        cfg.scene.lines.amplitude_permille = 600;
        let mut c = Controller::new(TIMER, 100).unwrap();
        c.load(&cfg).unwrap();
        let mut t = 0;
        let outs = stroke(&mut c, 19_500.0, 100_000.0, &mut t, 60);
        let fired = outs
            .iter()
            .position(|o| o.line == Some(0))
            .expect("line 0 fires");
        let fired_us = fired as u32 * 100;
        // The pulse went out at the lines' 600 ‰ peak.
        assert_eq!(outs[fired].amplitude_permille, Some(600));
        let fault = c.on_sample(Sample { code: 0, t_us: t });
        t += 100;
        assert_eq!(fault.action, Some(GateAction::Off));
        // 16 good samples to recover; the first output after them is the texture's.
        let after: std::vec::Vec<Output> = (0..20)
            .map(|_| feed(&mut c, 21_000.0, &mut t, 1).0)
            .collect();
        let amplitudes: std::vec::Vec<u16> =
            after.iter().filter_map(|o| o.amplitude_permille).collect();
        assert_eq!(amplitudes, [1000]);
        let (cross, _) = feed(&mut c, 22_500.0, &mut t, 1);
        assert!(t - fired_us < 20_000, "{} us", t - fired_us);
        assert_eq!(cross.line, Some(1));
        assert!(matches!(cross.action, Some(GateAction::Pulse(_))));
        assert_eq!(c.telemetry().lines_skipped, 0);
    }

    /// A sensor fault forgets where the finger was: recovering at rest 7 mm (seven ridges)
    /// from where the fault began fires no pulse, since the finger crossed nothing the sensor
    /// saw.
    #[test]
    fn position_phase_forgets_the_ridge_cell_across_faults() {
        let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
        let mut t = 0;
        let (_, actions) = feed(&mut c, 5_500.0, &mut t, 200);
        assert_eq!(actions, 0);
        for _ in 0..50 {
            let out = c.on_sample(Sample { code: 0, t_us: t });
            assert!(out.fault.is_some());
            t += 100;
        }
        let outs: std::vec::Vec<Output> = (0..2_000)
            .map(|_| {
                let out = c.on_sample(Sample {
                    code: code_at(&c, 12_500.0),
                    t_us: t,
                });
                t += 100;
                out
            })
            .collect();
        assert_eq!(
            pulses(&outs),
            [],
            "a pulse after recovering elsewhere at rest"
        );
        assert_eq!(c.telemetry().ridge_pulses, 0);
    }

    /// Position phase: a pulse on the first sample past each ridge, lasting duty·λ/V, in both
    /// directions, from the very first ridge (before the estimator has a speed, position ends
    /// the pulse); nothing at rest on a ridge; a fault cuts a pulse.
    #[test]
    fn position_phase_grating_pulses_at_each_ridge() {
        for speed in [20_000.0f32, 50_000.0, 200_000.0] {
            let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
            let mut t = 0;
            // 10.5 mm of travel each way, starting mid-cell (5.5 mm).
            let n = (10_500.0 / speed * 1e4) as usize;
            let mut outs = stroke(&mut c, 5_500.0, speed, &mut t, n);
            let turn = outs.len();
            outs.extend(stroke(&mut c, 5_500.0 + 10_500.0, -speed, &mut t, n));
            let p = pulses(&outs);
            // Ridges at 6..=15 mm up and 15..=6 mm down.
            assert_eq!(p.len(), 20, "{speed}: {p:?}");
            let want_us = 0.4 * 1_000.0 / speed * 1e6;
            for &(i, on_us) in &p {
                let (x, dir) = if i < turn {
                    (5_500.0 + speed * i as f32 * 1e-4, 1.0)
                } else {
                    (16_000.0 - speed * (i - turn) as f32 * 1e-4, -1.0)
                };
                // Past the ridge by less than one sample of travel (plus the 1 µm code step).
                let past = dir * (x - (x / 1_000.0).round() * 1_000.0);
                assert!(
                    (-1.5..=speed * 1e-4 + 1.5).contains(&past),
                    "{speed}: pulse at {x} um, {past} past its ridge"
                );
                // To the clock by the timer, or to the sample by position (the first ridge).
                assert!(
                    (on_us - want_us).abs() <= (0.05 * want_us).max(150.0),
                    "{speed}: on {on_us} us, want {want_us}"
                );
            }
            assert_eq!(c.telemetry().ridge_pulses, 20);
            assert_eq!(c.telemetry().ridges_skipped, 0);
        }
        // At rest on a ridge, dithering ±60 µm: not one action in 10 s.
        let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
        let mut t = 0;
        let quiet = (0..100_000).all(|i| {
            let um = 30_000.0 + (((i * 37) % 121) - 60) as f32;
            let out = c.on_sample(Sample {
                code: code_at(&c, um),
                t_us: t,
            });
            t += 100;
            out.action.is_none()
        });
        assert!(quiet, "bursts at rest");
        // A rail fault during a ridge pulse cuts it.
        let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
        let mut t = 0;
        let outs = stroke(&mut c, 5_500.0, 20_000.0, &mut t, 300);
        assert_eq!(pulses(&outs).len(), 1);
        let out = c.on_sample(Sample { code: 0, t_us: t });
        assert_eq!(out.action, Some(GateAction::Off));
    }

    /// A pulse sized from a lagging speed estimate is cut when the finger leaves the ridge, so
    /// its duty rest does not hold off the next ridge: 100 → 150 mm/s just before a ridge, the
    /// estimate still says 100 and sizes a 4 ms pulse; the finger covers the ridge's 0.4 mm in
    /// 2.7 ms. Uncut, pulse + rest (8 ms) would outlast the 6.7 ms to the next ridge.
    #[test]
    fn position_phase_cuts_pulses_the_estimate_stretched() {
        let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
        let mut t = 0;
        let mut outs = stroke(&mut c, 5_500.0, 100_000.0, &mut t, 145); // to 6.94 mm
        let jump = outs.len();
        outs.extend(stroke(&mut c, 6_950.0, 150_000.0, &mut t, 300)); // to 11.4 mm
        let p = pulses(&outs);
        // Ridges 6..=11: one pulse each, none skipped.
        assert_eq!(p.len(), 6, "{p:?}");
        assert_eq!(c.telemetry().ridges_skipped, 0, "{:?}", c.telemetry());
        let first_after = p.iter().find(|&&(i, _)| i >= jump).unwrap();
        assert!(
            outs[first_after.0 + 1..]
                .iter()
                .find_map(|o| o.action)
                .is_some_and(|a| a == GateAction::Off),
            "the pulse sized at 100 mm/s must be cut: {p:?}"
        );
        for &(i, on_us) in p.iter().filter(|&&(i, _)| i >= jump) {
            assert!(on_us <= 2_667.0 + 200.0, "pulse at sample {i}: {on_us} us");
        }
    }

    /// A single-sample glitch of ±2 mm (a wiper spark) crosses ridges in the reading but not
    /// under the finger: it fires nothing and cuts nothing. A dropped sample changes nothing.
    #[test]
    fn position_phase_ignores_glitches_and_bridges_drops() {
        let run = |glitch: Option<(usize, f32)>, drop: Option<usize>| {
            let mut c = single(Texture::Grating(crate::texture::Grating::new(1_000)), &[]);
            let mut outs = std::vec::Vec::new();
            for i in 0..1_000usize {
                if drop == Some(i) {
                    continue;
                }
                let mut um = 5_500.0 + 50_000.0 * i as f32 * 1e-4; // 50 mm/s to 10.5 mm
                if let Some((at, d)) = glitch {
                    if at == i {
                        um += d;
                    }
                }
                outs.push(c.on_sample(Sample {
                    code: code_at(&c, um),
                    t_us: i as u32 * 100,
                }));
            }
            (pulses(&outs), c.telemetry())
        };
        let (clean, _) = run(None, None);
        assert_eq!(clean.len(), 5, "{clean:?}");
        // Mid-pulse (just past ridge 7 at sample 300) and mid-cell, up and down.
        for (at, d) in [
            (303, 2_000.0),
            (303, -2_000.0),
            (350, 2_000.0),
            (350, -2_000.0),
        ] {
            let (p, tel) = run(Some((at, d)), None);
            assert_eq!(p, clean, "glitch {d} at {at}");
            assert_eq!(tel.ridges_skipped, 0);
        }
        let (p, _) = run(None, Some(500));
        assert_eq!(p.len(), 5);
    }

    /// Faster than the board's f_b limit (and than half the sample rate): one pulse per sample
    /// at most, pulses at least 1/f_max apart and never shorter than the f_max burst, every
    /// ridge either pulsed or counted, and the duty cap kept over every pulse + gap.
    #[test]
    fn position_phase_above_the_board_limit_skips_and_counts() {
        let g = crate::texture::Grating::new(100);
        let mut c = single(Texture::Grating(g), &[]);
        let mut t = 0;
        // 1.5 m/s over λ = 0.1 mm: 15 kHz of ridges, 1.5 per sample, on a 5 kHz board.
        let outs = stroke(&mut c, 5_050.0, 1_500_000.0, &mut t, 300);
        let p = pulses(&outs);
        let tel = c.telemetry();
        // Ridges 51 ..= the last one below the final position.
        let ridges = tel.position_um as u32 / 100 - 50;
        assert_eq!(tel.ridge_pulses as usize, p.len());
        assert_eq!(tel.ridge_pulses + tel.ridges_skipped, ridges, "{tel:?}");
        let min_on_us = 0.4 / TIMER.max_burst_hz as f32 * 1e6;
        for w in p.windows(2) {
            let gap_us = (w[1].0 - w[0].0) as f32 * 100.0;
            assert!(gap_us >= 1e6 / TIMER.max_burst_hz as f32, "{w:?}");
            assert!(w[0].1 >= min_on_us - 0.1, "{w:?}");
            assert!(w[0].1 / gap_us <= 0.5, "{w:?}");
        }
        assert!(p.len() > 10, "{p:?}");
    }

    #[test]
    fn drive_mode_is_announced_once_after_load() {
        let mut c = loaded();
        let mut t = 0;
        let outs = stroke(&mut c, 5_000.0, 0.0, &mut t, 3);
        assert_eq!(outs[0].drive, Some(crate::gate::DriveMode::Standing));
        assert!(outs[1..].iter().all(|o| o.drive.is_none()));
    }

    /// Above the board's limit a grating is clamped to it and counted (never aliased), and every
    /// velocity-driven texture goes quiet through a reversal and comes back after it.
    #[test]
    fn velocity_textures_at_the_edges() {
        // λ = 10 µm at 100 mm/s asks for 10 kHz on a 5 kHz board.
        let mut c = single(synth(10), &[]);
        let mut t = 0;
        let outs = stroke(&mut c, 5_000.0, 100_000.0, &mut t, 200);
        let s = last_settings(&outs).unwrap();
        assert_eq!(
            s.produced_millihz(TIMER.clock_hz),
            TIMER.max_burst_hz as u64 * 1000
        );
        assert!(c.telemetry().clamped > 100, "{:?}", c.telemetry());

        for texture in [
            synth(1_000),
            Texture::Material(crate::texture::Material::fig5(0.3)),
        ] {
            let mut c = single(texture, &[]);
            let mut t = 0;
            // Forward at 50 mm/s, then back at 50 mm/s: |V| passes through 0 at the turn.
            let mut outs = stroke(&mut c, 20_000.0, 50_000.0, &mut t, 1_000);
            let turn = outs.len();
            outs.extend(stroke(&mut c, 25_000.0, -50_000.0, &mut t, 1_000));
            let off_at_turn = outs[turn..turn + 40]
                .iter()
                .any(|o| o.action == Some(GateAction::Off));
            assert!(
                off_at_turn,
                "{}: no quiet spell at the reversal",
                texture.kind()
            );
            let back = last_settings(&outs[turn..]).expect("bursts after the reversal");
            let hz = back.produced_millihz(TIMER.clock_hz) as f32 / 1000.0;
            assert!(hz > 1.0, "{}: {hz}", texture.kind());
        }
    }

    /// Each configuration refusal reads as one sentence; a region's names the region, the
    /// caps' name the cap.
    #[test]
    fn config_errors_read_as_sentences() {
        let cases = [
            (
                ConfigError::Calibration(CalibrationError::BadLength { length_um: 0 }),
                "length 0 mm must be above 0 mm and at most 1000 mm",
            ),
            (
                ConfigError::Region(RegionError::HysteresisTooLarge {
                    hysteresis_um: 6_000,
                }),
                "hysteresis 6 mm is above the limit of 5 mm",
            ),
            (
                ConfigError::Limits(BurstError::BadDuty {
                    duty_permille: 1001,
                }),
                "duty cap 100.1 % must be above 0 % and at most 100 %",
            ),
            (
                ConfigError::Limits(BurstError::NoOnTime {
                    burst_millihz: 0,
                    max_duty_permille: 500,
                    max_on_time_us: 0,
                }),
                "on-time cap 0 ms must be above 0 ms",
            ),
            (
                ConfigError::Texture {
                    region: 2,
                    error: BurstError::DutyAboveCap {
                        duty_permille: 1000,
                        cap_permille: 500,
                    },
                },
                "region 2: duty 100 % is above the carrier's cap of 50 %",
            ),
            (
                ConfigError::TextureParams {
                    region: 0,
                    error: TextureError::BadWavelength {
                        wavelength_um: 0,
                        length_um: 63_000,
                    },
                },
                "region 0: wavelength 0 mm must be above 0 mm and at most the substrate's \
                 length, 63 mm",
            ),
            (
                ConfigError::Lines(TextureError::BadPulse {
                    pulse_us: 0,
                    max_on_time_us: 50_000,
                }),
                "line pulse 0 ms must be above 0 ms and at most the on-time cap of 50 ms",
            ),
            (
                ConfigError::LinePulse(BurstError::PulseTooLong {
                    pulse_us: 30_000_000,
                    max_us: 23_860_929,
                }),
                "line pulse: a pulse of 30000 ms is longer than the burst timer's longest, \
                 23860.929 ms",
            ),
            (
                ConfigError::TextureCount {
                    textures: 3,
                    boundaries: 1,
                },
                "3 textures for 1 boundaries, and a scene needs one texture more than \
                 boundaries",
            ),
            (
                ConfigError::NoSuchRegion {
                    index: 5,
                    regions: 3,
                },
                "region 5 does not exist: the scene has 3 regions (0 to 2)",
            ),
            (
                ConfigError::NoSuchBoundary {
                    index: 2,
                    boundaries: 2,
                },
                "boundary 2 does not exist: the scene has 2 boundaries (0 to 1)",
            ),
            (
                ConfigError::NoSuchBoundary {
                    index: 0,
                    boundaries: 0,
                },
                "boundary 0 does not exist: the scene is one region with no boundaries",
            ),
            (
                ConfigError::StaleLimit {
                    stale_after_us: 150,
                    min_us: 200,
                },
                "stale limit 0.15 ms must be at least two sample periods (0.2 ms) and at most \
                 1000 ms",
            ),
            (
                ConfigError::Estimator(EstimatorError::BadSamplePeriod {
                    sample_period_us: 0,
                }),
                "sample period 0 µs is outside the estimators' 10 µs to 100000 µs",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence, "{e:?}");
        }
    }
}
