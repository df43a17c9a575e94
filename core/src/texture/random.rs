//! Random texture: f_b and amplitude drawn uniformly about central values once per burst, like
//! the SAW display paper's "Randomness button" (a surface of fine, randomly distributed
//! scratches). The PRNG is a seeded PCG32, so a run reproduces exactly on host and target.

use rand_core::{Rng, SeedableRng};
use rand_pcg::Pcg32;

use crate::burst::{self, BurstCommand, BurstTimer, FastPlanner, SafetyLimits};

use super::compiled::{CompileError, Moment, Render, Request};
use super::{SpreadParam, TextureError};

/// A random region's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RandomBurst {
    /// Central burst frequency, mHz.
    pub center_millihz: u32,
    /// f_b is drawn in center × (1 ± spread), ‰.
    pub spread_permille: u16,
    /// Central amplitude, ‰ of full drive.
    pub amplitude_permille: u16,
    /// Amplitude is drawn in amplitude × (1 ± spread), ‰, clamped to full drive.
    pub amplitude_spread_permille: u16,
    /// Duty of each burst, ‰.
    pub duty_permille: u16,
    /// PRNG seed.
    pub seed: u64,
}

impl RandomBurst {
    /// Checks the spreads; the f_b extremes are checked against the board when the scene loads.
    pub fn validate(&self) -> Result<(), TextureError> {
        let bad = |param, permille| Err(TextureError::BadSpread { param, permille });
        if self.spread_permille >= 1000 {
            return bad(SpreadParam::Spread, self.spread_permille);
        }
        if self.amplitude_spread_permille > 1000 {
            return bad(SpreadParam::AmplitudeSpread, self.amplitude_spread_permille);
        }
        if self.amplitude_permille == 0 || self.amplitude_permille > 1000 {
            return bad(SpreadParam::Amplitude, self.amplitude_permille);
        }
        Ok(())
    }

    /// Highest f_b this texture can draw, mHz.
    pub fn max_millihz(&self) -> u64 {
        self.center_millihz as u64 * (1000 + self.spread_permille as u64) / 1000
    }

    /// Lowest f_b this texture can draw, mHz.
    pub fn min_millihz(&self) -> u64 {
        self.center_millihz as u64 * (1000 - self.spread_permille as u64) / 1000
    }
}

/// The running state of a random texture: its PRNG.
#[derive(Clone, Debug)]
pub(crate) struct RandomState {
    rng: Pcg32,
}

impl RandomState {
    pub(crate) fn new(seed: u64) -> Self {
        Self {
            rng: Pcg32::seed_from_u64(seed),
        }
    }

    /// A uniform draw in [−1, 1).
    fn unit(&mut self) -> f32 {
        // 24 random bits: exactly representable in f32, identical on every platform.
        (self.rng.next_u32() >> 8) as f32 * (2.0 / 16_777_216.0) - 1.0
    }

    /// Draws (f_b in Hz, amplitude ‰) for the next burst.
    pub(crate) fn draw(&mut self, p: &RandomBurst) -> (f32, u16) {
        let f =
            p.center_millihz as f32 * 1e-3 * (1.0 + self.unit() * p.spread_permille as f32 * 1e-3);
        let a = p.amplitude_permille as f32
            * (1.0 + self.unit() * p.amplitude_spread_permille as f32 * 1e-3);
        (f, a.clamp(1.0, 1000.0) as u16)
    }
}

/// A random region, compiled: a new draw once the running burst has had its whole period.
#[derive(Clone, Debug)]
pub(crate) struct RandomDraws {
    params: RandomBurst,
    state: RandomState,
    planner: FastPlanner,
    next_draw_us: Option<u32>,
}

impl RandomDraws {
    pub(crate) fn new(
        r: &RandomBurst,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Result<Self, CompileError> {
        r.validate()?;
        // Both extremes of the draw must be renderable, so no draw is ever refused.
        for millihz in [r.min_millihz(), r.max_millihz()] {
            let cmd = BurstCommand {
                burst_millihz: millihz as u32,
                duty_permille: r.duty_permille,
            };
            burst::plan(timer, limits, &cmd)?;
        }
        Ok(Self {
            params: *r,
            state: RandomState::new(r.seed),
            planner: FastPlanner::new(timer, limits, r.duty_permille)?,
            next_draw_us: None,
        })
    }
}

impl Render for RandomDraws {
    fn reset(&mut self) {
        self.next_draw_us = None;
    }

    // Every sample from the controller's one call site (`Compiled::request`): inlined.
    #[inline(always)]
    fn request(&mut self, now: &Moment<'_>) -> Request {
        // A new draw once the running burst has had its whole period; until then keep it.
        let due = self
            .next_draw_us
            .is_none_or(|next| now.t_us.wrapping_sub(next) as i32 >= 0);
        if !due {
            return Request {
                settings: now.gate.running(),
                amplitude: u16::MAX,
                ..Request::OFF
            };
        }
        let (hz, amplitude) = self.state.draw(&self.params);
        let r = Request::planned(self.planner.plan_hz(hz), amplitude);
        self.next_draw_us = Some(now.t_us.wrapping_add((1e6 / hz) as u32));
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> RandomBurst {
        RandomBurst {
            center_millihz: 80_000,
            spread_permille: 250,
            amplitude_permille: 800,
            amplitude_spread_permille: 200,
            duty_permille: 400,
            seed: 7,
        }
    }

    #[test]
    fn draws_stay_in_range_and_reproduce() {
        let mut a = RandomState::new(7);
        let mut b = RandomState::new(7);
        let (mut lo, mut hi) = (f32::MAX, 0.0f32);
        for _ in 0..10_000 {
            let (f, amp) = a.draw(&p());
            assert_eq!((f, amp), b.draw(&p()));
            assert!((60.0..=100.0).contains(&f), "{f}");
            assert!((640..=960).contains(&amp), "{amp}");
            lo = lo.min(f);
            hi = hi.max(f);
        }
        // The spread is really used, not collapsed to the centre.
        assert!(lo < 61.0 && hi > 99.0, "{lo}..{hi}");
    }

    /// The amplitude spread is used too, and a draw above full drive is clamped to it: 900 ‰
    /// ± 20 % reaches 1 000 ‰ (often) and never more, down to 720 ‰.
    #[test]
    fn amplitude_spreads_and_clamps_at_full_drive() {
        let q = RandomBurst {
            amplitude_permille: 900,
            ..p()
        };
        let mut s = RandomState::new(3);
        let amps: std::vec::Vec<u16> = (0..10_000).map(|_| s.draw(&q).1).collect();
        let (lo, hi) = (*amps.iter().min().unwrap(), *amps.iter().max().unwrap());
        assert!((720..730).contains(&lo), "{lo}");
        assert_eq!(hi, 1_000);
        let at_full = amps.iter().filter(|&&a| a == 1_000).count();
        // P(draw > 1000) = (1080 − 1000) / 360 ≈ 22 %.
        assert!((1_900..2_600).contains(&at_full), "{at_full}");
    }

    /// The f_b extremes the scene is checked against at load: 80 Hz ± 25 % → 60 and 100 Hz.
    #[test]
    fn extremes() {
        assert_eq!((p().min_millihz(), p().max_millihz()), (60_000, 100_000));
        let r = RandomBurst {
            spread_permille: 0,
            ..p()
        };
        assert_eq!((r.min_millihz(), r.max_millihz()), (80_000, 80_000));
    }

    /// Each limit alone: f_b spread below 100 %, amplitude spread up to 100 %, amplitude
    /// 1–1000 ‰.
    #[test]
    fn validation_limits() {
        let v = |r: RandomBurst| r.validate();
        let bad = |param, permille| Err(TextureError::BadSpread { param, permille });
        assert_eq!(
            v(RandomBurst {
                spread_permille: 999,
                ..p()
            }),
            Ok(())
        );
        assert_eq!(
            v(RandomBurst {
                spread_permille: 1000,
                ..p()
            }),
            bad(SpreadParam::Spread, 1000)
        );
        assert_eq!(
            v(RandomBurst {
                amplitude_spread_permille: 1000,
                ..p()
            }),
            Ok(())
        );
        assert_eq!(
            v(RandomBurst {
                amplitude_spread_permille: 1001,
                ..p()
            }),
            bad(SpreadParam::AmplitudeSpread, 1001)
        );
        assert_eq!(
            v(RandomBurst {
                amplitude_permille: 1,
                ..p()
            }),
            Ok(())
        );
        assert_eq!(
            v(RandomBurst {
                amplitude_permille: 1000,
                ..p()
            }),
            Ok(())
        );
        assert_eq!(
            v(RandomBurst {
                amplitude_permille: 1001,
                ..p()
            }),
            bad(SpreadParam::Amplitude, 1001)
        );
    }

    #[test]
    fn bad_spread_rejected() {
        assert!(RandomBurst {
            spread_permille: 1000,
            ..p()
        }
        .validate()
        .is_err());
        assert!(RandomBurst {
            amplitude_permille: 0,
            ..p()
        }
        .validate()
        .is_err());
    }
}
