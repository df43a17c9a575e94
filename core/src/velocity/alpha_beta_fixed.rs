//! α-β filter in I16F16 fixed point (the `fixed` crate): integer-only, bit-exact everywhere,
//! for a core without an FPU.
//!
//! I16F16 spans ±32 768 with a resolution of 1/65 536, too short for absolute positions in µm
//! (63 000). So the state is kept *relative to the last measurement*: `e = x̂ − x_last` (µm, a
//! few tens at most in tracking) and the velocity `v` in µm per slot (±30 µm at 300 mm/s and
//! 10 kHz). Per sample, m slots later: Δx = x − x_last (integer µm, saturated to the I16F16
//! range), residual r = Δx − e − m·v, then e = −(1 − α)·r and v = v + (β/m)·r — the same
//! recursion as [`super::AlphaBeta`], shifted by x_last.
//!
//! Products are rounded to nearest (not floored) so that quantization does not bias the
//! velocity: with floor rounding a body at rest settles a few LSB below zero. All arithmetic
//! saturates, so an absurd input gives a bounded output. Gains are quantized to 2⁻¹⁶
//! (β = 0.01 → 655/65 536, −0.05 %). Group delay as for the f32 filter: T_s·(α/β − ½).
//!
//! Dead band: the velocity integrator stops moving once |β·r| rounds to zero, i.e. for
//! |r| < 2⁻¹⁷/β µm, and the state can rest there with v ≈ −α·r: a velocity error of up to
//! α/(2β)·2⁻¹⁶ µm per slot (p = 0.9: 9.5 LSB = 1.45 µm/s at 10 kHz) that never decays. At rest
//! this is a residual velocity of ≤ 1.5 µm/s (a 1 mm grating would wrap its phase every
//! ≥ 11 minutes); it is the fixed-point price, and the tests bound it rather than hide it.

use fixed::types::I16F16;

use super::common::{
    alpha_beta_group_delay_us, alpha_beta_stable, alpha_beta_warmup, check_period,
    critically_damped_gains, Sampler, Step, TuningError, MIN_FIXED_BETA,
};
use super::VelocityEstimator;

/// α-β filter in I16F16.
#[derive(Clone, Debug)]
pub struct AlphaBetaFixed {
    one_minus_alpha: I16F16,
    beta: I16F16,
    /// x̂ − last measurement, µm.
    e: I16F16,
    /// Velocity, µm per slot.
    v: I16F16,
    last_x: i32,
    sampler: Sampler,
    seen: u32,
    warmup: u32,
}

/// a·b rounded to nearest (ties up), saturating.
fn mul(a: I16F16, b: I16F16) -> I16F16 {
    let p = (a.to_bits() as i64 * b.to_bits() as i64 + (1 << 15)) >> 16;
    I16F16::from_bits(p.clamp(i32::MIN as i64, i32::MAX as i64) as i32)
}

impl AlphaBetaFixed {
    /// Critically damped, double pole at `pole` (see [`super::AlphaBeta::critically_damped`]).
    pub fn critically_damped(sample_period_us: u32, pole: f32) -> Result<Self, TuningError> {
        let (alpha, beta) = critically_damped_gains(pole)?;
        Self::with_gains(sample_period_us, alpha, beta)
    }

    /// Explicit gains, inside the stability triangle and not below the I16F16 resolution.
    pub fn with_gains(sample_period_us: u32, alpha: f32, beta: f32) -> Result<Self, TuningError> {
        check_period(sample_period_us)?;
        if !alpha_beta_stable(alpha, beta) {
            return Err(TuningError::UnstableGains { alpha, beta });
        }
        if beta < MIN_FIXED_BETA {
            return Err(TuningError::BetaBelowResolution { beta });
        }
        let one_minus_alpha = I16F16::from_num(1.0 - alpha);
        let beta_q = I16F16::from_num(beta);
        // From the f32 gains, as for the f32 filter (the declared delay uses the quantized ones).
        let warmup = alpha_beta_warmup(alpha, beta);
        Ok(Self {
            one_minus_alpha,
            beta: beta_q,
            e: I16F16::ZERO,
            v: I16F16::ZERO,
            last_x: 0,
            sampler: Sampler::new(sample_period_us),
            seen: 0,
            warmup,
        })
    }

    /// Velocity state in µm per slot (for tests and telemetry).
    pub fn velocity_per_slot(&self) -> I16F16 {
        self.v
    }

    /// Forgets the state (the sampler is the caller's).
    fn clear(&mut self) {
        self.e = I16F16::ZERO;
        self.v = I16F16::ZERO;
        self.last_x = 0;
        self.seen = 0;
    }
}

impl VelocityEstimator for AlphaBetaFixed {
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        let m = match self.sampler.step(t_us) {
            Step::Repeat => return self.sampler.last_out(),
            Step::Slots(m) => m,
            Step::Start => {
                self.clear();
                self.last_x = position_um;
                self.seen = 1;
                return None;
            }
        };
        let dx = position_um
            .saturating_sub(self.last_x)
            .clamp(-32_767, 32_767);
        self.last_x = position_um;
        let mv = self.v.saturating_mul_int(m as i32);
        let r = I16F16::from_num(dx)
            .saturating_sub(self.e)
            .saturating_sub(mv);
        self.e = -mul(self.one_minus_alpha, r);
        let step = mul(self.beta, r);
        let step = if m > 1 {
            step / I16F16::from_num(m)
        } else {
            step
        };
        self.v = self.v.saturating_add(step);
        self.seen = self.seen.saturating_add(1);
        let out = (self.seen > self.warmup).then(|| {
            // µm/slot (Q16) × slots per second, rounded.
            // u32 division (one udiv on the M4); the period is at least 10 µs.
            let per_s = (1_000_000 / self.sampler.period_us()) as i64;
            ((self.v.to_bits() as i64 * per_s + (1 << 15)) >> 16) as i32
        });
        self.sampler.answer(out)
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        let alpha = 1.0 - self.one_minus_alpha.to_num::<f32>();
        alpha_beta_group_delay_us(alpha, self.beta.to_num::<f32>(), self.sampler.period_us())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocity::AlphaBeta;

    #[test]
    fn settles_on_ramps_within_the_dead_band() {
        for speed in [-30i32, -2, 1, 7] {
            let mut e = AlphaBetaFixed::critically_damped(100, 0.9).unwrap();
            let mut v = None;
            for i in 0..800i32 {
                v = e.update(31_000 + speed * i, i as u32 * 100);
            }
            let err = (v.unwrap() - speed * 10_000).abs();
            assert!(err <= 2, "speed {speed} µm/sample: {v:?}");
        }
    }

    #[test]
    fn zero_at_rest_no_limit_cycle() {
        let mut e = AlphaBetaFixed::critically_damped(100, 0.9).unwrap();
        let mut outs = [0i32; 200];
        for i in 0..1_200u32 {
            // Rest, quantized: flickers between two 16 µm codes, then holds still.
            let x = if i < 600 && i % 2 == 0 {
                48_016
            } else {
                48_000
            };
            if let Some(v) = e.update(x, i * 100) {
                if i >= 1_000 {
                    outs[(i - 1_000) as usize] = v;
                }
            }
        }
        // Inside the dead band (≤ 1.45 µm/s), not necessarily 0, and constant: no limit cycle.
        assert!(outs.iter().all(|&v| v.abs() <= 2), "{:?}", &outs[..10]);
        assert!(outs.iter().all(|&v| v == outs[0]), "{:?}", &outs[..10]);
    }

    #[test]
    fn tracks_the_f32_filter() {
        let mut f = AlphaBeta::critically_damped(100, 0.85).unwrap();
        let mut q = AlphaBetaFixed::critically_damped(100, 0.85).unwrap();
        let mut worst = 0;
        for i in 0..4_000u32 {
            // A 3 Hz sine of ±10 mm with a deterministic ±8 µm dither.
            let t = i as f32 * 1e-4;
            let x = 30_000.0 + 10_000.0 * libm::sinf(2.0 * core::f32::consts::PI * 3.0 * t);
            let x = x as i32 + ((i * 7919) % 17) as i32 - 8;
            if let (Some(a), Some(b)) = (f.update(x, i * 100), q.update(x, i * 100)) {
                worst = worst.max((a - b).abs());
            }
        }
        // The two differ only by quantization of gains and state: < 0.5 mm/s.
        assert!(worst < 500, "worst {worst} µm/s");
    }

    #[test]
    fn dropped_sample_reset_and_saturation() {
        let mut e = AlphaBetaFixed::critically_damped(100, 0.8).unwrap();
        let mut v = None;
        for i in 0..400u32 {
            if i % 40 == 13 {
                continue;
            }
            v = e.update(5 * i as i32, i * 100);
        }
        assert!((v.unwrap() - 50_000).abs() <= 2, "{v:?}");
        // A 60 mm jump in one sample saturates instead of wrapping.
        let v = e.update(60_000 + 2_000, 40_000).unwrap();
        assert!(v > 0 && v < 400_000_000, "{v}");
        e.reset();
        assert_eq!(e.update(0, 50_000), None);
        assert_eq!(e.group_delay_us(), 850);
    }

    /// Gains are refused with their values: outside the stability triangle, or a β below the
    /// I16F16 resolution (1/8192 = 0.0001220703125 is the smallest taken).
    #[test]
    fn refuses_gains_with_their_values() {
        assert_eq!(
            AlphaBetaFixed::with_gains(100, 2.0, 0.5).err(),
            Some(TuningError::UnstableGains {
                alpha: 2.0,
                beta: 0.5
            })
        );
        assert_eq!(
            AlphaBetaFixed::with_gains(100, 0.5, 0.000_122).err(),
            Some(TuningError::BetaBelowResolution { beta: 0.000_122 })
        );
        assert!(AlphaBetaFixed::with_gains(100, 0.5, 1.0 / 8_192.0).is_ok());
    }
}
