//! First-order adaptive windowing (FOAW), end-fit and best-fit, f32.
//!
//! Janabi-Sharifi, Hayward & Chen, "Discrete-time adaptive windowing for velocity estimation",
//! IEEE TCST 8(6), 2000. The window is the longest one, up to `n_max` steps back, whose straight
//! line stays within the uncertainty band `d` of every sample it spans; the velocity is that
//! line's slope. A long window at steady speed (low noise), a short one when the motion bends
//! (low lag): the adaptivity is the whole point — and its cost is O(n²) per sample in the worst
//! case, because every candidate window re-checks all its samples.
//!
//! The acceptance test used here, exactly. For a window reaching `n` samples back (n = 1, 2, …,
//! n_max, slot distances s_i from the newest sample, i = 0..=n):
//! - **end-fit**: the line through the newest sample x_0 and the oldest x_n; accepted iff every
//!   *intermediate* sample (0 < i < n) satisfies |x_i − line(s_i)| ≤ d;
//! - **best-fit**: the least-squares line through all n + 1 samples (through their centroid, not
//!   pinned to the newest sample); accepted iff *every* sample (0 ≤ i ≤ n) satisfies
//!   |x_i − line(s_i)| ≤ d.
//!
//! n = 1 (two samples) is always accepted. n grows one step at a time and stops at the first
//! rejected window: the estimate is the slope of the last accepted one (as in the paper's
//! algorithm, which does not look past a failure). `d` is the noise band: about 2–3 σ of the
//! position noise; quantization alone needs d ≥ one position step.
//!
//! Group delay: n·T_s/2 of the window in use ([`VelocityEstimator::group_delay_us`] reports the
//! current one; it is n_max·T_s/2 at a steady speed whose noise stays inside the band).

use super::common::{check_period, to_um_s, Sampler, Step, TuningError};
use super::VelocityEstimator;

/// Which line FOAW fits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FoawFit {
    /// Line through the window's two end samples.
    EndFit,
    /// Least-squares line through all of the window's samples.
    BestFit,
}

/// FOAW over at most `N` samples (windows of up to n_max = N − 1 steps).
#[derive(Clone, Debug)]
pub struct Foaw<const N: usize> {
    fit: FoawFit,
    band_um: f32,
    /// Positions and slot numbers; `newest` indexes the latest.
    ring: [(i32, u32); N],
    newest: usize,
    len: usize,
    slot: u32,
    sampler: Sampler,
    window: usize,
}

impl<const N: usize> Foaw<N> {
    /// FOAW with band `band_um` for samples every `sample_period_us`.
    pub fn new(fit: FoawFit, band_um: f32, sample_period_us: u32) -> Result<Self, TuningError> {
        if N < 2 {
            return Err(super::EstimatorError::WindowTooShort { window: N, min: 2 }.into());
        }
        check_period(sample_period_us)?;
        if !(band_um.is_finite() && band_um >= 0.0) {
            return Err(TuningError::BadBand { band_um });
        }
        Ok(Self {
            fit,
            band_um,
            ring: [(0, 0); N],
            newest: 0,
            len: 0,
            slot: 0,
            sampler: Sampler::new(sample_period_us),
            window: 0,
        })
    }

    /// Forgets the samples and the window (the sampler is the caller's).
    fn clear(&mut self) {
        self.len = 0;
        self.slot = 0;
        self.window = 0;
    }

    /// Steps back of the window used for the last estimate (0 before the first).
    pub fn window(&self) -> usize {
        self.window
    }

    /// Sample `i` steps back (0 = newest) as (position relative to the newest, slots back).
    #[allow(
        clippy::indexing_slicing,
        reason = "ring indices stay below the ring's length: each is reduced mod the length or is `head`/`newest`, which only ever take such values"
    )]
    fn back(&self, i: usize) -> (f32, f32) {
        let (x0, s0) = self.ring[self.newest];
        let (x, s) = self.ring[(self.newest + N - i) % N];
        ((x - x0) as f32, s0.wrapping_sub(s) as f32)
    }

    /// Slope in µm per slot (positive = moving to the far end).
    fn slope(&mut self) -> f32 {
        let d = self.band_um;
        // n = 1 is always accepted.
        let (y1, s1) = self.back(1);
        let mut best = -y1 / s1;
        self.window = 1;
        // Best-fit running sums over i = 0..=n of s, s², y, s·y (y_0 = s_0 = 0).
        let (mut ss, mut ss2, mut sy, mut ssy) = (s1, s1 * s1, y1, s1 * y1);
        for n in 2..self.len {
            let (yn, sn) = self.back(n);
            let accepted = match self.fit {
                FoawFit::EndFit => {
                    // Line through (0, 0) and (s_n, y_n): y = c·s.
                    let c = yn / sn;
                    let ok = (1..n).all(|i| {
                        let (y, s) = self.back(i);
                        (y - c * s).abs() <= d
                    });
                    ok.then_some(-c)
                }
                FoawFit::BestFit => {
                    ss += sn;
                    ss2 += sn * sn;
                    sy += yn;
                    ssy += sn * yn;
                    let m = (n + 1) as f32;
                    let c = (m * ssy - ss * sy) / (m * ss2 - ss * ss);
                    let a = (sy - c * ss) / m;
                    let ok = (0..=n).all(|i| {
                        let (y, s) = self.back(i);
                        (y - (a + c * s)).abs() <= d
                    });
                    ok.then_some(-c)
                }
            };
            match accepted {
                Some(slope) => {
                    best = slope;
                    self.window = n;
                }
                None => break,
            }
        }
        best
    }
}

impl<const N: usize> VelocityEstimator for Foaw<N> {
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
        self.newest = (self.newest + 1) % N;
        self.ring[self.newest] = (position_um, self.slot);
        self.len = (self.len + 1).min(N);
        let out = if self.len >= 2 {
            let per_s = 1e6 / self.sampler.period_us() as f32;
            Some(to_um_s(self.slope() * per_s))
        } else {
            None
        };
        self.sampler.answer(out)
    }

    fn reset(&mut self) {
        self.clear();
        self.sampler.reset();
    }

    fn group_delay_us(&self) -> u32 {
        self.window as u32 * self.sampler.period_us() / 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn both(band: f32) -> [Foaw<16>; 2] {
        [
            Foaw::new(FoawFit::EndFit, band, 100).unwrap(),
            Foaw::new(FoawFit::BestFit, band, 100).unwrap(),
        ]
    }

    #[test]
    fn exact_on_a_ramp_with_the_full_window() {
        for mut e in both(0.5) {
            let mut v = None;
            for i in 0..40i32 {
                v = e.update(2_000 + 3 * i, i as u32 * 100);
            }
            assert_eq!(v, Some(30_000));
            assert_eq!(e.window(), 15);
            assert_eq!(e.group_delay_us(), 750);
        }
    }

    #[test]
    fn zero_at_rest_and_quantized_rest_inside_the_band() {
        for mut e in both(20.0) {
            let mut v = None;
            for i in 0..40u32 {
                // A rest position flickering by one 16 µm step (12-bit quantization).
                let x = 40_000 + if i % 3 == 0 { 16 } else { 0 };
                v = e.update(x, i * 100);
            }
            // The band covers the flicker, so the window is long and the slope small.
            assert!(v.unwrap().abs() < 3_000, "{v:?}");
            assert!(e.window() >= 14);
        }
        for mut e in both(0.0) {
            let mut v = None;
            for i in 0..20u32 {
                v = e.update(40_000, i * 100);
            }
            assert_eq!(v, Some(0));
        }
    }

    #[test]
    fn window_shrinks_at_a_corner() {
        for mut e in both(1.0) {
            // 30 mm/s then, from sample 20, −30 mm/s: a reversal.
            let x = |i: i32| if i < 20 { 3 * i } else { 120 - 3 * i };
            let mut v = None;
            for i in 0..24 {
                v = e.update(10_000 + x(i), i as u32 * 100);
            }
            // Three samples after the corner the window spans only the new segment.
            assert_eq!(v, Some(-30_000), "{:?}", e.fit);
            assert!(e.window() <= 4);
        }
    }

    #[test]
    fn dropped_sample_bridged_and_reset() {
        for mut e in both(0.5) {
            let mut v = None;
            for i in 0..30u32 {
                if i == 17 {
                    continue; // lost
                }
                v = e.update(5 * i as i32, i * 100);
            }
            assert_eq!(v, Some(50_000));
            e.reset();
            assert_eq!(e.update(0, 5_000), None);
            assert_eq!(e.window(), 0);
        }
    }

    #[test]
    fn rejects_bad_config() {
        assert!(Foaw::<1>::new(FoawFit::EndFit, 1.0, 100).is_err());
        assert!(matches!(
            Foaw::<8>::new(FoawFit::BestFit, f32::NAN, 100),
            Err(TuningError::BadBand { band_um }) if band_um.is_nan()
        ));
        assert_eq!(
            Foaw::<8>::new(FoawFit::BestFit, -1.0, 100).err(),
            Some(TuningError::BadBand { band_um: -1.0 })
        );
    }

    /// `reset` forgets the clock too: a sample on the very next slot is a first sample.
    #[test]
    fn reset_forgets_the_clock() {
        for mut e in both(0.5) {
            for i in 0..30u32 {
                e.update(5 * i as i32, i * 100);
            }
            e.reset();
            assert_eq!(e.update(150, 3_000), None);
            assert_eq!(e.window(), 0);
        }
    }
}
