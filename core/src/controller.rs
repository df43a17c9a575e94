//! Controller: runs the stages in order for each sample and owns the fault state.
//!
//! Loading a configuration is a compile step: everything is validated, per-region constants are
//! prepared (timer settings of constant textures, 1/λ, stick-slip constants, fast planners, line
//! pulses) before anything is replaced, so a bad configuration changes nothing and the
//! per-sample path computes only what the active region's texture needs:
//! map → fault check → velocity → region → texture → burst → gate.

use heapless::Vec;

use crate::burst::{self, BurstError, BurstTimer, FastPlanner, SafetyLimits, TimerSettings};
use crate::gate::{BurstOutput, DriveMode, Gate, GateAction};
use crate::position::{CalibrationError, PositionMapper, SensorFault};
use crate::region::{RegionError, RegionMap, MAX_REGIONS};
use crate::sample::{PositionSource, Sample};
use crate::scene::Config;
use crate::texture::grating::{GratingRender, RidgeTracker};
use crate::texture::lines::LineTracker;
use crate::texture::material::MaterialConsts;
use crate::texture::random::RandomState;
use crate::texture::{Lines, RandomBurst, Texture, TextureError, FULL_AMPLITUDE};
use crate::velocity::{EstimatorError, LsqSlope, Median3, VelocityEstimator};

/// Samples in the default least-squares window: 3.2 ms at 10 kHz, 1.55 ms group delay.
pub const DEFAULT_WINDOW: usize = 32;
/// The default velocity estimator: the least-squares slope behind a median-of-3 pre-filter.
/// Chosen on the bench (docs/estimators.md): the median costs 0.1 ms of lag and 5 % of noise,
/// and cuts the worst error under single-sample outliers and drops from 130 to 22 mm/s.
pub type DefaultEstimator = Median3<LsqSlope<DEFAULT_WINDOW>>;
/// Consecutive good samples needed to leave a sensor fault (1.6 ms at 10 kHz): a wiper bouncing
/// on a worn track must not flash the carrier on between bounces.
pub const RECOVERY_SAMPLES: u16 = 16;
/// Region changes and clamps are logged at most this often; the rest are counted.
pub const LOG_INTERVAL_US: u32 = 100_000;

/// Why a configuration was rejected (the previous one stays active).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ConfigError {
    /// The rheostat calibration.
    Calibration(CalibrationError),
    /// The region layout.
    Region(RegionError),
    /// The carrier caps.
    Limits(BurstError),
    /// Region `region`'s burst cannot be rendered on this board.
    Texture {
        /// Index of the region.
        region: u8,
        /// What is wrong with its burst.
        error: BurstError,
    },
    /// Region `region`'s texture parameters are invalid.
    TextureParams {
        /// Index of the region.
        region: u8,
        /// What is wrong.
        error: TextureError,
    },
    /// The lines are invalid.
    Lines(TextureError),
    /// The line pulse cannot be rendered on this board.
    LinePulse(BurstError),
    /// Textures must number one more than boundaries.
    TextureCount {
        /// Textures given.
        textures: usize,
        /// Boundaries given.
        boundaries: usize,
    },
    /// Stale limit shorter than two sample periods or above one second.
    StaleLimit {
        /// The limit asked for, µs.
        stale_after_us: u32,
        /// Two sample periods, µs.
        min_us: u32,
    },
    /// The velocity estimator rejected the sample period.
    Estimator(EstimatorError),
}

/// Longest stale limit, µs.
const MAX_STALE_US: u32 = 1_000_000;

/// One sentence per refusal, for hosts (the scene-file reader, host-sim). The firmware logs the
/// defmt form instead, so this is never linked on target.
impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::{Deci, Milli};
        match *self {
            ConfigError::Calibration(e) => e.fmt(f),
            ConfigError::Region(e) => e.fmt(f),
            // The caps' own checks reuse the burst errors; named here as the caps they are.
            ConfigError::Limits(BurstError::BadDuty { duty_permille }) => write!(
                f,
                "duty cap {} % must be above 0 % and at most 100 %",
                Deci(duty_permille as u64)
            ),
            ConfigError::Limits(e) => e.fmt(f),
            ConfigError::Texture { region, error } => write!(f, "region {region}: {error}"),
            ConfigError::TextureParams { region, error } => write!(f, "region {region}: {error}"),
            ConfigError::Lines(e) => e.fmt(f),
            ConfigError::LinePulse(e) => write!(f, "line pulse: {e}"),
            ConfigError::TextureCount {
                textures,
                boundaries,
            } => write!(
                f,
                "{textures} textures for {boundaries} boundaries, and a scene needs one texture \
                 more than boundaries"
            ),
            ConfigError::StaleLimit {
                stale_after_us,
                min_us,
            } => write!(
                f,
                "stale limit {} ms must be at least two sample periods ({} ms) and at most {} ms",
                Milli(stale_after_us as u64),
                Milli(min_us as u64),
                Milli(MAX_STALE_US as u64)
            ),
            ConfigError::Estimator(e) => e.fmt(f),
        }
    }
}

/// What one sample produced (for logs, host analyses and the firmware's telemetry).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Output {
    /// Position, µm, when the sensor is healthy.
    pub position_um: Option<i32>,
    /// Velocity, µm/s, once the estimator has a full window.
    pub velocity_um_s: Option<i32>,
    /// Region under the finger.
    pub region: Option<u8>,
    /// The action for the burst-timer port, when the line must change.
    pub action: Option<GateAction>,
    /// The new drive amplitude, ‰, when it changes.
    pub amplitude_permille: Option<u16>,
    /// The drive mode, on the first sample after a scene loads.
    pub drive: Option<DriveMode>,
    /// The index of a line crossed on this sample (its pulse fired).
    pub line: Option<u8>,
    /// The sensor fault in force, if any.
    pub fault: Option<SensorFault>,
}

/// Counters for the low-rate telemetry log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Telemetry {
    /// Samples processed.
    pub samples: u32,
    /// Fault onsets.
    pub faults: u32,
    /// Region switches.
    pub region_switches: u32,
    /// Gate actions issued.
    pub gate_actions: u32,
    /// Samples whose f_b was clamped to the board's limit.
    pub clamped: u32,
    /// Line pulses fired.
    pub line_pulses: u32,
    /// Line crossings dropped to keep the duty cap.
    pub lines_skipped: u32,
    /// Grating ridge pulses fired (position phase).
    pub ridge_pulses: u32,
    /// Ridge crossings without a pulse: several in one sample, faster than the board's f_b
    /// limit, or inside the duty cap's rest.
    pub ridges_skipped: u32,
    /// Last position, µm (−1 when unknown).
    pub position_um: i32,
    /// Last velocity, µm/s.
    pub velocity_um_s: i32,
    /// Region under the finger (255 when none).
    pub region: u8,
    /// Burst frequency on the line, mHz (0 when off).
    pub burst_millihz: u32,
}

/// A region's texture, compiled: only what its per-sample path needs.
#[derive(Clone, Debug)]
enum Compiled {
    Off,
    Fixed(TimerSettings),
    Grating {
        inv_wavelength_per_um: f32,
        motion: MotionGate,
        planner: FastPlanner,
        amplitude: u16,
    },
    Ridges(Ridges),
    Material {
        consts: MaterialConsts,
        motion: MotionGate,
        planner: FastPlanner,
    },
    Random {
        params: RandomBurst,
        state: RandomState,
        planner: FastPlanner,
        next_draw_us: Option<u32>,
    },
}

/// A position-phase grating, compiled: one pulse per ridge crossing (texture::grating).
#[derive(Clone, Copy, Debug)]
struct Ridges {
    wavelength_um: i32,
    rearm_um: i32,
    /// The ridge's share of the period, duty · λ, µm.
    ridge_um: i32,
    /// duty · λ · timer clock: the pulse's on-time in clocks is this over |V| in µm/s.
    on_clock_um_s: u64,
    /// Shortest pulse: the on-time of a burst at the board's top f_b.
    min_on_clocks: u64,
    /// Longest pulse: the on-time cap.
    max_on_clocks: u64,
    /// Pulses start at least this far apart, µs (the board's top f_b).
    min_spacing_us: u32,
    /// A pulse is not cut before it has been on this long, µs (the shortest pulse).
    min_on_us: u32,
    amplitude: u16,
    tracker: RidgeTracker,
    last_pulse_us: Option<u32>,
    /// While a pulse may be on: the span of positions it stays on over, µm (lo ..hi).
    on_span_um: Option<(i32, i32)>,
    /// Largest step between two samples the slider can make, µm; a larger one is a glitch
    /// until the next sample confirms it.
    max_step_um: i32,
    /// The last position accepted, and a jump waiting for confirmation.
    last_um: Option<i32>,
    jump_um: Option<i32>,
}

/// The fastest the slider is taken to move, µm/s: a step between two samples that would need
/// more (over up to four sample periods, to bridge dropped samples) is a sensor glitch.
pub const MAX_SLIDER_SPEED_UM_S: u32 = 2_000_000;

/// What a texture wants from the gate on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Want {
    /// Periodic bursts of `settings`, or off when None.
    Periodic,
    /// One pulse of `settings` now.
    Pulse,
    /// End the running pulse now (the finger has left its ridge).
    EndPulse,
}

impl Ridges {
    fn new(
        g: &crate::texture::Grating,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        sample_period_us: u32,
    ) -> Result<Self, BurstError> {
        if timer.max_burst_hz == 0 {
            return Err(timer.bad());
        }
        limits.check_duty(g.duty_permille)?;
        let duty = g.duty_permille as u64;
        let clock = timer.clock_hz as u64;
        let max_on_clocks = limits.max_on_time_clocks(timer);
        let min_on_clocks =
            (clock * duty / (1000 * timer.max_burst_hz as u64)).clamp(1, max_on_clocks.max(1));
        // Both extremes must be renderable, so no crossing is ever refused by the timer.
        timer.one_pulse(max_on_clocks)?;
        timer.one_pulse(min_on_clocks)?;
        Ok(Self {
            wavelength_um: g.wavelength_um as i32,
            rearm_um: g.rearm_um as i32,
            ridge_um: (g.wavelength_um as u64 * duty / 1000) as i32,
            on_clock_um_s: duty * g.wavelength_um as u64 * clock / 1000,
            min_on_clocks,
            max_on_clocks,
            min_spacing_us: 1_000_000u32.div_ceil(timer.max_burst_hz),
            min_on_us: timer.clocks_to_us_ceil(min_on_clocks) as u32,
            amplitude: g.amplitude_permille,
            tracker: RidgeTracker::default(),
            last_pulse_us: None,
            on_span_um: None,
            max_step_um: (4 * MAX_SLIDER_SPEED_UM_S as u64 * sample_period_us as u64 / 1_000_000)
                .min(i32::MAX as u64) as i32,
            last_um: None,
            jump_um: None,
        })
    }

    fn reset(&mut self) {
        self.tracker.reset();
        self.on_span_um = None;
        self.last_um = None;
        self.jump_um = None;
    }

    /// False for a single-sample glitch: a step the slider cannot make, not (yet) confirmed by
    /// a second sample near it. A real jump (after a gap) costs one sample.
    fn plausible(&mut self, position_um: i32) -> bool {
        let near = |a: i32, b: i32| a.abs_diff(b) <= self.max_step_um as u32;
        let ok = self.last_um.is_none_or(|last| near(last, position_um))
            || self.jump_um.is_some_and(|j| near(j, position_um));
        if ok {
            self.last_um = Some(position_um);
            self.jump_um = None;
        } else {
            self.jump_um = Some(position_um);
        }
        ok
    }

    /// What to do on this sample, the pulse's settings, and the ridges passed without a pulse.
    ///
    /// A pulse's length is set from the speed, duty·λ/|V|, so at a steady speed the timer ends
    /// it on time to the clock. It is also ended by position: once the finger leaves the
    /// ridge's share of the period (forward past it, or back beyond the re-arm distance) the
    /// pulse is cut, so an estimate that lags an acceleration or a reversal cannot stretch it
    /// (and its duty rest) over the next ridge. With the speed unknown (the estimator's first
    /// window after a start or a fault) the timer is set to the on-time cap and position alone
    /// ends the pulse.
    fn step(
        &mut self,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        timer: &BurstTimer,
    ) -> (Want, Option<TimerSettings>, u32) {
        let mut want = Want::Periodic;
        if !self.plausible(position_um) {
            return (want, None, 0);
        }
        if let Some((lo, hi)) = self.on_span_um {
            let long_enough = self
                .last_pulse_us
                .is_some_and(|t0| t_us.wrapping_sub(t0) >= self.min_on_us);
            if (position_um < lo || position_um > hi) && long_enough {
                self.on_span_um = None;
                want = Want::EndPulse;
            }
        }
        let Some(c) = self
            .tracker
            .update(position_um, self.wavelength_um, self.rearm_um)
        else {
            return (want, None, 0);
        };
        let too_soon = self
            .last_pulse_us
            .is_some_and(|last| t_us.wrapping_sub(last) < self.min_spacing_us);
        let on = match velocity_um_s {
            Some(v) => self
                .on_clock_um_s
                .checked_div(v.unsigned_abs() as u64)
                .unwrap_or(u64::MAX),
            None => u64::MAX,
        }
        .clamp(self.min_on_clocks, self.max_on_clocks);
        // `new` checked that both ends of the clamp render, so one_pulse cannot fail here; if it
        // did, the ridge would be skipped like one that comes too soon.
        let settings = if too_soon {
            None
        } else {
            timer.one_pulse(on).ok()
        };
        let Some(settings) = settings else {
            return (want, None, c.skipped + 1);
        };
        let ridge = c.ridge * self.wavelength_um;
        self.on_span_um = Some(if c.up {
            (ridge - self.rearm_um, ridge + self.ridge_um)
        } else {
            (ridge - self.ridge_um, ridge + self.rearm_um)
        });
        self.last_pulse_us = Some(t_us);
        (Want::Pulse, Some(settings), c.skipped)
    }
}

/// Speed threshold with hysteresis: on at `on_um_s`, off below half of it.
#[derive(Clone, Copy, Debug)]
struct MotionGate {
    on_um_s: f32,
    moving: bool,
}

impl MotionGate {
    fn new(min_speed_um_s: u32) -> Self {
        Self {
            on_um_s: min_speed_um_s as f32,
            moving: false,
        }
    }

    /// The speed to render, or None while below the threshold (or velocity unknown).
    fn speed(&mut self, velocity_um_s: Option<i32>) -> Option<f32> {
        let Some(v) = velocity_um_s else {
            self.moving = false;
            return None;
        };
        let speed = (v as f32).abs();
        self.moving = if self.moving {
            speed >= 0.5 * self.on_um_s
        } else {
            speed >= self.on_um_s
        };
        self.moving.then_some(speed)
    }
}

/// What a texture asks for on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Request {
    /// Periodic settings (off when None), or the pulse's when `want` is [`Want::Pulse`].
    settings: Option<TimerSettings>,
    /// Ridge crossings passed without a pulse on this sample.
    skipped: u32,
    amplitude: u16,
    want: Want,
    clamped: bool,
}

impl Request {
    /// Line off at full amplitude.
    const OFF: Request = Request {
        settings: None,
        skipped: 0,
        amplitude: FULL_AMPLITUDE,
        want: Want::Periodic,
        clamped: false,
    };
}

impl Compiled {
    fn compile(
        texture: &Texture,
        region: u8,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        length_um: u32,
        sample_period_us: u32,
    ) -> Result<(Self, bool), ConfigError> {
        let params = |error| ConfigError::TextureParams { region, error };
        let burst = |error| ConfigError::Texture { region, error };
        Ok(match texture {
            Texture::Off => (Compiled::Off, false),
            Texture::Constant(cmd) => {
                let (s, capped) = burst::plan(timer, limits, cmd).map_err(burst)?;
                (Compiled::Fixed(s), capped)
            }
            Texture::Grating(g) if g.render == GratingRender::PositionPhase => {
                g.validate(length_um).map_err(params)?;
                (
                    Compiled::Ridges(
                        Ridges::new(g, timer, limits, sample_period_us).map_err(burst)?,
                    ),
                    false,
                )
            }
            Texture::Grating(g) => {
                g.validate(length_um).map_err(params)?;
                let planner = FastPlanner::new(timer, limits, g.duty_permille).map_err(burst)?;
                let c = Compiled::Grating {
                    inv_wavelength_per_um: 1.0 / g.wavelength_um as f32,
                    motion: MotionGate::new(g.min_speed_um_s),
                    planner,
                    amplitude: g.amplitude_permille,
                };
                (c, false)
            }
            Texture::Material(m) => {
                m.validate().map_err(params)?;
                let planner = FastPlanner::new(timer, limits, m.duty_permille).map_err(burst)?;
                (
                    Compiled::Material {
                        consts: m.prepare(),
                        motion: MotionGate::new(m.min_speed_um_s),
                        planner,
                    },
                    false,
                )
            }
            Texture::Random(r) => {
                r.validate().map_err(params)?;
                // Both extremes of the draw must be renderable, so no draw is ever refused.
                for millihz in [r.min_millihz(), r.max_millihz()] {
                    let cmd = burst::BurstCommand {
                        burst_millihz: millihz as u32,
                        duty_permille: r.duty_permille,
                    };
                    burst::plan(timer, limits, &cmd).map_err(burst)?;
                }
                let planner = FastPlanner::new(timer, limits, r.duty_permille).map_err(burst)?;
                (
                    Compiled::Random {
                        params: *r,
                        state: RandomState::new(r.seed),
                        planner,
                        next_draw_us: None,
                    },
                    false,
                )
            }
        })
    }

    /// Forgets motion and draw state (region change, fault).
    fn reset(&mut self) {
        match self {
            Compiled::Grating { motion, .. } | Compiled::Material { motion, .. } => {
                motion.moving = false
            }
            Compiled::Random { next_draw_us, .. } => *next_draw_us = None,
            Compiled::Ridges(r) => r.reset(),
            Compiled::Off | Compiled::Fixed(_) => {}
        }
    }

    /// The request of this texture for one sample.
    fn request(
        &mut self,
        position_um: i32,
        velocity_um_s: Option<i32>,
        t_us: u32,
        running: Option<TimerSettings>,
        timer: &BurstTimer,
    ) -> Request {
        let off = Request::OFF;
        let planned = |p: Option<(TimerSettings, bool)>, amplitude| match p {
            Some((s, clamped)) => Request {
                settings: Some(s),
                amplitude,
                clamped,
                ..off
            },
            None => off,
        };
        match self {
            Compiled::Off => off,
            Compiled::Fixed(s) => Request {
                settings: Some(*s),
                ..off
            },
            Compiled::Grating {
                inv_wavelength_per_um,
                motion,
                planner,
                amplitude,
            } => match motion.speed(velocity_um_s) {
                Some(speed) => planned(planner.plan_hz(speed * *inv_wavelength_per_um), *amplitude),
                None => off,
            },
            Compiled::Ridges(r) => {
                let (want, settings, skipped) = r.step(position_um, velocity_um_s, t_us, timer);
                Request {
                    settings,
                    skipped,
                    amplitude: r.amplitude,
                    want,
                    clamped: false,
                }
            }
            Compiled::Material {
                consts,
                motion,
                planner,
            } => match motion.speed(velocity_um_s) {
                Some(speed) => planned(
                    planner.plan_hz(consts.stick_slip_hz(speed * 1e-6)),
                    FULL_AMPLITUDE,
                ),
                None => off,
            },
            Compiled::Random {
                params,
                state,
                planner,
                next_draw_us,
            } => {
                // A new draw once the running burst has had its whole period; until then keep it.
                let due = next_draw_us.is_none_or(|next| t_us.wrapping_sub(next) as i32 >= 0);
                if !due {
                    return Request {
                        settings: running,
                        amplitude: u16::MAX,
                        ..off
                    };
                }
                let (hz, amplitude) = state.draw(params);
                let r = planned(planner.plan_hz(hz), amplitude);
                *next_draw_us = Some(t_us.wrapping_add((1e6 / hz) as u32));
                r
            }
        }
    }
}

/// A rate limit for log lines, on the sample clock.
#[derive(Clone, Copy, Debug, Default)]
struct LogLimit {
    last_us: Option<u32>,
    suppressed: u32,
}

impl LogLimit {
    /// True when a line may be logged now; otherwise counts it as suppressed.
    fn due(&mut self, t_us: u32) -> bool {
        let due = self
            .last_us
            .is_none_or(|last| t_us.wrapping_sub(last) >= LOG_INTERVAL_US);
        if due {
            self.last_us = Some(t_us);
        } else {
            self.suppressed += 1;
        }
        due
    }

    /// Lines suppressed since the last logged one; resets the count.
    fn take_suppressed(&mut self) -> u32 {
        core::mem::take(&mut self.suppressed)
    }
}

/// A validated, compiled configuration.
#[derive(Clone, Debug)]
struct Active {
    mapper: PositionMapper,
    regions: RegionMap,
    compiled: Vec<Compiled, MAX_REGIONS>,
    lines: Lines,
    /// The pulse of a line (one-pulse settings), when the scene has lines.
    line_pulse: Option<TimerSettings>,
    /// After a line pulse the line stays low this long, so the duty over pulse + rest keeps the cap.
    line_refractory_us: u32,
    limits: SafetyLimits,
    stale_after_us: u32,
    drive: DriveMode,
}

/// The control core.
#[derive(Clone, Debug)]
pub struct Controller<E: VelocityEstimator = DefaultEstimator> {
    timer: BurstTimer,
    sample_period_us: u32,
    active: Option<Active>,
    estimator: E,
    gate: Gate,
    region: Option<u8>,
    fault: Option<SensorFault>,
    good_run: u16,
    last_sample_us: Option<u32>,
    region_log: LogLimit,
    clamp_log: LogLimit,
    lines: LineTracker,
    /// Start of the running line pulse, while in its pulse + refractory window.
    pulse_start_us: Option<u32>,
    amplitude: Option<u16>,
    drive_pending: bool,
    telemetry: Telemetry,
}

impl Controller<DefaultEstimator> {
    /// A controller with the default estimator, no configuration loaded (line off).
    pub fn new(timer: BurstTimer, sample_period_us: u32) -> Result<Self, ConfigError> {
        let lsq = LsqSlope::new(sample_period_us).map_err(ConfigError::Estimator)?;
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
            estimator,
            gate: Gate::default(),
            region: None,
            fault: None,
            good_run: 0,
            last_sample_us: None,
            region_log: LogLimit::default(),
            clamp_log: LogLimit::default(),
            lines: LineTracker::default(),
            pulse_start_us: None,
            amplitude: None,
            drive_pending: false,
            telemetry: Telemetry {
                position_um: -1,
                region: u8::MAX,
                ..Telemetry::default()
            },
        }
    }

    /// Validates and compiles `config`, then makes it active. On error nothing changes.
    pub fn load(&mut self, config: &Config) -> Result<(), ConfigError> {
        match self.compile(config) {
            Ok(active) => {
                info!(
                    "scene loaded: {} regions, {} lines, hysteresis {} um, duty cap {} permille, on-time cap {} us",
                    active.regions.len(),
                    active.lines.positions_um.len(),
                    config.scene.hysteresis_um,
                    active.limits.max_duty_permille,
                    active.limits.max_on_time_us
                );
                for (i, t) in config.scene.textures.iter().enumerate() {
                    debug!("region {}: {}", i, t.kind());
                }
                self.active = Some(active);
                // The old region index and line arming mean nothing in the new layout.
                self.region = None;
                self.lines.reset();
                self.drive_pending = true;
                Ok(())
            }
            Err(e) => {
                // `{}`: the sentence on a host (`log`), the same defmt `Format` on target.
                warn!("scene rejected, previous kept: {}", e);
                Err(e)
            }
        }
    }

    fn compile(&self, config: &Config) -> Result<Active, ConfigError> {
        let mapper = PositionMapper::new(config.calibration).map_err(ConfigError::Calibration)?;
        let scene = &config.scene;
        if scene.textures.len() != scene.boundaries_um.len() + 1 {
            return Err(ConfigError::TextureCount {
                textures: scene.textures.len(),
                boundaries: scene.boundaries_um.len(),
            });
        }
        let regions = RegionMap::new(
            scene.textures.len(),
            &scene.boundaries_um,
            mapper.length_um(),
            scene.hysteresis_um,
        )
        .map_err(ConfigError::Region)?;
        config.limits.validate().map_err(ConfigError::Limits)?;
        let min_stale_us = 2 * self.sample_period_us;
        if config.stale_after_us < min_stale_us || config.stale_after_us > MAX_STALE_US {
            return Err(ConfigError::StaleLimit {
                stale_after_us: config.stale_after_us,
                min_us: min_stale_us,
            });
        }
        let mut compiled = Vec::new();
        for (i, texture) in scene.textures.iter().enumerate() {
            let (c, capped) = Compiled::compile(
                texture,
                i as u8,
                &self.timer,
                &config.limits,
                mapper.length_um(),
                self.sample_period_us,
            )?;
            if capped {
                warn!(
                    "region {}: on-time capped to {} us",
                    i, config.limits.max_on_time_us
                );
            }
            // Cannot fail: the region map holds at most MAX_REGIONS.
            let _ = compiled.push(c);
        }
        scene
            .lines
            .validate(mapper.length_um(), config.limits.max_on_time_us)
            .map_err(ConfigError::Lines)?;
        let (line_pulse, line_refractory_us) = if scene.lines.positions_um.is_empty() {
            (None, 0)
        } else {
            (
                Some(self.pulse_settings(scene.lines.pulse_us)?),
                line_refractory_us(&scene.lines, &config.limits),
            )
        };
        Ok(Active {
            mapper,
            regions,
            compiled,
            lines: scene.lines.clone(),
            line_pulse,
            line_refractory_us,
            limits: config.limits,
            stale_after_us: config.stale_after_us,
            drive: scene.drive,
        })
    }

    /// One-pulse settings of `pulse_us`: high for the whole count, one tick low at the end.
    fn pulse_settings(&self, pulse_us: u32) -> Result<TimerSettings, ConfigError> {
        let clocks = pulse_us as u64 * self.timer.clock_hz as u64 / 1_000_000;
        self.timer.one_pulse(clocks).map_err(ConfigError::LinePulse)
    }

    /// The burst timer this controller plans for.
    pub fn timer(&self) -> &BurstTimer {
        &self.timer
    }

    /// Counters and last values, for telemetry.
    pub fn telemetry(&self) -> Telemetry {
        self.telemetry
    }

    /// The position mapper of the active configuration.
    pub fn mapper(&self) -> Option<&PositionMapper> {
        self.active.as_ref().map(|a| &a.mapper)
    }

    /// Runs one sample through every stage.
    pub fn on_sample(&mut self, sample: Sample) -> Output {
        self.telemetry.samples = self.telemetry.samples.wrapping_add(1);
        self.last_sample_us = Some(sample.t_us);
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
        let velocity_um_s = self.estimator.update(position_um, t_us);
        let region = match self.region {
            None => active.regions.lookup(position_um),
            Some(r) => active.regions.track(r, position_um),
        };
        if self.region != Some(region) {
            self.note_region_change(region, position_um, t_us);
        }
        let mut out = Output {
            position_um: Some(position_um),
            velocity_um_s,
            region: Some(region),
            drive,
            ..Output::default()
        };
        let crossed = self.lines_step(position_um, t_us);
        if let Some((amplitude, action, line)) = crossed {
            // Inside a line pulse or its rest: the pulse owns the line and the amplitude.
            out.action = action;
            out.line = line;
            out.amplitude_permille = self.set_amplitude(amplitude);
        } else {
            let Some(active) = self.active.as_mut() else {
                return out;
            };
            let running = self.gate.running();
            let request = match active.compiled.get_mut(region as usize) {
                Some(c) => c.request(position_um, velocity_um_s, t_us, running, &self.timer),
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
            if request.amplitude != u16::MAX {
                out.amplitude_permille = self.set_amplitude(request.amplitude);
            }
        }
        let t = &mut self.telemetry;
        t.position_um = position_um;
        t.velocity_um_s = velocity_um_s.unwrap_or(0);
        t.region = region;
        out
    }

    /// Lines: fires a pulse on a crossing, and owns the gate during a pulse and its rest.
    /// Returns (amplitude, action, line fired) while the pulse window is open.
    fn lines_step(
        &mut self,
        position_um: i32,
        t_us: u32,
    ) -> Option<(u16, Option<GateAction>, Option<u8>)> {
        let active = self.active.as_ref()?;
        let pulse = active.line_pulse?;
        let fired = self.lines.update(&active.lines, position_um);
        let window_us = active.lines.pulse_us + active.line_refractory_us;
        if let Some(start) = self.pulse_start_us {
            let dt = t_us.wrapping_sub(start);
            if dt < window_us {
                if fired.is_some() {
                    self.telemetry.lines_skipped = self.telemetry.lines_skipped.wrapping_add(1);
                    debug!("line crossed during a pulse's rest: skipped to keep the duty cap");
                }
                return Some((active.lines.amplitude_at(dt), None, None));
            }
            self.pulse_start_us = None;
        }
        let line = fired?;
        let amplitude = active.lines.amplitude_at(0);
        let action = self.gate.pulse(pulse, t_us, &self.timer, &active.limits);
        if !matches!(action, Some(GateAction::Pulse(_))) {
            // A burst is running or resting: a pulse now would break the duty cap.
            self.telemetry.lines_skipped = self.telemetry.lines_skipped.wrapping_add(1);
            debug!(
                "line {} crossed at {} um while the duty cap is spent: skipped",
                line, position_um
            );
            self.count_action(action);
            return None;
        }
        self.pulse_start_us = Some(t_us);
        self.telemetry.line_pulses = self.telemetry.line_pulses.wrapping_add(1);
        debug!("line {} crossed at {} um: pulse", line, position_um);
        self.count_action(action);
        Some((amplitude, action, Some(line)))
    }

    /// Checks the stale-sensor watchdog at `now_us`; call it from a timer at least every few
    /// sample periods. Returns the off action when the sensor has gone quiet.
    pub fn on_tick(&mut self, now_us: u32) -> Option<GateAction> {
        let stale_after = self.active.as_ref()?.stale_after_us;
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
        self.region = None;
        self.lines.reset();
        self.pulse_start_us = None;
        if let Some(active) = self.active.as_mut() {
            active.compiled.iter_mut().for_each(Compiled::reset);
        }
        self.telemetry.position_um = -1;
        self.telemetry.region = u8::MAX;
        let limits = self.active.as_ref().map(|a| a.limits).unwrap_or_default();
        let action = self.gate.force_off(t_us, &self.timer, &limits);
        self.count_action(action);
        Output {
            action,
            fault: Some(fault),
            ..Output::default()
        }
    }

    fn note_region_change(&mut self, region: u8, position_um: i32, t_us: u32) {
        if self.region.is_some() {
            self.telemetry.region_switches = self.telemetry.region_switches.wrapping_add(1);
        }
        self.region = Some(region);
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

    fn set_amplitude(&mut self, permille: u16) -> Option<u16> {
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
        // The common cases, a burst running unchanged or the line idle and staying so, before
        // the caps are even fetched.
        if self.gate.steady(desired) {
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
            self.telemetry.burst_millihz = self
                .gate
                .running()
                .map(|s| s.produced_millihz(self.timer.clock_hz) as u32)
                .unwrap_or(0);
        }
    }
}

/// Sends one output's changes to a burst port: drive mode first, then amplitude, then the line.
pub fn apply<B: BurstOutput>(output: &Output, out: &mut B) {
    if let Some(mode) = output.drive {
        out.set_drive(mode);
    }
    if let Some(a) = output.amplitude_permille {
        out.set_amplitude(a);
    }
    if let Some(action) = output.action {
        out.apply(action);
    }
}

/// Rest after a line pulse so that pulse / (pulse + rest) ≤ the duty cap.
fn line_refractory_us(lines: &Lines, limits: &SafetyLimits) -> u32 {
    let cap = limits.max_duty_permille as u64;
    (lines.pulse_us as u64 * (1000 - cap)).div_ceil(cap) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::BurstCommand;
    use crate::position::Calibration;
    use crate::scene::default_config;
    use crate::texture::Texture;

    const TIMER: BurstTimer = BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 5_000,
    };

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
        // The 20 Hz region's 20 ms on-time may have run right up to the fault: at a 50 % cap the
        // line restarts 20 ms after it, not before.
        let mut started = None;
        for _ in 0..400 {
            let (out, _) = feed(&mut c, 5_000.0, &mut t, 1);
            if matches!(out.action, Some(GateAction::Start(_))) {
                started = Some(t - 100);
                break;
            }
        }
        let started = started.expect("restarts after the rest");
        assert!(
            (20_000..20_200).contains(&(started - fault_t)),
            "{}",
            started - fault_t
        );
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
        let mut cfg = default_config();
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
    /// 10 ms rest (50 %). Inside it the triangular envelope is reported (half way up at
    /// 2.5 ms, the peak at 5 ms) and a second line crossed is skipped and counted; crossed at
    /// exactly 20 ms it fires.
    #[test]
    fn line_window_holds_the_envelope_and_skips_inside_it() {
        for (cross_at_us, fires) in [(19_900u32, false), (20_000, true)] {
            let mut c = single(Texture::Off, &[20_000, 21_000]);
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
            assert_eq!(at(1_000 + 2_500).amplitude_permille, Some(500));
            assert_eq!(at(1_000 + 5_000).amplitude_permille, Some(1_000));
            // After the pulse, through the rest, the drive stays at 0 (the region's texture does
            // not take the amplitude back before the window ends).
            let rest = &outs[(1_000 + 10_000) / 100..(1_000 + 19_900) / 100];
            assert!(rest.iter().all(|o| o.amplitude_permille.unwrap_or(0) == 0));
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

    /// Position phase: a pulse on the first sample past each ridge, lasting duty·λ/V, in both
    /// directions, from the very first ridge (before the estimator has a speed, position ends
    /// the pulse); nothing at rest on a ridge; a fault cuts a pulse.
    /// The span a ridge pulse stays on over, to the µm: going up over the ridge at 6 mm it is
    /// [6 mm − rearm, 6 mm + duty·λ]; the pulse is cut one µm outside either end, not on it.
    #[test]
    fn ridge_pulse_span_edges() {
        let g = crate::texture::Grating::new(1_000);
        let rearm = g.rearm_um as i32;
        // (speed, approach: the last sample fires, a sample on the ridge, the span).
        let up: (i32, &[i32], i32, (i32, i32)) = (
            20_000,
            &[5_500, 5_800, 6_000],
            6_010,
            (6_000 - rearm, 6_000 + 400),
        );
        // Going down over the same ridge the span is mirrored: [6 mm − duty·λ, 6 mm + rearm].
        let down: (i32, &[i32], i32, (i32, i32)) = (
            -20_000,
            &[6_500, 6_200, 6_000, 5_999],
            5_990,
            (6_000 - 400, 6_000 + rearm),
        );
        for (v, approach, on_ridge, (lo, hi)) in [up, down] {
            for (edge, outside) in [(lo, lo - 1), (hi, hi + 1)] {
                let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
                let mut t = 0;
                let mut step = |r: &mut Ridges, um: i32| {
                    t += 100;
                    r.step(um, Some(v), t, &TIMER).0
                };
                let (&last, before) = approach.split_last().unwrap();
                for &um in before {
                    assert_eq!(step(&mut r, um), Want::Periodic, "{v} um/s at {um} um");
                }
                assert_eq!(step(&mut r, last), Want::Pulse, "{v} um/s at {last} um");
                // Past the shortest pulse, still on the ridge.
                for _ in 0..10 {
                    assert_eq!(step(&mut r, on_ridge), Want::Periodic);
                }
                assert_eq!(step(&mut r, edge), Want::Periodic, "{v} um/s at {edge} um");
                assert_eq!(
                    step(&mut r, outside),
                    Want::EndPulse,
                    "{v} um/s at {outside} um"
                );
            }
        }
    }

    /// Ridge pulses may start as close as the board's shortest burst period (200 µs at 5 kHz),
    /// not closer: two ridges crossed 200 µs apart both fire; 150 µs apart, the second is
    /// counted as skipped.
    #[test]
    fn ridge_pulses_as_close_as_the_board_allows() {
        let g = crate::texture::Grating::new(1_000);
        let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
        let fired: std::vec::Vec<_> = [(100, 5_500), (200, 6_000), (300, 6_500), (400, 7_000)]
            .into_iter()
            .map(|(t, um)| {
                let (want, _, skipped) = r.step(um, Some(5_000_000), t, &TIMER);
                (want, skipped)
            })
            .collect();
        assert_eq!(
            fired,
            [
                (Want::Periodic, 0),
                (Want::Pulse, 0),
                // Past the ridge's 400 µm share: the first pulse is cut by position.
                (Want::EndPulse, 0),
                (Want::Pulse, 0)
            ]
        );
        let mut r = Ridges::new(&g, &TIMER, &SafetyLimits::default(), 100).unwrap();
        r.step(5_500, Some(5_000_000), 100, &TIMER);
        r.step(6_000, Some(5_000_000), 200, &TIMER);
        r.step(6_600, Some(5_000_000), 275, &TIMER);
        let (want, _, skipped) = r.step(7_000, Some(5_000_000), 350, &TIMER);
        // The first pulse is cut here too (past its share, and on for its 80 µs minimum).
        assert_eq!((want, skipped), (Want::EndPulse, 1));
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
