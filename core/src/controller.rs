//! Controller: runs the stages in order for each sample and owns the fault state.
//!
//! Loading a configuration is a compile step: everything is validated and the per-region timer
//! settings are planned before anything is replaced, so a bad configuration changes nothing.
//! The per-sample path is then: map → fault check → velocity → region → table look-up → gate.

use heapless::Vec;

use crate::burst::{self, BurstError, BurstTimer, SafetyLimits, TimerSettings};
use crate::gate::{BurstOutput, Gate, GateAction};
use crate::position::{CalibrationError, PositionMapper, SensorFault};
use crate::region::{RegionError, RegionMap, MAX_REGIONS};
use crate::sample::{PositionSource, Sample};
use crate::scene::Config;
use crate::velocity::{EstimatorError, LsqSlope, VelocityEstimator};

/// Samples in the default least-squares window: 3.2 ms at 10 kHz, 1.55 ms group delay.
pub const DEFAULT_WINDOW: usize = 32;
/// The default velocity estimator.
pub type DefaultEstimator = LsqSlope<DEFAULT_WINDOW>;
/// Consecutive good samples needed to leave a sensor fault (1.6 ms at 10 kHz): a wiper bouncing
/// on a worn track must not flash the carrier on between bounces.
pub const RECOVERY_SAMPLES: u16 = 16;
/// Region changes are logged at most this often; the rest are counted and reported with the next.
pub const REGION_LOG_INTERVAL_US: u32 = 100_000;

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
    /// Region `region`'s texture cannot be rendered on this board.
    Texture {
        /// Index of the region.
        region: u8,
        /// What is wrong with its burst.
        error: BurstError,
    },
    /// Textures must number one more than boundaries.
    TextureCount,
    /// Stale limit shorter than two sample periods or above one second.
    StaleLimit,
    /// The velocity estimator rejected the sample period.
    Estimator(EstimatorError),
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
    /// Last position, µm (−1 when unknown).
    pub position_um: i32,
    /// Last velocity, µm/s.
    pub velocity_um_s: i32,
    /// Region under the finger (255 when none).
    pub region: u8,
    /// Burst frequency on the line, mHz (0 when off).
    pub burst_millihz: u32,
}

/// A validated, compiled configuration.
#[derive(Clone, Debug)]
struct Active {
    mapper: PositionMapper,
    regions: RegionMap,
    /// Per region: the planned settings, or None for an off region.
    settings: Vec<Option<TimerSettings>, MAX_REGIONS>,
    limits: SafetyLimits,
    stale_after_us: u32,
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
    last_region_log_us: Option<u32>,
    unlogged_switches: u32,
    telemetry: Telemetry,
}

impl Controller<DefaultEstimator> {
    /// A controller with the default estimator, no configuration loaded (line off).
    pub fn new(timer: BurstTimer, sample_period_us: u32) -> Result<Self, ConfigError> {
        let estimator = LsqSlope::new(sample_period_us).map_err(ConfigError::Estimator)?;
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
            last_region_log_us: None,
            unlogged_switches: 0,
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
                    "scene loaded: {} regions, hysteresis {} um, duty cap {} permille, on-time cap {} us",
                    active.regions.len(),
                    config.scene.hysteresis_um,
                    active.limits.max_duty_permille,
                    active.limits.max_on_time_us
                );
                self.active = Some(active);
                // The old region index means nothing in the new layout.
                self.region = None;
                Ok(())
            }
            Err(e) => {
                warn!("scene rejected, previous kept: {:?}", e);
                Err(e)
            }
        }
    }

    fn compile(&self, config: &Config) -> Result<Active, ConfigError> {
        let mapper = PositionMapper::new(config.calibration).map_err(ConfigError::Calibration)?;
        let scene = &config.scene;
        if scene.textures.len() != scene.boundaries_um.len() + 1 {
            return Err(ConfigError::TextureCount);
        }
        let regions = RegionMap::new(
            scene.textures.len(),
            &scene.boundaries_um,
            mapper.length_um(),
            scene.hysteresis_um,
        )
        .map_err(ConfigError::Region)?;
        config.limits.validate().map_err(ConfigError::Limits)?;
        if config.stale_after_us < 2 * self.sample_period_us || config.stale_after_us > 1_000_000 {
            return Err(ConfigError::StaleLimit);
        }
        let mut settings = Vec::new();
        for (i, texture) in scene.textures.iter().enumerate() {
            let planned = match texture.fixed_command() {
                None => None,
                Some(cmd) => {
                    let (s, capped) =
                        burst::plan(&self.timer, &config.limits, &cmd).map_err(|error| {
                            ConfigError::Texture {
                                region: i as u8,
                                error,
                            }
                        })?;
                    if capped {
                        warn!(
                            "region {}: on-time capped to {} us",
                            i, config.limits.max_on_time_us
                        );
                    }
                    Some(s)
                }
            };
            // Cannot fail: the region map holds at most MAX_REGIONS.
            let _ = settings.push(planned);
        }
        Ok(Active {
            mapper,
            regions,
            settings,
            limits: config.limits,
            stale_after_us: config.stale_after_us,
        })
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
        let Some(active) = self.active.as_ref() else {
            let action = self.drive(None);
            return Output {
                action,
                ..Output::default()
            };
        };
        let position_um = match active.mapper.position_um(&sample) {
            Ok(p) => p,
            Err(fault) => return self.enter_fault(fault),
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
        let velocity_um_s = self.estimator.update(position_um, sample.t_us);
        let region = match self.region {
            None => active.regions.lookup(position_um),
            Some(r) => active.regions.track(r, position_um),
        };
        let desired = active.settings.get(region as usize).copied().flatten();
        if self.region != Some(region) {
            self.note_region_change(region, position_um, sample.t_us);
        }
        let action = self.drive(desired);
        let t = &mut self.telemetry;
        t.position_um = position_um;
        t.velocity_um_s = velocity_um_s.unwrap_or(0);
        t.region = region;
        Output {
            position_um: Some(position_um),
            velocity_um_s,
            region: Some(region),
            action,
            fault: None,
        }
    }

    /// Checks the stale-sensor watchdog at `now_us`; call it from a timer at least every few
    /// sample periods. Returns the off action when the sensor has gone quiet.
    pub fn on_tick(&mut self, now_us: u32) -> Option<GateAction> {
        let stale_after = self.active.as_ref()?.stale_after_us;
        let last = self.last_sample_us?;
        if now_us.wrapping_sub(last) > stale_after && self.fault != Some(SensorFault::Stale) {
            return self.enter_fault(SensorFault::Stale).action;
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
        if let Some(action) = output.action {
            out.apply(action);
        }
        Some(output)
    }

    fn enter_fault(&mut self, fault: SensorFault) -> Output {
        if self.fault != Some(fault) {
            self.telemetry.faults = self.telemetry.faults.wrapping_add(1);
            error!("sensor fault {:?}: carrier off", fault);
        }
        self.fault = Some(fault);
        self.good_run = 0;
        self.estimator.reset();
        self.region = None;
        self.telemetry.position_um = -1;
        self.telemetry.region = u8::MAX;
        let action = self.drive(None);
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
        let due = match self.last_region_log_us {
            None => true,
            Some(last) => t_us.wrapping_sub(last) >= REGION_LOG_INTERVAL_US,
        };
        if due {
            info!(
                "region {} at {} um ({} changes not logged)",
                region, position_um, self.unlogged_switches
            );
            self.last_region_log_us = Some(t_us);
            self.unlogged_switches = 0;
        } else {
            self.unlogged_switches += 1;
        }
    }

    fn drive(&mut self, desired: Option<TimerSettings>) -> Option<GateAction> {
        let limits = self.active.as_ref().map(|a| a.limits).unwrap_or_default();
        let action = self.gate.request(desired, &self.timer, &limits);
        if action.is_some() {
            self.telemetry.gate_actions = self.telemetry.gate_actions.wrapping_add(1);
            self.telemetry.burst_millihz = self
                .gate
                .running()
                .map(|s| s.produced_millihz(self.timer.clock_hz) as u32)
                .unwrap_or(0);
        }
        action
    }
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
        let out = c.on_sample(Sample { code: 0, t_us: t });
        t += 100;
        assert_eq!(out.action, Some(GateAction::Off));
        assert_eq!(out.fault, Some(SensorFault::RailLow));
        // Good samples shorter than the recovery run keep it off.
        let (out, actions) = feed(&mut c, 5_000.0, &mut t, RECOVERY_SAMPLES as usize - 1);
        assert_eq!(actions, 0);
        assert_eq!(out.fault, Some(SensorFault::RailLow));
        let (out, _) = feed(&mut c, 5_000.0, &mut t, 1);
        assert!(matches!(out.action, Some(GateAction::Start(_))), "{out:?}");
        assert_eq!(c.telemetry().faults, 1);
    }

    #[test]
    fn stale_sensor_turns_the_line_off() {
        let mut c = loaded();
        let mut t = 0;
        feed(&mut c, 5_000.0, &mut t, 10);
        assert_eq!(c.on_tick(t + 1_000), None);
        assert_eq!(c.on_tick(t + 6_000), Some(GateAction::Off));
        assert_eq!(c.on_tick(t + 7_000), None);
    }

    /// Each bad configuration is rejected with its own error and the running scene is untouched.
    #[test]
    fn bad_configs_rejected_previous_kept() {
        let mut c = loaded();
        let mut t = 0;
        let (before, _) = feed(&mut c, 30_000.0, &mut t, 1);
        let good = default_config();
        let mut cases: heapless::Vec<(Config, ConfigError), 12> = heapless::Vec::new();
        let mut cfg = good.clone();
        cfg.calibration = Calibration {
            code_at_start: good.calibration.code_at_end,
            code_at_end: good.calibration.code_at_start,
            ..good.calibration
        };
        let _ = cases.push((cfg, ConfigError::Calibration(CalibrationError::EndsSwapped)));
        let mut cfg = good.clone();
        cfg.calibration.code_at_end = cfg.calibration.code_at_start + 100;
        let _ = cases.push((
            cfg,
            ConfigError::Calibration(CalibrationError::EndsTooClose),
        ));
        let mut cfg = good.clone();
        cfg.scene.boundaries_um[1] = cfg.scene.boundaries_um[0] - 1;
        let _ = cases.push((cfg, ConfigError::Region(RegionError::Unsorted { index: 1 })));
        for (hz_milli, duty, err) in [
            (0, 400, BurstError::ZeroFrequency),
            (5_000_001, 400, BurstError::AboveBoardLimit),
            (80_000, 0, BurstError::BadDuty),
            (80_000, 501, BurstError::DutyAboveCap),
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
        let _ = cases.push((cfg, ConfigError::Limits(BurstError::BadDuty)));
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
    }
}
