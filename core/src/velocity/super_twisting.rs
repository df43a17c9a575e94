//! Levant's super-twisting (first-order robust exact) differentiator, explicit Euler, f32.
//!
//! Levant, "Robust exact differentiation via sliding mode technique", Automatica 34(3), 1998:
//!   ż₀ = z₁ − λ₁·L^½·|z₀ − f|^½·sign(z₀ − f),   ż₁ = −λ₀·L·sign(z₀ − f),
//! with L a bound on |f̈| (the finger's acceleration, µm/s²) and the standard gains λ₁ = 1.5,
//! λ₀ = 1.1 (Levant 2003). Output: z₁.
//!
//! Discretization: one explicit Euler step of h = T_s per slot (m steps across m slots with a
//! dropped sample, all against the newest measurement). In exact arithmetic and without noise it
//! converges in finite time and is then exact on any f with |f̈| ≤ L, up to the discretization
//! chatter: z₁ moves by λ₀·L·T_s every step (1.1 mm/s at L = 10 m/s², 10 kHz). With position noise
//! ε the error grows as √(L·ε) (Levant's bound): the differentiator trusts the sign of every
//! residual, so it is the noise-sensitive extreme of this set. L trades acceleration tracking
//! against noise. Group delay: declared as one sample (the Euler step); there is no linear lag to
//! speak of — the bench measures the effective one.

use super::common::{check_period, to_um_s, Sampler, Step, TuningError};
use super::VelocityEstimator;

/// λ₁ (Levant 2003).
pub const STD_LAMBDA1: f32 = 1.5;
/// λ₀ (Levant 2003).
pub const STD_LAMBDA0: f32 = 1.1;

/// Super-twisting differentiator.
#[derive(Clone, Debug)]
pub struct SuperTwisting {
    /// λ₁·√L, √(µm)/s.
    k1: f32,
    /// λ₀·L, µm/s².
    k0: f32,
    h: f32,
    /// Position estimate relative to `origin`, µm.
    z0: f32,
    /// Velocity estimate, µm/s.
    z1: f32,
    origin: i32,
    sampler: Sampler,
}

impl SuperTwisting {
    /// Differentiator for accelerations up to `lipschitz_um_s2` (e.g. 1e7 = 10 m/s²).
    pub fn new(sample_period_us: u32, lipschitz_um_s2: f32) -> Result<Self, TuningError> {
        check_period(sample_period_us)?;
        if !(lipschitz_um_s2.is_finite() && lipschitz_um_s2 > 0.0) {
            return Err(TuningError::BadLipschitz { lipschitz_um_s2 });
        }
        Ok(Self {
            k1: STD_LAMBDA1 * libm::sqrtf(lipschitz_um_s2),
            k0: STD_LAMBDA0 * lipschitz_um_s2,
            h: sample_period_us as f32 * 1e-6,
            z0: 0.0,
            z1: 0.0,
            origin: 0,
            sampler: Sampler::new(sample_period_us),
        })
    }

    /// Forgets the state (the sampler is the caller's).
    fn clear(&mut self) {
        self.z0 = 0.0;
        self.z1 = 0.0;
        self.origin = 0;
    }
}

impl VelocityEstimator for SuperTwisting {
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        let m = match self.sampler.step(t_us) {
            Step::Repeat => return self.sampler.last_out(),
            Step::Slots(m) => m,
            Step::Start => {
                self.clear();
                // Relative coordinates keep f32 resolution on the 63 mm stroke.
                self.origin = position_um;
                return None;
            }
        };
        let f = position_um.saturating_sub(self.origin) as f32;
        for _ in 0..m {
            let e = self.z0 - f;
            let s = if e > 0.0 {
                1.0
            } else if e < 0.0 {
                -1.0
            } else {
                0.0
            };
            self.z0 += self.h * (self.z1 - self.k1 * libm::sqrtf(e.abs()) * s);
            self.z1 -= self.h * self.k0 * s;
        }
        self.sampler.answer(Some(to_um_s(self.z1)))
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        self.sampler.period_us()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converges_on_a_ramp_within_the_chatter() {
        let mut e = SuperTwisting::new(100, 1e7).unwrap();
        let mut worst_late = 0;
        for i in 0..2_000i32 {
            // 50 mm/s.
            let v = e.update(10_000 + 5 * i, i as u32 * 100).unwrap_or(0);
            if i > 1_000 {
                worst_late = worst_late.max((v - 50_000).abs());
            }
        }
        // Chatter bound: a few steps of λ₀·L·T_s = 1.1 mm/s.
        assert!(worst_late <= 3_300, "worst {worst_late} µm/s");
    }

    #[test]
    fn exactly_zero_at_rest() {
        let mut e = SuperTwisting::new(100, 1e7).unwrap();
        assert_eq!(e.update(40_000, 0), None);
        for i in 1..100u32 {
            assert_eq!(e.update(40_000, i * 100), Some(0));
        }
    }

    #[test]
    fn dropped_sample_and_reset() {
        let mut e = SuperTwisting::new(100, 1e7).unwrap();
        let mut v = 0;
        for i in 0..3_000u32 {
            if i % 100 == 50 {
                continue;
            }
            v = e.update(-2 * i as i32, i * 100).unwrap_or(0);
        }
        assert!((v + 20_000).abs() <= 3_300, "{v}");
        e.reset();
        assert_eq!(e.update(7, 400_000), None);
        assert_eq!(e.group_delay_us(), 100);
        assert_eq!(
            SuperTwisting::new(100, 0.0).err(),
            Some(TuningError::BadLipschitz {
                lipschitz_um_s2: 0.0
            })
        );
    }
}
