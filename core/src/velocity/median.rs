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
    /// Samples seen since the last reset, saturating at 3 (the first median).
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

impl<E> Median3<E> {
    /// Takes a sample into the three-position window: the median of the last three and the
    /// middle one's time, or None while the window refills (after a reset or a gap).
    #[inline(always)]
    fn median(&mut self, position_um: i32, t_us: u32) -> Option<(i32, u32)> {
        // A gap (or time run backwards, which wraps to a huge offset): start the window over.
        if t_us.wrapping_sub(self.t_mid).wrapping_add(self.half_us) >= self.gap_us {
            self.len = 0;
        }
        let (a, b, t) = (self.x_old, self.x_mid, self.t_mid);
        self.x_old = b;
        self.x_mid = position_um;
        self.t_mid = t_us;
        if self.len < 3 {
            // The third sample since the start is the first median: from then on `len` stays
            // at 3, which tells `estimate` a median has gone in.
            self.len += 1;
            if self.len < 3 {
                return None;
            }
        }
        Some((median3(a, b, position_um), t))
    }
}

pub(crate) fn median3(a: i32, b: i32, c: i32) -> i32 {
    a.max(b).min(a.min(b).max(c))
}

impl<E: VelocityEstimator> VelocityEstimator for Median3<E> {
    #[inline(always)]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        let (m, t) = self.median(position_um, t_us)?;
        self.inner.update(m, t)
    }

    fn reset(&mut self) {
        self.len = 0;
        self.inner.reset();
    }

    /// The window is three positions: a rest keeps it as an update does and rests the inner
    /// estimator, if that one rests.
    #[inline(always)]
    fn rests(&self) -> bool {
        self.inner.rests()
    }

    #[inline(always)]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        if let Some((m, t)) = self.median(position_um, t_us) {
            self.inner.rest(m, t);
        }
    }

    fn wake(&mut self) {
        self.inner.wake();
    }

    /// Two samples more than the inner window: the first median needs three.
    #[inline(always)]
    fn window_samples(&self) -> usize {
        match self.inner.window_samples() {
            0 => 0,
            n => n + 2,
        }
    }

    #[inline(always)]
    fn estimate(&self) -> Option<i32> {
        // While the window refills after a reset or a gap `update` answers None.
        if self.len < 3 {
            return None;
        }
        self.inner.estimate()
    }

    fn group_delay_us(&self) -> u32 {
        self.inner.group_delay_us() + self.period_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocity::{LsqSlope, OneSampleDifference};

    /// `window_samples` is where an estimator fed from scratch first answers (a seed of that
    /// many positions gives it its whole window); 0 for one that is never seeded.
    #[test]
    fn the_window_is_where_the_first_answer_comes() {
        fn first_answer<E: VelocityEstimator>(mut e: E) -> (usize, usize) {
            let at = (1..200)
                .find(|&k| e.update(1_000 + 9 * k as i32, k as u32 * 100).is_some())
                .unwrap_or(0);
            (e.window_samples(), at)
        }
        let (w, at) = first_answer(Median3::new(LsqSlope::<32>::new(100).unwrap(), 100));
        assert_eq!((w, at), (34, 34));
        let (w, at) = first_answer(Median3::new(LsqSlope::<26>::new(100).unwrap(), 100));
        assert_eq!((w, at), (28, 28));
        let (w, at) = first_answer(LsqSlope::<26>::new(100).unwrap());
        assert_eq!((w, at), (26, 26));
        let (w, _) = first_answer(Median3::new(OneSampleDifference::new(100).unwrap(), 100));
        assert_eq!(w, 0);
    }

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

    /// An estimator whose state is not a window does not rest: it says so, a rest is an
    /// update, and it has no estimate of its own to offer (the controller keeps the last).
    #[test]
    fn an_estimator_that_cannot_rest_is_updated() {
        let mut e = OneSampleDifference::new(100).unwrap();
        assert!(!e.rests());
        for i in 0..5u32 {
            e.rest(10 * i as i32, i * 100);
        }
        assert_eq!(e.update(50, 500), Some(100_000));
        assert_eq!(e.estimate(), None);
        assert!(Median3::new(LsqSlope::<8>::new(100).unwrap(), 100).rests());
        assert!(!Median3::new(OneSampleDifference::new(100).unwrap(), 100).rests());
    }

    /// The controller's contract (docs/sample-contract.md): an estimator rested through any
    /// run of samples and woken answers, from then on, exactly what one updated on every
    /// sample answers, and `estimate` reads the same figure at any point of a rest. Streams
    /// with jitter, lost samples, duplicates, silences (restarts) and time running backwards;
    /// rest runs of every length, the window's edge included. The plain slope at a narrow
    /// window (wrapping i32 sums), a short one and a wide one (i64 sums), and the default
    /// median-of-3 in front of it.
    mod rest_then_wake {
        use super::*;
        use crate::velocity::VelocityEstimator;
        use proptest::prelude::*;

        fn check<E: VelocityEstimator + Clone>(
            fresh: E,
            steps: &[(i32, u32, bool)],
        ) -> Result<(), TestCaseError> {
            prop_assert!(fresh.rests());
            let (mut always, mut rested) = (fresh.clone(), fresh);
            let (mut t, mut x, mut resting) = (1_000u32, 20_000i32, false);
            for (i, &(dx, dt, rest)) in steps.iter().enumerate() {
                x = x.wrapping_add(dx).clamp(0, 1_000_000);
                t = t.wrapping_add(dt);
                let want = always.update(x, t);
                if rest {
                    rested.rest(x, t);
                    resting = true;
                    prop_assert_eq!(
                        rested.estimate(),
                        want,
                        "estimate while resting, sample {}",
                        i
                    );
                } else {
                    if resting {
                        rested.wake();
                        resting = false;
                    }
                    prop_assert_eq!(rested.update(x, t), want, "update after wake, sample {}", i);
                    prop_assert_eq!(
                        rested.estimate(),
                        want,
                        "estimate awake, sample {} of {}",
                        i,
                        core::any::type_name::<E>()
                    );
                }
            }
            Ok(())
        }

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(400))]
            #[test]
            fn a_rested_estimator_woken_answers_as_one_never_rested(
                steps in proptest::collection::vec(
                    (
                        prop_oneof![8 => -300i32..300, 1 => -600_000i32..600_000],
                        // On the grid with jitter; lost samples; duplicates; a silence (gap);
                        // time run backwards (wraps to a huge step).
                        prop_oneof![12 => 60u32..140, 2 => 150u32..450, 1 => 0u32..40, 1 => 500u32..5_000, 1 => (u32::MAX - 300)..=u32::MAX],
                        // Rest runs: long and short.
                        prop::bool::weighted(0.5),
                    ),
                    1..400,
                ),
                run_len in 1usize..80,
            ) {
                // Stretch each rest/awake choice over `run_len` samples so rests span windows.
                let steps: std::vec::Vec<_> = steps
                    .iter()
                    .enumerate()
                    .map(|(i, &(dx, dt, _))| (dx, dt, steps[i / run_len * run_len].2))
                    .collect();
                check(LsqSlope::<32>::new(100).unwrap(), &steps)?;
                check(LsqSlope::<7>::new(100).unwrap(), &steps)?;
                check(LsqSlope::<80>::new(100).unwrap(), &steps)?;
                check(Median3::new(LsqSlope::<32>::new(100).unwrap(), 100), &steps)?;
                check(Median3::new(LsqSlope::<26>::new(100).unwrap(), 100), &steps)?;
                // The outlier guards (issue #35): the same contract.
                check(crate::velocity::InnovationGate::new(LsqSlope::<16>::new(100).unwrap(), 100, 100, 2), &steps)?;
                check(crate::velocity::StepClamp::new(LsqSlope::<16>::new(100).unwrap(), 100, 1_000_000), &steps)?;
            }
        }
    }
}
