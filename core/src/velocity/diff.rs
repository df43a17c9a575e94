//! Backward differences: the one-sample difference and the k-sample difference, f32.
//!
//! `v = (x_n − x_{n−K}) / (t_n − t_{n−K})` with the time span counted in whole sample slots, so a
//! dropped sample inside the span is bridged exactly. Exact on any ramp; the noise gain is
//! √2·σ_x / (K·T_s), so at 10 kHz the one-sample difference turns 8 µm of position noise into
//! 113 mm/s of velocity noise — the reason it is only a reference point.
//! Group delay: K·T_s / 2.

use super::common::{check_period, to_um_s, Sampler, Step};
use super::{EstimatorError, VelocityEstimator};

/// K-sample backward difference.
#[derive(Clone, Debug)]
pub struct BackwardDifference<const K: usize> {
    /// The last K positions with their slot numbers; `head` is the oldest once full.
    ring: [(i32, u32); K],
    head: usize,
    len: usize,
    slot: u32,
    sampler: Sampler,
}

/// The one-sample difference.
pub type OneSampleDifference = BackwardDifference<1>;

impl<const K: usize> BackwardDifference<K> {
    /// An estimator for samples every `sample_period_us`.
    pub fn new(sample_period_us: u32) -> Result<Self, EstimatorError> {
        if K < 1 {
            return Err(EstimatorError::WindowTooShort { window: K, min: 1 });
        }
        check_period(sample_period_us)?;
        Ok(Self {
            ring: [(0, 0); K],
            head: 0,
            len: 0,
            slot: 0,
            sampler: Sampler::new(sample_period_us),
        })
    }

    /// Forgets the positions (the sampler is the caller's).
    fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.slot = 0;
    }
}

impl<const K: usize> VelocityEstimator for BackwardDifference<K> {
    #[allow(
        clippy::indexing_slicing,
        reason = "ring indices stay below the ring's length: each is reduced mod the length or is `head`/`newest`, which only ever take such values"
    )]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        match self.sampler.step(t_us) {
            Step::Repeat => return self.sampler.last_out(),
            Step::Start => self.clear(),
            Step::Slots(m) => self.slot = self.slot.wrapping_add(m),
        }
        let out = if self.len == K {
            let (x_old, s_old) = self.ring[self.head];
            let span_s =
                self.slot.wrapping_sub(s_old) as f32 * self.sampler.period_us() as f32 * 1e-6;
            let v = (position_um as f32 - x_old as f32) / span_s;
            self.ring[self.head] = (position_um, self.slot);
            self.head = (self.head + 1) % K;
            Some(to_um_s(v))
        } else {
            self.ring[(self.head + self.len) % K] = (position_um, self.slot);
            self.len += 1;
            None
        };
        self.sampler.answer(out)
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        K as u32 * self.sampler.period_us() / 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_on_ramps_both_directions() {
        let mut e1 = OneSampleDifference::new(100).unwrap();
        let mut e8 = BackwardDifference::<8>::new(100).unwrap();
        let (mut v1, mut v8) = (None, None);
        for i in 0..20i32 {
            // 20 mm/s = 2 µm per 100 µs.
            v1 = e1.update(1_000 + 2 * i, i as u32 * 100);
            v8 = e8.update(60_000 - 7 * i, i as u32 * 100);
        }
        assert_eq!(v1, Some(20_000));
        assert_eq!(v8, Some(-70_000));
    }

    #[test]
    fn none_until_k_back_then_zero_at_rest() {
        let mut e = BackwardDifference::<4>::new(100).unwrap();
        for i in 0..4u32 {
            assert_eq!(e.update(31_500, i * 100), None);
        }
        assert_eq!(e.update(31_500, 400), Some(0));
    }

    #[test]
    fn dropped_sample_bridged_exactly_and_long_gap_restarts() {
        let mut e = BackwardDifference::<2>::new(100).unwrap();
        let x = |t: u32| (t / 10) as i32; // 100 mm/s: 10 µm per sample
        e.update(x(0), 0);
        e.update(x(100), 100);
        assert_eq!(e.update(x(200), 200), Some(100_000));
        // The sample at 300 µs is lost: the span is three slots, not two.
        assert_eq!(e.update(x(400), 400), Some(100_000));
        // A silence of 1 ms restarts: no output until two more samples.
        assert_eq!(e.update(x(1_400), 1_400), None);
    }

    #[test]
    fn reset_forgets_history() {
        let mut e = OneSampleDifference::new(100).unwrap();
        e.update(0, 0);
        assert_eq!(e.update(5, 100), Some(50_000));
        e.reset();
        assert_eq!(e.update(1_000, 200), None);
        assert_eq!(e.update(1_000, 300), Some(0));
        assert_eq!(e.group_delay_us(), 50);
    }

    #[test]
    fn rejects_bad_config() {
        assert_eq!(
            BackwardDifference::<0>::new(100).err(),
            Some(EstimatorError::WindowTooShort { window: 0, min: 1 })
        );
        assert_eq!(
            OneSampleDifference::new(5).err(),
            Some(EstimatorError::BadSamplePeriod {
                sample_period_us: 5
            })
        );
    }
}
