//! Least-squares slope estimator: O(1) integer running sums, bit-exact on every platform.
//!
//! Samples are placed on the sampling grid by the shared slot clock (`common.rs`): timestamp
//! jitter below half a period is rounded away, a lost sample (a step of 2..=4 slots) is bridged by
//! the straight line between its neighbours, so a ramp stays exact through it, and only a longer
//! silence or time running backwards restarts the window.

use super::common::{check_period, Sampler, Tick};
use super::{EstimatorError, VelocityEstimator};

/// Longest window whose sums [`LsqSlope`] keeps in 32-bit arithmetic (wrapping): exact while
/// the slope's centred sum Σ(2k − (N − 1))·x_k fits i32. That sum does not change when every
/// position moves by the same amount and is at most N²/4 times the spread of the window's
/// positions: 1 024 × spread at N = 64, so any window spread under 2.09 m (the substrate is at
/// most 1 m: `position::MAX_LENGTH_UM`). On the M4F a 32-bit add or multiply is one
/// instruction where a 64-bit one is two to four (−12 per sample, `docs/target-cost.md`).
/// Longer windows (the conversion-budget study's, up to 256) keep them in i64, exact for any
/// positions.
pub const LSQ_NARROW_WINDOW: usize = 64;

/// Least-squares slope over the last `N` samples, integer arithmetic.
#[derive(Clone, Debug)]
pub struct LsqSlope<const N: usize> {
    window: [i32; N],
    /// Index of the oldest entry once full.
    head: usize,
    len: usize,
    /// Σ x_k over the window. Up to [`LSQ_NARROW_WINDOW`] samples it is kept mod 2^32 (the
    /// low word, sign-extended): it reaches the slope only through the centred sum's update,
    /// whose true value fits i32 there, so the wrapped result is exact.
    sum: i64,
    /// While filling: Σ k·x_k with k = 0 for the oldest entry (W). Once full: the centred sum
    /// 2W − (N − 1)·Σx the slope is made of, kept up to date directly (it saves recomputing it
    /// from W every sample). Mod 2^32 like `sum` for a narrow window; the centred sum is then
    /// exact.
    weighted: i64,
    sampler: Sampler,
    /// Samples went in by [`VelocityEstimator::rest`] since the last update: the window and
    /// the sums are current, the slope and `Sampler`'s last answer are not.
    resting: bool,
    /// µm/s per unit of 2·Σ(k − (N−1)/2)·x_k, Q32: 6·10⁶ / (N (N²−1) T_s).
    gain_q32: i64,
    /// The range of the centred sum whose rounded product with `gain_q32` is an i32 speed:
    /// inside it the product neither overflows i64 nor needs clamping, outside the speed
    /// saturates (worked out once: one range test on the M4F instead of a 64-bit overflow
    /// check and a 64-bit clamp).
    centred_min: i64,
    centred_max: i64,
}

impl<const N: usize> LsqSlope<N> {
    /// An estimator for samples every `sample_period_us`.
    pub fn new(sample_period_us: u32) -> Result<Self, EstimatorError> {
        if N < 2 {
            return Err(EstimatorError::WindowTooShort { window: N, min: 2 });
        }
        check_period(sample_period_us)?;
        let gain_q32 = slope_gain_q32(N, sample_period_us);
        let (centred_min, centred_max) = speed_range(gain_q32);
        Ok(Self {
            window: [0; N],
            head: 0,
            len: 0,
            sum: 0,
            weighted: 0,
            sampler: Sampler::new(sample_period_us),
            resting: false,
            gain_q32,
            centred_min,
            centred_max,
        })
    }
}

impl<const N: usize> LsqSlope<N> {
    /// Adds a position at the next slot, dropping the oldest once the window is full.
    #[inline(always)]
    #[allow(
        clippy::indexing_slicing,
        reason = "ring indices stay below the ring's length: each is reduced mod the length or is `head`/`newest`, which only ever take such values"
    )]
    fn push(&mut self, position_um: i32) {
        // `head` < N always; the `% N` (an AND for N = 32) shows it to the compiler, so no
        // bounds check stays on the per-sample path (scripts/panic-check.sh).
        let head = self.head % N;
        if self.len < N {
            self.fill(position_um);
            self.window[(head + self.len) % N] = position_um;
            self.len += 1;
            return;
        }
        let oldest = self.window[head];
        // Every remaining entry's index drops by one and the newest enters at N − 1:
        // W' = W − (S − oldest) + (N − 1)x and S' = S − oldest + x, so the centred sum
        // C = 2W − (N − 1)S moves by C' − C = −2S + (N + 1)·oldest + (N − 1)x.
        if N <= LSQ_NARROW_WINDOW {
            let (s, c, x, o) = (self.sum as i32, self.weighted as i32, position_um, oldest);
            let c = c
                .wrapping_sub(s.wrapping_mul(2))
                .wrapping_add((N as i32 + 1).wrapping_mul(o))
                .wrapping_add((N as i32 - 1).wrapping_mul(x));
            self.weighted = c as i64;
            self.sum = s.wrapping_add(x.wrapping_sub(o)) as i64;
        } else {
            let (x, o) = (position_um as i64, oldest as i64);
            self.weighted += -2 * self.sum + (N as i64 + 1) * o + (N as i64 - 1) * x;
            self.sum += x - o;
        }
        self.window[head] = position_um;
        self.head = (head + 1) % N;
    }

    /// Adds a sample to a window not yet full (its index is `len`); the last one turns Σk·x_k
    /// into the centred sum.
    #[inline(always)]
    fn fill(&mut self, position_um: i32) {
        if N <= LSQ_NARROW_WINDOW {
            let (s, w, x) = (self.sum as i32, self.weighted as i32, position_um);
            let w = w.wrapping_add((self.len as i32).wrapping_mul(x));
            let s = s.wrapping_add(x);
            let w = if self.len + 1 == N {
                w.wrapping_mul(2)
                    .wrapping_sub((N as i32 - 1).wrapping_mul(s))
            } else {
                w
            };
            self.sum = s as i64;
            self.weighted = w as i64;
        } else {
            let x = position_um as i64;
            self.weighted += self.len as i64 * x;
            self.sum += x;
            if self.len + 1 == N {
                self.weighted = 2 * self.weighted - (N as i64 - 1) * self.sum;
            }
        }
    }

    /// The slope of a full window, µm/s.
    #[inline(always)]
    fn slope(&self) -> Option<i32> {
        if self.len < N {
            return None;
        }
        Some(self.speed(self.weighted))
    }

    /// The speed, µm/s, of centred sum `centred2`, rounded to nearest and saturating. Any real
    /// window is inside the range (N = 32, T_s = 100 µs, a full 63 mm jump: 3·10⁸ µm/s of
    /// 2.1·10⁹). A pathological window saturates when it is wider than
    /// [`LSQ_NARROW_WINDOW`]; a narrow one's positions must lie within 2.09 m of each other
    /// (beyond, its 32-bit sums wrap), as the controller's, within the substrate, do.
    #[inline(always)]
    fn speed(&self, centred2: i64) -> i32 {
        if (self.centred_min..=self.centred_max).contains(&centred2) {
            ((centred2 * self.gain_q32 + (1 << 31)) >> 32) as i32
        } else if centred2 > 0 {
            i32::MAX
        } else {
            i32::MIN
        }
    }

    /// Empties the window (the sampler is the caller's).
    fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.sum = 0;
        self.weighted = 0;
        self.resting = false;
    }

    /// Places a sample on the grid and pushes it (and the lost samples before it, on the line
    /// between their neighbours) into the window and its sums. None for a duplicate, which
    /// changes nothing.
    #[inline(always)]
    fn place(&mut self, position_um: i32, t_us: u32) -> Option<()> {
        // The clock's own tick, not `Sampler::step`: on a gap the clock has restarted on this
        // sample already, keeping its sub-µs grid phase (`step` would restart it from scratch, as
        // the other estimators do), and only the window is cleared.
        match self.sampler.tick(t_us) {
            Tick::Duplicate => return None,
            Tick::Gap => self.clear(),
            Tick::Slots(m) if m > 1 && self.len > 0 => {
                // Lost samples: fill their slots on the line between the neighbours. The newest
                // is at (head + len − 1) mod N, always inside the window: `get` is never None.
                if let Some(&newest) = self.window.get((self.head + self.len - 1) % N) {
                    let (a, b) = (newest as i64, position_um as i64);
                    for k in 1..m as i64 {
                        self.push((a + (b - a) * k / m as i64) as i32);
                    }
                }
            }
            Tick::First | Tick::Slots(_) => {}
        }
        self.push(position_um);
        Some(())
    }
}

/// µm/s per unit of the centred sum 2·Σ(k − (N−1)/2)·x_k of an `n`-sample window, Q32:
/// 6·10⁶ / (n (n²−1) T_s), rounded (`n` ≥ 2 and a period of at least 10 µs: the constructors'
/// checks). Shared with the plane's two-axis slope (`plane::velocity::PlaneLsq`).
pub(crate) fn slope_gain_q32(n: usize, sample_period_us: u32) -> i64 {
    let n = n as i64;
    let denom = n * (n * n - 1) * sample_period_us as i64;
    let gain_q32 = ((6_000_000i128 << 32) + denom as i128 / 2) / denom as i128;
    gain_q32 as i64
}

/// The centred sums c whose speed ⌊(c·g + 2³¹) / 2³²⌋ lies in i32, for a gain g ≥ 0: the
/// speed grows with c, so it is the interval between the smallest c reaching i32::MIN and
/// the largest staying at or below i32::MAX (in i128, where c·g cannot overflow), narrowed
/// to where c·g + 2³¹ fits i64. A zero gain gives speed 0 for every c.
pub(crate) fn speed_range(gain_q32: i64) -> (i64, i64) {
    if gain_q32 <= 0 {
        return (i64::MIN, i64::MAX);
    }
    let g = gain_q32 as i128;
    let half = 1i128 << 31;
    // c·g + 2³¹ ≤ (MAX + 1)·2³² − 1 and c·g + 2³¹ ≥ MIN·2³², each also within i64.
    let hi =
        ((((i32::MAX as i128 + 1) << 32) - 1 - half).min(i64::MAX as i128 - half)).div_euclid(g);
    // c·g + 2³¹ ≥ MIN·2³² = −2⁶³ holds for every c·g that fits i64 (−2⁶³ + 2³¹ floors to
    // MIN too): the lower end is where the product itself would overflow.
    let lo = -((1i128 << 63) / g);
    (lo as i64, hi as i64)
}

impl<const N: usize> VelocityEstimator for LsqSlope<N> {
    // Once per sample from one call site: inlined, so the window's fields stay in registers
    // (a call costs the M4F a prologue, spills and an epilogue every sample).
    #[inline(always)]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        debug_assert!(!self.resting, "update after rest without wake");
        match self.place(position_um, t_us) {
            None => self.sampler.last_out(),
            Some(()) => self.sampler.answer(self.slope()),
        }
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        (N as u32 - 1) * self.sampler.period_us() / 2
    }

    /// A rest keeps the slot clock, the window and its two running sums (a few adds) and skips
    /// the slope (a 64-bit multiply and the range test) and its bookkeeping: the slope is
    /// there in O(1) whenever asked.
    #[inline(always)]
    fn rests(&self) -> bool {
        true
    }

    #[inline(always)]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        if self.place(position_um, t_us).is_some() {
            self.resting = true;
        }
    }

    fn wake(&mut self) {
        if self.resting {
            self.resting = false;
            // What `update` would have answered on the last rested sample: a duplicate next
            // repeats it.
            self.sampler.answer(self.slope());
        }
    }

    /// N on-grid samples fill the window, whose slope is the estimate.
    #[inline(always)]
    fn window_samples(&self) -> usize {
        N
    }

    #[inline(always)]
    fn estimate(&self) -> Option<i32> {
        if !self.resting {
            return self.sampler.last_out();
        }
        self.slope()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::velocity::EstimatorError;

    /// Inside the precomputed range and just outside it the speed is the exact rounded,
    /// saturated product (worked in i128), for several windows and periods, and the range's
    /// ends are where it stops being representable without a clamp.
    #[test]
    fn the_range_test_is_the_exact_saturated_product() {
        fn check<const N: usize>(period_us: u32) {
            let e = LsqSlope::<N>::new(period_us).unwrap();
            let exact = |c: i64| {
                let v = ((c as i128 * e.gain_q32 as i128) + (1 << 31)) >> 32;
                v.clamp(i32::MIN as i128, i32::MAX as i128) as i32
            };
            for c in [e.centred_min, e.centred_max, 0, i64::MIN, i64::MAX] {
                for d in -2..=2i64 {
                    let c = c.saturating_add(d);
                    assert_eq!(e.speed(c), exact(c), "N {N} T {period_us} c {c}");
                }
            }
            // The ends are tight: one further out needs the clamp or overflows i64.
            let wide = |c: i64| {
                c.checked_mul(e.gain_q32)
                    .and_then(|p| p.checked_add(1 << 31))
                    .is_none_or(|p| i32::try_from(p >> 32).is_err())
            };
            assert!(
                !wide(e.centred_max) && wide(e.centred_max + 1),
                "N {N} T {period_us}"
            );
            assert!(
                !wide(e.centred_min) && wide(e.centred_min - 1),
                "N {N} T {period_us}"
            );
        }
        check::<2>(10);
        check::<32>(100);
        check::<64>(100);
        check::<16>(100_000);
        check::<1024>(100_000);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 512, ..Default::default() })]
        /// The sums give the exact slope: every output equals the least-squares centred sum
        /// of the last N positions worked in i128 (times the gain, rounded and saturated),
        /// over positions anywhere on a 1 m substrate, jumps from one end to the other
        /// included, at the longest narrow window (wrapping i32 sums), a short one and a wide
        /// one (i64 sums).
        #[test]
        fn the_wrapping_sums_are_the_exact_slope(
            xs in proptest::collection::vec(
                proptest::prop_oneof![0i32..=1_000_000, 499_990i32..500_010, proptest::strategy::Just(0), proptest::strategy::Just(1_000_000)],
                1..300,
            ),
        ) {
            fn run<const N: usize>(xs: &[i32]) -> Result<(), proptest::test_runner::TestCaseError> {
                let mut e = LsqSlope::<N>::new(10).unwrap();
                for (i, &x) in xs.iter().enumerate() {
                    let got = e.update(x, i as u32 * 10);
                    let want = (i + 1 >= N).then(|| {
                        let c: i128 = xs[i + 1 - N..=i]
                            .iter()
                            .enumerate()
                            .map(|(k, &x)| (2 * k as i128 - (N as i128 - 1)) * x as i128)
                            .sum();
                        let v = (c * e.gain_q32 as i128 + (1 << 31)) >> 32;
                        v.clamp(i32::MIN as i128, i32::MAX as i128) as i32
                    });
                    proptest::prop_assert_eq!(got, want, "N {} sample {}", N, i);
                }
                Ok(())
            }
            run::<64>(&xs)?;
            run::<7>(&xs)?;
            // A wide window: its sums in i64.
            run::<80>(&xs)?;
        }
    }

    #[test]
    fn exact_on_a_ramp() {
        let mut e = LsqSlope::<32>::new(100).unwrap();
        let mut last = None;
        for i in 0..100u32 {
            // 20 mm/s = 2 µm per 100 µs sample.
            last = e.update(1_000 + 2 * i as i32, i * 100);
        }
        assert_eq!(last, Some(20_000));
    }

    #[test]
    fn none_until_window_full_and_after_gap() {
        let mut e = LsqSlope::<8>::new(100).unwrap();
        for i in 0..7u32 {
            assert_eq!(e.update(i as i32, i * 100), None);
        }
        assert_eq!(e.update(7, 700), Some(10_000));
        // A dropped sample (a step of 2 periods) is bridged: still 1 µm per 100 µs.
        assert_eq!(e.update(9, 900), Some(10_000));
        // A late stamp (+40 µs) is rounded to its slot; a repeated reading changes nothing.
        assert_eq!(e.update(10, 1_040), Some(10_000));
        assert_eq!(e.update(10, 1_045), Some(10_000));
        assert_eq!(e.update(11, 1_100), Some(10_000));
        // Six periods of silence restart the window.
        assert_eq!(e.update(17, 1_700), None);
        // So does time running backwards.
        let mut e = LsqSlope::<8>::new(100).unwrap();
        for i in 0..8u32 {
            e.update(i as i32, 10_000 + i * 100);
        }
        assert_eq!(e.update(8, 5_000), None);
    }

    #[test]
    fn negative_and_zero_speeds() {
        let mut e = LsqSlope::<16>::new(100).unwrap();
        let mut v = None;
        for i in 0..40u32 {
            v = e.update(50_000 - 30 * i as i32, i * 100);
        }
        assert_eq!(v, Some(-300_000));
        let mut e = LsqSlope::<16>::new(100).unwrap();
        for i in 0..40u32 {
            v = e.update(12_345, i * 100);
        }
        assert_eq!(v, Some(0));
    }

    #[test]
    fn rejects_bad_config() {
        assert_eq!(
            LsqSlope::<1>::new(100).err(),
            Some(EstimatorError::WindowTooShort { window: 1, min: 2 })
        );
        assert_eq!(
            LsqSlope::<4>::new(0).err(),
            Some(EstimatorError::BadSamplePeriod {
                sample_period_us: 0
            })
        );
    }

    /// Both refusals read as sentences naming the value and the limit.
    #[test]
    fn errors_read_as_sentences() {
        let e = LsqSlope::<1>::new(100).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "a velocity window of 1 samples is shorter than the 2 the estimator needs"
        );
        let e = LsqSlope::<4>::new(100_001).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "sample period 100001 µs is outside the estimators' 10 µs to 100000 µs"
        );
    }
}
