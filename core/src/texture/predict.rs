//! Crossing prediction for the hybrid grating renderer: a least-squares line through the last
//! [`FIT_SAMPLES`] positions, kept in O(1) per sample, that says where the finger is now
//! (lag-free on a steady stroke) and when inside the coming sample period it reaches a ridge.
//!
//! Why a line and not the velocity estimator: the estimator's slope is centred half its window
//! back (1.65 ms at 10 kHz) and says nothing about *where* the finger is; the line's end point
//! is the finger's position at the newest sample with the noise of a 64-sample average
//! (σ·√((4N − 2)/(N(N + 1))) = 0.25 σ), which is what places a burst inside the period.
//!
//! The line is trusted only on a steady stroke: a full window of consecutive samples (a gap, a
//! dropped sample or a rejected glitch empties it), a speed above the trust speed, and every
//! new sample within [`INNOVATION_GATE_UM`] of where the line said it would be (a reversal or a
//! hard acceleration bends the path away from the line and empties it too). Otherwise the
//! renderer falls back to position phase.

/// Samples in the fit: 6.4 ms at 10 kHz. 16 gave 4–5 µm RMS on the host model but a worst
/// error above 10 µm at 2 LSB; 32 halved the end point's noise variance and left the closed
/// loop's steady worst at 10.2 µm (its 3 σ floor 8.4 µm); 64 halves it again (σ 0.35 → 0.25 of
/// one sample's): steady worst 6.6 µm (`tests/tests/hybrid.rs`). The price is the refill: after
/// a turn, a gap or a glitch the renderer is position phase for 6.4 ms instead of 3.2; the per
/// sample cost is the same (O(1) sums), the ring 128 B larger. Under acceleration the longer
/// window's bias (four times the 32-sample line's) is handed to its newer half
/// ([`DISAGREE_UM`]).
pub const FIT_SAMPLES: usize = 64;

/// Trust speed, µm/s: below it the line's slope is too close to its noise (0.23 µm per sample
/// RMS at 3 LSB, 10 kHz) to say which way the finger goes, and position phase places bursts
/// within the noise anyway (one sample of travel is 1 µm).
pub const TRUST_SPEED_UM_S: u32 = 10_000;

/// Largest distance, µm, between a new sample and the line's prediction for it before the line
/// is dropped. 6 σ of the innovation at 3 LSB (12 µm per sample); a 100 mm/s reversal leaves
/// the line by 2 × 10 µm per sample, so it is caught within four samples, before the line's
/// slope has turned.
pub const INNOVATION_GATE_UM: f32 = 72.0;

/// Largest distance, µm, between the ends of the full window's line and of its newer half's
/// before the half's is used. On a steady stroke the two differ by noise alone: σ·√(0.1225 −
/// 0.0611) = 0.25 σ (the full window's end is the efficient estimate, so the difference's
/// variance is the difference of the variances), 3.0 µm at 3 LSB; 9 µm is 3 σ of it. An
/// acceleration bends the path, and the full window's end, whose bias grows with the square
/// of its length, leaves the half's by more: then the half's line, four times less biased,
/// places the burst (the bench's mixed motion: RMS 19 µm on the full window alone, against 6
/// on a 32-sample line).
pub const DISAGREE_UM: f32 = 9.0;

/// Distance, µm, between the full end and the half's quick end below which the full line is
/// kept without the half's line: 1 µm inside [`DISAGREE_UM`], over twice the two ends' worst
/// rounding apart (see `LineFit::chosen`).
const AGREE_SURELY_UM: f32 = DISAGREE_UM - 1.0;

const N: usize = FIT_SAMPLES;
/// The newer half of the window.
const H: usize = FIT_SAMPLES / 2;
const _: () = assert!(N == 2 * H && N.is_power_of_two());

/// The running line fit.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LineFit {
    ring: [i32; N],
    /// Index of the oldest sample in `ring` once full; the next write goes there.
    head: usize,
    /// Samples in the window, up to [`N`]: one count for both windows (the half holds the
    /// newest `count.min(H)`), so a full window is one test (M4F: a load and a test fewer than a
    /// count per window).
    count: usize,
    /// The sums over the whole window.
    full: Sums<N>,
    /// The same two sums over the newest [`H`] samples.
    half: Sums<H>,
    last_t_us: u32,
    /// Where the line said the next sample would be, µm; NaN for nowhere (no line): every
    /// comparison with NaN is false, so no sample is off it (an Option cost the M4F a load
    /// and a test more per sample).
    expected_um: f32,
}

impl Default for LineFit {
    fn default() -> Self {
        Self {
            ring: [0; N],
            head: 0,
            count: 0,
            full: Sums::default(),
            half: Sums::default(),
            last_t_us: 0,
            expected_um: f32::NAN,
        }
    }
}

/// The line at the newest sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Line {
    /// Position at the newest sample, µm.
    pub end_um: f32,
    /// Slope, µm per sample period.
    pub slope_um: f32,
}

impl LineFit {
    /// Empties the window (a gap, a glitch, a region change, a fault).
    pub(crate) fn reset(&mut self) {
        self.head = 0;
        self.count = 0;
        self.full = Sums::default();
        self.half = Sums::default();
        self.expected_um = f32::NAN;
    }

    /// Adds a sample taken at `t_us`; returns the line once the window is full. A step of
    /// the clock other than one period (± half a period: a dropped sample or a stall) or a
    /// sample further than [`INNOVATION_GATE_UM`] from the line's prediction starts over.
    pub(crate) fn push(&mut self, position_um: i32, t_us: u32, period_us: u32) -> Option<Line> {
        let step_us = t_us.wrapping_sub(self.last_t_us);
        self.last_t_us = t_us;
        // Exactly one period on (the firmware stamps its samples so): one compare.
        let on_grid = step_us == period_us || step_us.abs_diff(period_us) <= period_us / 2;
        let off_line = (position_um as f32 - self.expected_um).abs() > INNOVATION_GATE_UM;
        if !on_grid || off_line {
            self.reset();
        }
        let count = self.count;
        if count == N {
            // Full (most samples): the oldest leaves the window, and the sample H newer than
            // it (age H − 1) the newer half. Masked: `head` is below N, and the mask says so to
            // the compiler, which drops the bounds tests (and with them the `get`s' None arms).
            let at = self.head & (N - 1);
            let oldest = self.ring.get(at).copied().unwrap_or(0);
            let half_oldest = self.ring.get((at + H) & (N - 1)).copied().unwrap_or(0);
            if let Some(slot) = self.ring.get_mut(at) {
                *slot = position_um;
            }
            self.head = (at + 1) & (N - 1);
            self.full.slide(position_um, oldest);
            self.half.slide(position_um, half_oldest);
        } else {
            // Filling: the new sample's index is `count`; the half slides once it holds H (its
            // oldest, age H − 1, at index count − H).
            if count >= H {
                let oldest = self.ring.get(count - H).copied().unwrap_or(0);
                self.half.slide(position_um, oldest);
            } else {
                self.half.fill(position_um, count);
            }
            if let Some(slot) = self.ring.get_mut(count) {
                *slot = position_um;
            }
            self.full.fill(position_um, count);
            self.count = count + 1;
            if count + 1 < N {
                return None;
            }
        }
        let line = self.chosen();
        self.expected_um = line.end_um + line.slope_um;
        Some(line)
    }

    /// The full window's line, or its newer half's where the two disagree (an acceleration).
    ///
    /// The half's line is made only near or past [`DISAGREE_UM`]: on a steady stroke (most
    /// samples) its end is read from one division of the half's exact end numerator
    /// ([`Sums::end_numerator`]) and the full line is kept when that is within
    /// [`AGREE_SURELY_UM`] of the full end (M4F: ~7 instructions a sample fewer than the half's
    /// line). The same line as the test on the half's own end: for positions within ±1 m
    /// (`position::MAX_LENGTH_UM`) that end, as `line_of` makes it, lies within 0.35 µm of the
    /// exact end (its slope term, up to 1.5·10^6 µm, rounded three times) and the quick one
    /// within 0.2 µm (two roundings of at most 1.7·10^6 µm), so a quick distance ≤ 8 µm is a
    /// distance to the half's own end under 8.6 µm, which the 9 µm test keeps too.
    #[inline(always)]
    fn chosen(&self) -> Line {
        let full = self.full.line();
        let half_end_um = self.half.end_numerator() as f32 / Sums::<H>::END_DENOMINATOR;
        if (full.end_um - half_end_um).abs() <= AGREE_SURELY_UM {
            return full;
        }
        let half = self.half.line();
        if (full.end_um - half.end_um).abs() <= DISAGREE_UM {
            full
        } else {
            half
        }
    }

    /// The line the last [`Self::push`] returned (None while the window fills), made again
    /// from the sums: O(1), for a velocity read at a stream's rate, not per sample.
    pub(crate) fn line(&self) -> Option<Line> {
        (self.count == N).then(|| self.chosen())
    }

    /// The newest `k` samples of the window (fewer if it holds fewer), oldest first, with the
    /// times they were taken at, µs: every sample in the window came one period after the one
    /// before (`push` starts over on any other step), the newest at the last push's time.
    pub(crate) fn history(
        &self,
        k: usize,
        period_us: u32,
    ) -> impl Iterator<Item = (i32, u32)> + '_ {
        let count = self.count;
        let k = k.min(count);
        // Oldest of the window at ring index `head` once full (0 while filling).
        let first = if count == N { self.head } else { 0 };
        let last_t_us = self.last_t_us;
        (count - k..count).map(move |age_from_oldest| {
            let at = (first + age_from_oldest) & (N - 1);
            let back = (count - 1 - age_from_oldest) as u32;
            (
                self.ring.get(at).copied().unwrap_or(0),
                last_t_us.wrapping_sub(back.wrapping_mul(period_us)),
            )
        })
    }

    /// The newer half's line (tests).
    #[cfg(test)]
    fn half_line(&self) -> Line {
        self.half.line()
    }
}

/// Σy and Σi·y over a sliding window of up to `W` samples, i = 0 for the oldest (wrapping:
/// Σi·y is at most 2 016 · 10^6 µm for W = 64 on a 1 m substrate, inside i32, and exactness
/// does not depend on it).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct Sums<const W: usize> {
    sum_um: i32,
    moment_um: i32,
}

impl<const W: usize> Sums<W> {
    /// Adds a sample to a window not yet full, at index `index` (the samples it holds).
    #[inline(always)]
    fn fill(&mut self, position_um: i32, index: usize) {
        self.moment_um = self
            .moment_um
            .wrapping_add((index as i32).wrapping_mul(position_um));
        self.sum_um = self.sum_um.wrapping_add(position_um);
    }

    /// Slides a full window by one: every index drops by one, `oldest` leaves, the new
    /// sample enters at W − 1.
    #[inline(always)]
    fn slide(&mut self, position_um: i32, oldest: i32) {
        self.moment_um = self
            .moment_um
            .wrapping_sub(self.sum_um.wrapping_sub(oldest))
            .wrapping_add((W as i32 - 1).wrapping_mul(position_um));
        self.sum_um = self.sum_um.wrapping_sub(oldest).wrapping_add(position_um);
    }

    /// The least-squares line through the window's samples, at the newest (full window).
    #[inline(always)]
    fn line(&self) -> Line {
        line_of(self.sum_um, self.moment_um, W)
    }

    /// W(W + 1)/2: the line's end is [`Self::end_numerator`] over it.
    const END_DENOMINATOR: f32 = (W * (W + 1) / 2) as f32;

    /// 3·Σi·y − (W − 2)·Σy, exact: the line's end times W(W + 1)/2 (the end is Σy/W plus
    /// (W − 1)/2 slopes, 12·Σi·y − 6(W − 1)·Σy over W(W² − 1) each). Wrapping like the sums,
    /// and exact where the result fits i32: |end| ≤ 5/3 of the largest |position| (the end's
    /// weights' absolute sum), 8.8·10^8 for W = 32 at 1 m.
    #[inline(always)]
    fn end_numerator(&self) -> i32 {
        self.moment_um
            .wrapping_mul(3)
            .wrapping_sub(self.sum_um.wrapping_mul(W as i32 - 2))
    }
}

/// The least-squares line through `n` samples from their Σy and Σi·y, at the newest.
///
/// 12·Σ(i − c)·y = 12·Σi·y − 6(n − 1)·Σy, wrapping: 12·Σi·y overflows i32 on a long substrate,
/// but the sums are kept mod 2^32 and the result (slope × n(n² − 1)) fits i32 for any slope
/// under 8 mm per sample (80 m/s) at n = 64, so the wrapped difference is exact.
#[inline(always)]
fn line_of(sum_um: i32, moment_um: i32, n: usize) -> Line {
    let num = moment_um
        .wrapping_mul(12)
        .wrapping_sub(sum_um.wrapping_mul(6 * (n as i32 - 1)));
    // Σ(i − (n−1)/2)², i = 0..n: n(n² − 1)/12, the slope's denominator, times 12.
    let slope_um = num as f32 / (n * (n * n - 1)) as f32;
    let end_um = sum_um as f32 / n as f32 + slope_um * ((n - 1) as f32 / 2.0);
    Line { end_um, slope_um }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fill(fit: &mut LineFit, f: impl Fn(i32) -> i32, from: i32, to: i32) -> Option<Line> {
        let mut line = None;
        for k in from..to {
            line = fit.push(f(k), k as u32 * 100, 100);
        }
        line
    }

    /// On a ramp the line is exact: its end is the newest sample and its slope the step.
    #[test]
    fn a_ramp_is_fitted_exactly() {
        let mut fit = LineFit::default();
        assert_eq!(fill(&mut fit, |k| 1_000 + 7 * k, 0, N as i32 - 1), None);
        let line = fill(&mut fit, |k| 1_000 + 7 * k, N as i32 - 1, N as i32).unwrap();
        assert_eq!(line.slope_um, 7.0);
        assert_eq!(line.end_um, (1_000 + 7 * (N as i32 - 1)) as f32);
        // Sliding keeps it exact (and the sums small-error free: integers).
        let line = fill(&mut fit, |k| 1_000 + 7 * k, N as i32, 500).unwrap();
        assert_eq!(line.slope_um, 7.0);
        assert_eq!(line.end_um, (1_000 + 7 * 499) as f32);
        // Going down.
        let mut fit = LineFit::default();
        let line = fill(&mut fit, |k| 900_000 - 20 * k, 0, 300).unwrap();
        assert_eq!(line.slope_um, -20.0);
        assert_eq!(line.end_um, (900_000 - 20 * 299) as f32);
    }

    /// The least-squares line through `xs` (f64, directly): (slope, value at the newest).
    fn direct_fit(xs: &[f64]) -> (f64, f64) {
        let n = xs.len() as f64;
        let c = (n - 1.0) / 2.0;
        let mean = xs.iter().sum::<f64>() / n;
        let slope = xs
            .iter()
            .enumerate()
            .map(|(i, v)| (i as f64 - c) * (v - mean))
            .sum::<f64>()
            / (n * (n * n - 1.0) / 12.0);
        (slope, mean + slope * c)
    }

    /// A symmetric ±d alternation about a level: slope 0, end at the level ± the fit's share
    /// of the last point's offset. Checks the moment update against a direct sum.
    #[test]
    fn the_running_sums_match_a_direct_fit() {
        let y = |k: i32| 5_000 + 3 * k + if k % 3 == 0 { 11 } else { -4 } + (k * k) % 7;
        let mut fit = LineFit::default();
        for k in 0..200 {
            let got = fit.push(y(k), k as u32 * 100, 100);
            if k < N as i32 - 1 {
                assert!(got.is_none());
                continue;
            }
            // Direct least squares over the last N samples, in f64.
            let mut xs = [0f64; N];
            for (i, v) in xs.iter_mut().enumerate() {
                *v = y(k + 1 - N as i32 + i as i32) as f64;
            }
            // Off the line by more than the gate? Then the fit restarted; this path stays on
            // (and the two ends agree, so the full window's line is the one returned).
            let got = got.expect("window full");
            let (slope, end) = direct_fit(&xs);
            assert!((got.slope_um as f64 - slope).abs() < 1e-4, "{k}");
            assert!((got.end_um as f64 - end).abs() < 2e-3, "{k}");
            // The newer half's sums against a direct fit over the newest H.
            let (slope, end) = direct_fit(&xs[N - H..]);
            let half = fit.half_line();
            assert!((half.slope_um as f64 - slope).abs() < 1e-4, "{k}");
            assert!((half.end_um as f64 - end).abs() < 2e-3, "{k}");
        }
    }

    /// Under acceleration the full window's end lags the path; when it leaves the newer half's
    /// end by more than [`DISAGREE_UM`], the half's line is the one returned (and predicts the
    /// next sample). Hand-worked: y = 20·k + a·k²/2 µm. The least-squares line through n
    /// samples of a parabola misses its newest by a·(n − 1)(n − 2)/12: at a = 0.01 µm per
    /// sample² (1 m/s² at 10 kHz) 3.26 µm for n = 64 and 0.78 for n = 32, within 9 µm of each
    /// other, so the full line is used; at a = 0.05 (5 m/s²) 16.3 against 3.9: the half's.
    #[test]
    fn an_acceleration_hands_the_line_to_the_newer_half() {
        for (a, uses_half) in [(0.01f64, false), (0.05, true)] {
            let y = |k: i32| (20.0 * k as f64 + a * (k as f64).powi(2) / 2.0).round() as i32;
            let mut fit = LineFit::default();
            let mut line = None;
            for k in 0..N as i32 + 20 {
                line = fit.push(y(k), k as u32 * 100, 100);
            }
            let line = line.expect("full");
            let k = N as i32 + 19;
            let truth = y(k) as f32;
            let half = fit.half_line();
            assert_eq!(line == half, uses_half, "a {a}: {line:?} {half:?}");
            let bias = |n: f64| a * (n - 1.0) * (n - 2.0) / 12.0;
            let used = if uses_half {
                bias(H as f64)
            } else {
                bias(N as f64)
            };
            assert!(
                ((truth - line.end_um) as f64 - used).abs() < 0.6,
                "a {a}: end {} truth {truth}",
                line.end_um
            );
        }
    }

    /// The quick agreement test keeps the line the test on the half's own end picks: swept
    /// through the acceleration where the two ends part by 9 µm (the bias difference is
    /// a·(63·62 − 31·30)/12 = 248·a, so a ≈ 0.036 µm per sample²), both ways, slow and fast,
    /// near 0 and near 1 m, every sample against the full and half lines chosen directly.
    #[test]
    fn the_quick_agreement_test_picks_the_line_the_ends_test_picks() {
        let (mut full_kept, mut half_taken, mut near_limit) = (0, 0, 0);
        for base in [1_000.0f64, 500_000.0, 930_000.0] {
            for speed in [-400.0f64, -20.0, 3.0, 20.0, 400.0] {
                for step in 0..120 {
                    let a = 0.028 + step as f64 * 0.0001;
                    let y = |k: i32| {
                        let k = k as f64;
                        let wobble = ((k * 7.0) % 5.0) - 2.0;
                        (base + speed * k + a * k * k / 2.0 + wobble).round() as i32
                    };
                    let mut fit = LineFit::default();
                    for k in 0..N as i32 + 40 {
                        let Some(got) = fit.push(y(k), k as u32 * 100, 100) else {
                            continue;
                        };
                        let (full, half) = (fit.full.line(), fit.half.line());
                        // The quick end is the half's own, to within the two roundings (the
                        // doc's bound is 0.55 µm; near 1 m one f32 ulp is 0.0625 µm).
                        let quick_um = fit.half.end_numerator() as f32 / Sums::<H>::END_DENOMINATOR;
                        assert!(
                            (quick_um - half.end_um).abs() <= 0.55,
                            "{quick_um} {half:?}"
                        );
                        let distance_um = (full.end_um - half.end_um).abs();
                        let want = if distance_um <= DISAGREE_UM {
                            full_kept += 1;
                            full
                        } else {
                            half_taken += 1;
                            half
                        };
                        if (distance_um - DISAGREE_UM).abs() < 1.0 {
                            near_limit += 1;
                        }
                        assert_eq!(got, want, "base {base} speed {speed} a {a} k {k}");
                    }
                }
            }
        }
        // The sweep crosses the limit: both lines are picked, many samples within 1 µm of it.
        assert!(
            full_kept > 1_000 && half_taken > 1_000,
            "{full_kept} {half_taken}"
        );
        assert!(near_limit > 100, "{near_limit}");
    }

    /// The history an estimator is seeded from: the newest k positions, oldest first, stamped
    /// one period apart back from the last push (the pushes' own stamps jitter within half a
    /// period), while filling and once the ring has wrapped; empty after a reset.
    #[test]
    fn the_history_is_the_newest_positions_oldest_first_one_period_apart() {
        let y = |k: u32| 3_000 + 7 * k as i32 + (k % 3) as i32;
        let mut fit = LineFit::default();
        // Stamps jittered by up to 30 µs: the window keeps them (on the grid).
        let t = |k: u32| 50_000 + k * 100 + (k % 4) * 10;
        for k in 0..10 {
            fit.push(y(k), t(k), 100);
        }
        let got: std::vec::Vec<_> = fit.history(4, 100).collect();
        let want: std::vec::Vec<_> = (6..10).map(|k| (y(k), t(9) - (9 - k) * 100)).collect();
        assert_eq!(got, want);
        assert_eq!(fit.history(100, 100).count(), 10);
        assert_eq!(fit.history(100, 100).next(), Some((y(0), t(9) - 900)));
        // Wrapped: 150 pushes in a 64-slot ring.
        for k in 10..150 {
            fit.push(y(k), t(k), 100);
        }
        let got: std::vec::Vec<_> = fit.history(34, 100).collect();
        let want: std::vec::Vec<_> = (116..150)
            .map(|k| (y(k), t(149) - (149 - k) * 100))
            .collect();
        assert_eq!(got, want);
        let all: std::vec::Vec<_> = fit.history(1_000, 100).map(|(p, _)| p).collect();
        assert_eq!(all, (86..150).map(y).collect::<std::vec::Vec<_>>());
        fit.reset();
        assert_eq!(fit.history(34, 100).count(), 0);
    }

    /// The line asked for again (a velocity read at a stream's rate) is the one the last push
    /// returned; none while the window fills.
    #[test]
    fn the_line_asked_again_is_the_last_pushed() {
        let mut fit = LineFit::default();
        let mut last = None;
        for k in 0..N as i32 + 20 {
            last = fit.push(1_000 + 12 * k + k % 5, k as u32 * 100, 100);
            assert_eq!(fit.line(), last, "{k}");
        }
        assert!(last.is_some());
        // An acceleration hands both to the newer half.
        for k in N as i32 + 20..N as i32 + 60 {
            let x = (20.0 * k as f64 + 0.05 * (k as f64).powi(2) / 2.0) as i32;
            last = fit.push(x, k as u32 * 100, 100);
            assert_eq!(fit.line(), last, "{k}");
        }
    }

    /// A dropped sample, a stall and a sample off the line each empty the window.
    #[test]
    fn gaps_and_jumps_start_over() {
        let ramp = |k: i32| 10_000 + 5 * k;
        let mut fit = LineFit::default();
        assert!(fill(&mut fit, ramp, 0, N as i32 + 8).is_some());
        // One period missing (200 µs step): no line until the window refills.
        let g = N as i32 + 9;
        assert_eq!(fit.push(ramp(g), g as u32 * 100, 100), None);
        for k in g + 1..g + N as i32 - 1 {
            assert_eq!(fit.push(ramp(k), k as u32 * 100, 100), None, "{k}");
        }
        let k = g + N as i32 - 1;
        assert!(fit.push(ramp(k), k as u32 * 100, 100).is_some());
        // Jitter within half a period keeps it.
        assert!(fit
            .push(ramp(k + 1), (k as u32 + 1) * 100 + 40, 100)
            .is_some());
        // A sample 80 µm off the line: over the 72 µm gate.
        let k = k + 2;
        assert_eq!(fit.push(ramp(k) + 80, k as u32 * 100, 100), None);
        // 70 µm off: kept.
        let mut fit = LineFit::default();
        fill(&mut fit, ramp, 0, N as i32 + 8);
        let k = N as i32 + 8;
        assert!(fit.push(ramp(k) + 70, k as u32 * 100, 100).is_some());
        // The clock wrapping through u32::MAX is one period like any other.
        let mut fit = LineFit::default();
        let t0 = u32::MAX - 1_000;
        let mut line = None;
        for k in 0..N as u32 + 8 {
            line = fit.push(ramp(k as i32), t0.wrapping_add(k * 100), 100);
        }
        assert_eq!(line.unwrap().slope_um, 5.0);
    }
}
