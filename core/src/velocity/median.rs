//! Median-of-3 pre-filter: wraps any estimator and feeds it the median of the last three
//! positions, stamped with the middle sample's time.
//!
//! A single-sample outlier (a wiper spark, an ADC glitch) never reaches the inner estimator; a
//! ramp passes unchanged (the median of three samples of a monotone ramp is the middle one).
//! Cost: two or three compares per sample. Group delay: the inner estimator's plus one sample.
//! Not removed: two consecutive outliers, and the corner of a reversal is clipped by one sample.
//! After a silence the inner estimator restarts on (its slot clock's gap rule), the window
//! starts over too, so no position from before the silence is mixed into the ones after.

use super::{VelocityEstimator, MAX_BRIDGED_SLOTS};

/// Median-of-3 pre-filter around `E`.
#[derive(Clone, Debug)]
pub struct Median3<E> {
    inner: E,
    /// The two previous positions, older first (only the last two are kept: the third is the
    /// new sample, so nothing is shifted through an array).
    x_old: i32,
    x_mid: i32,
    /// Timestamp of `x_mid`, the time the median is stamped with.
    t_mid: u32,
    /// Samples seen since the last reset, saturating at 2.
    len: u8,
    period_us: u32,
    /// ⌊period/2⌋, so that an offset rounds to the nearest whole period as the slot clock does.
    half_us: u32,
    /// (MAX_BRIDGED_SLOTS + 1) periods: a rounded offset from here on is a gap.
    gap_us: u32,
}

impl<E: VelocityEstimator> Median3<E> {
    /// Wraps `inner`, whose samples come every `sample_period_us`.
    pub fn new(inner: E, sample_period_us: u32) -> Self {
        Self {
            inner,
            x_old: 0,
            x_mid: 0,
            t_mid: 0,
            len: 0,
            period_us: sample_period_us,
            half_us: sample_period_us / 2,
            gap_us: sample_period_us.saturating_mul(MAX_BRIDGED_SLOTS + 1),
        }
    }

    /// The wrapped estimator.
    pub fn inner(&self) -> &E {
        &self.inner
    }
}

fn median3(a: i32, b: i32, c: i32) -> i32 {
    a.max(b).min(a.min(b).max(c))
}

impl<E: VelocityEstimator> VelocityEstimator for Median3<E> {
    #[inline(always)]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        // A gap (or time run backwards, which wraps to a huge offset): start the window over.
        if t_us.wrapping_sub(self.t_mid).wrapping_add(self.half_us) >= self.gap_us {
            self.len = 0;
        }
        let (a, b, t) = (self.x_old, self.x_mid, self.t_mid);
        self.x_old = b;
        self.x_mid = position_um;
        self.t_mid = t_us;
        if self.len < 2 {
            self.len += 1;
            return None;
        }
        self.inner.update(median3(a, b, position_um), t)
    }

    fn reset(&mut self) {
        self.len = 0;
        self.inner.reset();
    }

    fn group_delay_us(&self) -> u32 {
        self.inner.group_delay_us() + self.period_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocity::{LsqSlope, OneSampleDifference};

    #[test]
    fn median_of_three() {
        for (a, b, c) in [
            (1, 2, 3),
            (3, 2, 1),
            (2, 1, 3),
            (2, 3, 1),
            (3, 1, 2),
            (1, 3, 2),
        ] {
            assert_eq!(median3(a, b, c), 2);
        }
        assert_eq!(median3(5, 5, -1), 5);
    }

    #[test]
    fn ramp_passes_exactly_and_outlier_is_removed() {
        let mut e = Median3::new(OneSampleDifference::new(100).unwrap(), 100);
        let mut outs = [None; 40];
        for i in 0..40i32 {
            let mut x = 1_000 + 4 * i;
            if i == 20 {
                x += 5_000; // a spike
            }
            outs[i as usize] = e.update(x, i as u32 * 100);
        }
        assert_eq!(outs[2], None);
        // The spike (50 m/s through a raw difference) never shows. Around it the median hands
        // on the neighbour's position in its place, which a one-sample difference sees as one
        // doubled step and one null step — and nothing else.
        assert_eq!(outs[21], Some(80_000));
        assert_eq!(outs[23], Some(0));
        for (i, v) in outs.iter().enumerate().skip(3) {
            if i != 21 && i != 23 {
                assert_eq!(*v, Some(40_000), "sample {i}");
            }
        }
    }

    #[test]
    fn zero_at_rest_delay_and_reset() {
        let mut e = Median3::new(LsqSlope::<8>::new(100).unwrap(), 100);
        let mut v = None;
        for i in 0..20u32 {
            v = e.update(7_000, i * 100);
        }
        assert_eq!(v, Some(0));
        assert_eq!(e.group_delay_us(), 350 + 100);
        e.reset();
        assert_eq!(e.update(7_000, 2_000), None);
        assert_eq!(e.update(7_000, 2_100), None);
    }

    #[test]
    fn dropped_sample_passes_to_the_inner_estimator() {
        // The inner difference sees the middle sample's true time, so a lost sample is bridged.
        let mut e = Median3::new(OneSampleDifference::new(100).unwrap(), 100);
        let mut v = None;
        for i in 0..30u32 {
            if i == 15 {
                continue;
            }
            v = e.update(3 * i as i32, i * 100);
            assert!(v.is_none() || v == Some(30_000), "{i}: {v:?}");
        }
        assert_eq!(v, Some(30_000));
    }
}
