//! Scenarios: a trajectory through the rheostat/ADC model into a stream of observations, made
//! once per scenario and replayed to every method (so all methods see the very same noise).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::position::{Calibration, PositionMapper};
use saw_core::sample::{Sample, CODE_FULL_SCALE};

use crate::adc::{AdcModel, AdcParams};
use crate::trajectory::{Piece, Trajectory};

/// What the estimator is handed at one sample slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Input {
    /// A position, µm.
    Position(i32),
    /// A sensor fault: the controller resets the estimator.
    Fault,
    /// No sample in this slot.
    Dropped,
}

/// One sample slot.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Obs {
    /// Timestamp, µs.
    pub t_us: u32,
    /// What arrives.
    pub input: Input,
    /// True velocity, µm/s.
    pub v_true: f64,
    /// True acceleration (finite difference of the true velocity), µm/s².
    pub a_true: f64,
    /// Whether this slot counts in the error figures.
    pub scored: bool,
}

/// How a scenario is generated.
#[derive(Clone, Debug)]
pub struct Spec {
    /// Finger motion.
    pub trajectory: Trajectory,
    /// Duration, s.
    pub duration_s: f64,
    /// ADC noise per conversion, 12-bit LSB RMS.
    pub noise_lsb: f64,
    /// Sample rate, Hz.
    pub rate_hz: u32,
    /// Probability that a sample is replaced by a single-sample outlier of ±`outlier_um`.
    pub outlier_prob: f64,
    /// Outlier size, µm.
    pub outlier_um: f64,
    /// Probability that a sample is lost.
    pub drop_prob: f64,
    /// Slots before this time are not scored (warm-up), s.
    pub warmup_s: f64,
    /// PRNG seed (ADC noise and the outlier/drop draws).
    pub seed: u64,
}

impl Spec {
    /// A clean spec: no outliers, no drops, 50 ms warm-up.
    pub fn new(trajectory: Trajectory, duration_s: f64, noise_lsb: f64, rate_hz: u32) -> Self {
        Self {
            trajectory,
            duration_s,
            noise_lsb,
            rate_hz,
            outlier_prob: 0.0,
            outlier_um: 2_000.0,
            drop_prob: 0.0,
            warmup_s: 0.05,
            seed: 1,
        }
    }

    /// Sample period, µs.
    pub fn period_us(&self) -> u32 {
        1_000_000 / self.rate_hz
    }

    /// Generates the observation stream.
    pub fn generate(&self) -> Vec<Obs> {
        let cal = Calibration::default();
        let mapper = PositionMapper::new(cal).expect("default calibration");
        // The study's figures (docs/bench-results.md) were measured on the per-conversion noise
        // stream: the reference model, kept here so the same seeds give the published numbers.
        let adc_params = AdcParams {
            per_conversion: true,
            ..AdcParams::default()
        }
        .with_noise(self.noise_lsb, self.seed);
        let mut adc = AdcModel::new(cal, adc_params).expect("adc model");
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x5A5A_0F0F_1234_8765);
        let period = self.period_us();
        let n = (self.duration_s * self.rate_hz as f64).round() as u64;
        let um_per_code = cal.length_um as f64 / (cal.code_at_end - cal.code_at_start) as f64;
        let dt = period as f64 * 1e-6;
        (0..n)
            .map(|k| {
                let t_us = k * period as u64;
                let t_s = t_us as f64 * 1e-6;
                let s = self.trajectory.state(t_s);
                let a_true = (self.trajectory.state(t_s + dt / 2.0).velocity_um_s
                    - self
                        .trajectory
                        .state((t_s - dt / 2.0).max(0.0))
                        .velocity_um_s)
                    / dt;
                let sample = adc.sample(s.position_um, t_us);
                let input = match sample {
                    None => Input::Dropped,
                    Some(_) if rng.random::<f64>() < self.drop_prob => Input::Dropped,
                    Some(mut smp) => {
                        if rng.random::<f64>() < self.outlier_prob {
                            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                            let code = smp.code as f64 + sign * self.outlier_um / um_per_code;
                            // Keep it off the rails: an outlier, not a fault.
                            let lo = (CODE_FULL_SCALE / 50) as f64;
                            let hi = (CODE_FULL_SCALE * 49 / 50) as f64;
                            smp = Sample {
                                code: code.clamp(lo, hi) as u16,
                                t_us: smp.t_us,
                            };
                        }
                        match mapper.position_um(&smp) {
                            Ok(x) => Input::Position(x),
                            Err(_) => Input::Fault,
                        }
                    }
                };
                Obs {
                    t_us: t_us as u32,
                    input,
                    v_true: s.velocity_um_s,
                    a_true,
                    scored: t_s >= self.warmup_s,
                }
            })
            .collect()
    }
}

/// The reference motion: rest, a slow back-and-forth (peak 21 mm/s), then a fast one peaking at
/// 300 mm/s and 10 m/s² (amplitude 9 mm, period 0.1885 s). Continuous in position and velocity.
pub fn mixed() -> (Trajectory, f64) {
    let fast_period = 2.0 * std::f64::consts::PI * 0.3 / 10.0; // ω = a/v = 33.3 rad/s
    let pieces = vec![
        Piece {
            trajectory: Trajectory::Rest { at_um: 20_000.0 },
            duration_s: 0.1,
        },
        Piece {
            trajectory: Trajectory::Sine {
                a_um: 20_000.0,
                b_um: 30_000.0,
                period_s: 1.5,
            },
            duration_s: 1.5,
        },
        Piece {
            trajectory: Trajectory::Sine {
                a_um: 20_000.0,
                b_um: 38_000.0,
                period_s: fast_period,
            },
            duration_s: 5.0 * fast_period,
        },
    ];
    let d = 0.1 + 1.5 + 5.0 * fast_period;
    (Trajectory::Piecewise { pieces }, d)
}

/// The reference stream: the mixed motion at 2 LSB and 10 kHz.
pub fn reference_spec(seed: u64) -> Spec {
    let (t, d) = mixed();
    let mut s = Spec::new(t, d, 2.0, 10_000);
    s.seed = seed;
    s
}

/// Constant speed `v` (µm/s) from 10 mm, long enough for ≥ 0.1 s and ≤ 40 mm of travel.
pub fn constant(v: f64) -> (Trajectory, f64) {
    let d = (40_000.0 / v).clamp(0.1, 0.5);
    (
        Trajectory::Constant {
            from_um: 10_000.0,
            speed_um_s: v,
        },
        d,
    )
}

/// The delay probe: 5 mm/s for 0.1 s, then 0.5 m/s² up to 35 mm/s. Scored only while the true
/// speed is within 15..25 mm/s.
pub fn delay_probe() -> (Trajectory, f64) {
    let pieces = vec![
        Piece {
            trajectory: Trajectory::Constant {
                from_um: 10_000.0,
                speed_um_s: 5_000.0,
            },
            duration_s: 0.1,
        },
        Piece {
            trajectory: Trajectory::Ramp {
                from_um: 10_500.0,
                v0_um_s: 5_000.0,
                accel_um_s2: 5e5,
                v_max_um_s: 35_000.0,
            },
            duration_s: 0.07,
        },
    ];
    (Trajectory::Piecewise { pieces }, 0.17)
}

/// Acceleration of the delay probe, µm/s².
pub const DELAY_PROBE_ACCEL: f64 = 5e5;

/// Instant reversals: a triangle between 10 and 40 mm at 100 mm/s.
pub fn reversals() -> (Trajectory, f64) {
    (
        Trajectory::Triangle {
            a_um: 10_000.0,
            b_um: 40_000.0,
            speed_um_s: 100_000.0,
        },
        1.8,
    )
}

/// At rest mid-stroke.
pub fn rest() -> Trajectory {
    Trajectory::Rest { at_um: 31_500.0 }
}
