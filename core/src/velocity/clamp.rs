//! Step clamp: an outlier guard that wraps any estimator and limits each sample's step from
//! the position last handed on to the most the slider can move in one period.
//!
//! The position handed to the inner estimator is `x_ref + clamp(x − x_ref, ±max_step)`, with
//! `max_step` = `max_speed_um_s`·T_s. A clean stroke slower than the limit passes unchanged
//! (no added lag, bit-exact output); a single-sample outlier reaches the slope as a one-sample
//! spike of at most `max_step` instead of its full size; a real jump is followed at the
//! limit's speed (issue #35; `docs/conversion-budget.md`, "Outlier guards").
//!
//! Cost per sample: a subtract, two compares (a clamp) and an add; no multiply. Not removed:
//! the spike's `max_step` (its error is `max_step` times the slope's largest weight, so the
//! shorter the window the more it shows). After a silence (the slot clock's gap rule) or a
//! reset the first sample is taken as it comes; a lost sample widens the next step's limit by
//! its slots, as the slope bridges it.

use super::{VelocityEstimator, MAX_BRIDGED_SLOTS};

/// Step clamp around `E`.
#[derive(Clone, Debug)]
pub struct StepClamp<E> {
    inner: E,
    /// Largest step per period, µm.
    max_step_um: i32,
    /// The position last handed to the inner estimator, µm.
    x_ref: i32,
    /// Its timestamp, µs.
    t_ref: u32,
    /// False after a reset or a gap: the next sample is taken as it comes.
    primed: bool,
    period_us: u32,
    /// ⌊period/2⌋ and (MAX_BRIDGED_SLOTS + 1) periods, as the median's gap test.
    half_us: u32,
    gap_us: u32,
}

impl<E: VelocityEstimator> StepClamp<E> {
    /// Wraps `inner`, whose samples come every `sample_period_us`, limiting each step to
    /// `max_speed_um_s` over one period (at least 1 µm).
    pub fn new(inner: E, sample_period_us: u32, max_speed_um_s: u32) -> Self {
        let step = (max_speed_um_s as u64 * sample_period_us as u64 / 1_000_000)
            .clamp(1, i32::MAX as u64 / (MAX_BRIDGED_SLOTS as u64 + 1));
        Self {
            inner,
            max_step_um: step as i32,
            x_ref: 0,
            t_ref: 0,
            primed: false,
            period_us: sample_period_us,
            half_us: sample_period_us / 2,
            gap_us: sample_period_us.saturating_mul(MAX_BRIDGED_SLOTS + 1),
        }
    }

    /// The wrapped estimator.
    pub fn inner(&self) -> &E {
        &self.inner
    }

    /// The position to hand on for a sample at `position_um`, `t_us`.
    #[inline(always)]
    fn clamp(&mut self, position_um: i32, t_us: u32) -> i32 {
        let dt = t_us.wrapping_sub(self.t_ref).wrapping_add(self.half_us);
        self.t_ref = t_us;
        let out = if dt >= self.gap_us || !self.primed {
            // A gap, time run backwards, or the first sample: start over on it.
            self.primed = true;
            position_um
        } else {
            // Slots since the last sample (1 on the grid; up to MAX_BRIDGED_SLOTS + 1 with
            // lost samples): only off the grid does this divide.
            let slots = if dt < self.period_us + self.half_us {
                1
            } else {
                (dt / self.period_us.max(1)) as i32
            };
            let limit = self.max_step_um * slots.max(1);
            let step = position_um.wrapping_sub(self.x_ref).clamp(-limit, limit);
            self.x_ref.wrapping_add(step)
        };
        self.x_ref = out;
        out
    }
}

impl<E: VelocityEstimator> VelocityEstimator for StepClamp<E> {
    #[inline(always)]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        let x = self.clamp(position_um, t_us);
        self.inner.update(x, t_us)
    }

    fn reset(&mut self) {
        self.primed = false;
        self.inner.reset();
    }

    fn group_delay_us(&self) -> u32 {
        self.inner.group_delay_us()
    }

    /// A rest clamps as an update does and rests the inner estimator.
    #[inline(always)]
    fn rests(&self) -> bool {
        self.inner.rests()
    }

    #[inline(always)]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        let x = self.clamp(position_um, t_us);
        self.inner.rest(x, t_us);
    }

    fn wake(&mut self) {
        self.inner.wake();
    }

    #[inline(always)]
    fn estimate(&self) -> Option<i32> {
        self.inner.estimate()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocity::test_strokes::{assert_a_clean_ramp_is_untouched, ramp};
    use crate::velocity::LsqSlope;

    const T: u32 = 100;

    /// 1 m/s: 100 µm per 100 µs period.
    fn clamp16() -> StepClamp<LsqSlope<16>> {
        StepClamp::new(LsqSlope::<16>::new(T).unwrap(), T, 1_000_000)
    }

    #[test]
    fn a_clean_ramp_gives_the_bare_slope_bit_exact() {
        assert_a_clean_ramp_is_untouched(clamp16(), LsqSlope::<16>::new(T).unwrap(), T);
    }

    #[test]
    fn a_single_sample_spike_is_cut_to_one_step() {
        let (mut g, mut bare) = (clamp16(), LsqSlope::<16>::new(T).unwrap());
        let (mut worst, mut worst_bare) = (0i64, 0i64);
        for i in 0..200u32 {
            let x = ramp(i) + if i == 100 { 2_000 } else { 0 };
            let (a, b) = (g.update(x, i * T), bare.update(x, i * T));
            if i >= 20 {
                worst = worst.max((a.unwrap() as i64 - 20_000).abs());
                worst_bare = worst_bare.max((b.unwrap() as i64 - 20_000).abs());
            }
        }
        // A spike of one 100 µm step at the slope's largest weight, 6·15/(16·255)/T_s per µm:
        // 22.1 mm/s, plus the dither's few mm/s.
        assert!(worst <= 26_000, "clamped {worst} µm/s");
        assert!(worst >= 18_000, "clamped {worst} µm/s");
        assert!(worst_bare >= 400_000, "bare {worst_bare} µm/s");
    }

    #[test]
    fn a_real_jump_is_followed_at_the_limit() {
        let mut g = clamp16();
        let mut seen = std::vec::Vec::new();
        for i in 0..80u32 {
            let x = if i < 40 { 10_000 } else { 15_000 };
            g.update(x, i * T);
            seen.push(g.x_ref);
        }
        // 5 mm at 100 µm per sample: 50 samples, the last one landing on the jump.
        assert_eq!(seen[40], 10_100);
        assert_eq!(seen[60], 12_100);
        assert_eq!(seen[79], 14_000);
        // A lost sample doubles the next step's limit.
        let mut g = clamp16();
        g.update(0, 0);
        g.update(1_000, 2 * T);
        assert_eq!(g.x_ref, 200);
    }

    #[test]
    fn a_gap_restarts_the_clamp() {
        let mut g = clamp16();
        for i in 0..30u32 {
            g.update(10_000, i * T);
        }
        g.update(30_000, 40 * T);
        assert_eq!(g.x_ref, 30_000);
        g.reset();
        g.update(50_000, 50 * T);
        assert_eq!(g.x_ref, 50_000);
    }
}
