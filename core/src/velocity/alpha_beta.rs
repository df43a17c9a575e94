//! α-β filter (a steady-state Kalman filter for a constant-velocity model), f32.
//!
//! Per sample, m slots after the previous one (m = 1 normally, 2.. with dropped samples):
//! predict x̂⁻ = x̂ + m·v̂ (v̂ in µm per slot), residual r = x − x̂⁻, correct x̂ = x̂⁻ + α·r,
//! v̂ = v̂ + (β/m)·r.
//!
//! Gains from one double pole p ∈ (0, 1) of the error dynamics (critically damped, no overshoot
//! at a velocity step): α = 1 − p², β = (1 − p)². Exact at any constant speed once settled.
//! Group delay at constant acceleration: T_s·(α/β − ½) = T_s·((1 + p)/(1 − p) − ½)
//! (p = 0.9 → 18.5 samples = 1.85 ms at 10 kHz; p = 0.85 → 11.8 samples).
//! Velocity noise for white position noise σ_x: σ_v = σ_x/T_s·√(2β² / (α(4 − 2α − β)))
//! (p = 0.9: 0.0171·σ_x/T_s — the LSQ window of equal delay, N = 38, gives 0.0148·σ_x/T_s).

use super::common::{
    alpha_beta_group_delay_us, alpha_beta_stable, alpha_beta_warmup, check_period,
    critically_damped_gains, to_um_s, Sampler, Step, TuningError,
};
use super::VelocityEstimator;

/// α-β filter, f32.
#[derive(Clone, Debug)]
pub struct AlphaBeta {
    alpha: f32,
    beta: f32,
    /// Position estimate minus the last measurement, µm (relative, so f32 keeps its resolution
    /// on a 63 mm stroke).
    e: f32,
    last_x: i32,
    /// Velocity estimate, µm per slot.
    v: f32,
    sampler: Sampler,
    /// Samples seen since (re)start, saturating.
    seen: u32,
    warmup: u32,
}

impl AlphaBeta {
    /// Critically damped α-β with its double pole at `pole` (0 < pole < 1; larger = smoother
    /// and slower).
    pub fn critically_damped(sample_period_us: u32, pole: f32) -> Result<Self, TuningError> {
        let (alpha, beta) = critically_damped_gains(pole)?;
        Self::with_gains(sample_period_us, alpha, beta)
    }

    /// α-β with explicit gains, inside the stability triangle 0 < α < 2, 0 < β < 4 − 2α.
    pub fn with_gains(sample_period_us: u32, alpha: f32, beta: f32) -> Result<Self, TuningError> {
        check_period(sample_period_us)?;
        if !alpha_beta_stable(alpha, beta) {
            return Err(TuningError::UnstableGains { alpha, beta });
        }
        // No output until the start transient (from v̂ = 0) has had about two group delays.
        let warmup = alpha_beta_warmup(alpha, beta);
        Ok(Self {
            alpha,
            beta,
            e: 0.0,
            last_x: 0,
            v: 0.0,
            sampler: Sampler::new(sample_period_us),
            seen: 0,
            warmup,
        })
    }

    /// (α, β).
    pub fn gains(&self) -> (f32, f32) {
        (self.alpha, self.beta)
    }

    /// Forgets the state (the sampler is the caller's).
    fn clear(&mut self) {
        self.e = 0.0;
        self.last_x = 0;
        self.v = 0.0;
        self.seen = 0;
    }
}

impl VelocityEstimator for AlphaBeta {
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
        let mf = m as f32;
        let dx = position_um.saturating_sub(self.last_x) as f32;
        self.last_x = position_um;
        // r = x − (x̂ + m·v̂) with x̂ = x_last + e; then x̂ − x = e_new = −(1 − α)·r.
        let r = dx - self.e - mf * self.v;
        self.e = -(1.0 - self.alpha) * r;
        self.v += self.beta * r / mf;
        self.seen = self.seen.saturating_add(1);
        let out = (self.seen > self.warmup)
            .then(|| to_um_s(self.v * 1e6 / self.sampler.period_us() as f32));
        self.sampler.answer(out)
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        alpha_beta_group_delay_us(self.alpha, self.beta, self.sampler.period_us())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settles_exactly_on_a_ramp() {
        let mut e = AlphaBeta::critically_damped(100, 0.9).unwrap();
        let mut v = None;
        for i in 0..600i32 {
            v = e.update(1_000 + 2 * i, i as u32 * 100);
        }
        assert_eq!(v, Some(20_000));
        assert_eq!(e.group_delay_us(), 1_850);
    }

    #[test]
    fn none_during_warmup_then_zero_at_rest() {
        let mut e = AlphaBeta::critically_damped(100, 0.9).unwrap();
        for i in 0..37u32 {
            assert_eq!(e.update(25_000, i * 100), None, "sample {i}");
        }
        assert_eq!(e.update(25_000, 3_700), Some(0));
    }

    #[test]
    fn measured_lag_matches_declared_delay_under_acceleration() {
        // 1 m/s² from rest, positions rounded to whole µm; the lag is averaged over the last
        // 1 000 samples so the rounding noise (≈ 50 µm/s on one sample) averages out.
        let mut e = AlphaBeta::critically_damped(100, 0.9).unwrap();
        let a = 1e6f64; // µm/s²
        let mut lag_sum = 0.0;
        for i in 0..3_000u32 {
            let t = i as f64 * 1e-4;
            let v = e.update(libm::round(0.5 * a * t * t) as i32, i * 100);
            if i >= 2_000 {
                lag_sum += (a * t - v.unwrap() as f64) / a * 1e6;
            }
        }
        let lag_us = lag_sum / 1_000.0;
        assert!((lag_us - 1_850.0).abs() < 10.0, "lag {lag_us} µs");
    }

    #[test]
    fn dropped_sample_predicts_over_the_gap() {
        let mut e = AlphaBeta::critically_damped(100, 0.8).unwrap();
        let mut v = None;
        for i in 0..400u32 {
            if i % 50 == 25 {
                continue; // one lost sample every 5 ms
            }
            v = e.update(-3 * i as i32, i * 100);
        }
        assert_eq!(v, Some(-30_000));
    }

    #[test]
    fn reset_and_bad_gains() {
        let mut e = AlphaBeta::critically_damped(100, 0.5).unwrap();
        for i in 0..20u32 {
            e.update(i as i32 * 10, i * 100);
        }
        e.reset();
        assert_eq!(e.update(0, 10_000), None);
        assert_eq!(
            AlphaBeta::critically_damped(100, 1.0).err(),
            Some(TuningError::BadPole { pole: 1.0 })
        );
        assert_eq!(
            AlphaBeta::with_gains(100, 1.5, 1.1).err(),
            Some(TuningError::UnstableGains {
                alpha: 1.5,
                beta: 1.1
            })
        );
    }
}
