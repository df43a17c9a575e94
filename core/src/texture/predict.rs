//! Crossing prediction for the hybrid grating renderer: a least-squares line through the last
//! [`FIT_SAMPLES`] positions, kept in O(1) per sample, that says where the finger is now
//! (lag-free on a steady stroke) and when inside the coming sample period it reaches a ridge.
//!
//! Why a line and not the velocity estimator: the estimator's slope is centred half its window
//! back (1.65 ms at 10 kHz) and says nothing about *where* the finger is; the line's end point
//! is the finger's position at the newest sample with the noise of a 32-sample average
//! (σ·√((4N − 2)/(N(N + 1))) = 0.35 σ), which is what places a burst inside the period.
//!
//! The line is trusted only on a steady stroke: a full window of consecutive samples (a gap, a
//! dropped sample or a rejected glitch empties it), a speed above the trust speed, and every
//! new sample within [`INNOVATION_GATE_UM`] of where the line said it would be (a reversal or a
//! hard acceleration bends the path away from the line and empties it too). Otherwise the
//! renderer falls back to position phase.

/// Samples in the fit: 3.2 ms at 10 kHz. 16 gave 4–5 µm RMS on the host model but a worst
/// error above 10 µm at 2 LSB; 32 halves the end point's noise variance.
pub const FIT_SAMPLES: usize = 32;

/// Trust speed, µm/s: below it the line's slope is too close to its noise (0.23 µm per sample
/// RMS at 3 LSB, 10 kHz) to say which way the finger goes, and position phase places bursts
/// within the noise anyway (one sample of travel is 1 µm).
pub const TRUST_SPEED_UM_S: u32 = 10_000;

/// Largest distance, µm, between a new sample and the line's prediction for it before the line
/// is dropped. 6 σ of the innovation at 3 LSB (12 µm per sample); a 100 mm/s reversal leaves
/// the line by 2 × 10 µm per sample, so it is caught within four samples, before the line's
/// slope has turned.
pub const INNOVATION_GATE_UM: f32 = 72.0;

const N: usize = FIT_SAMPLES;
/// Σ(i − (N−1)/2)², i = 0..N: N(N² − 1)/12, the slope's denominator, times 12.
const SLOPE_DEN: f32 = (N * (N * N - 1)) as f32;

/// The running line fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct LineFit {
    ring: [i32; N],
    /// Index of the oldest sample in `ring` once full; the next write goes there.
    head: usize,
    count: usize,
    /// Σ y over the window.
    sum_um: i32,
    /// Σ i·y, i = 0 for the oldest: at most 496 · 10^6 µm for a 1 m substrate, inside i32.
    moment_um: i32,
    last_t_us: u32,
    /// Where the line said the next sample would be, µm.
    expected_um: Option<f32>,
}

impl Default for LineFit {
    fn default() -> Self {
        Self {
            ring: [0; N],
            head: 0,
            count: 0,
            sum_um: 0,
            moment_um: 0,
            last_t_us: 0,
            expected_um: None,
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
        self.count = 0;
        self.head = 0;
        self.sum_um = 0;
        self.moment_um = 0;
        self.expected_um = None;
    }

    /// Adds a sample taken at `t_us`; returns the line once the window is full. A step of
    /// the clock other than one period (± half a period: a dropped sample or a stall) or a
    /// sample further than [`INNOVATION_GATE_UM`] from the line's prediction starts over.
    pub(crate) fn push(&mut self, position_um: i32, t_us: u32, period_us: u32) -> Option<Line> {
        let step_us = t_us.wrapping_sub(self.last_t_us);
        self.last_t_us = t_us;
        let on_grid = step_us.abs_diff(period_us) <= period_us / 2;
        let off_line = self
            .expected_um
            .is_some_and(|e| (position_um as f32 - e).abs() > INNOVATION_GATE_UM);
        if !on_grid || off_line {
            self.reset();
        }
        if self.count < N {
            // Filling: the new sample's index is `count`.
            if let Some(slot) = self.ring.get_mut(self.count) {
                *slot = position_um;
            }
            self.sum_um = self.sum_um.wrapping_add(position_um);
            self.moment_um = self
                .moment_um
                .wrapping_add((self.count as i32).wrapping_mul(position_um));
            self.count += 1;
            if self.count < N {
                return None;
            }
        } else {
            // Sliding: every index drops by one, the oldest leaves, the newest enters at N − 1.
            let oldest = self.ring.get(self.head).copied().unwrap_or(0);
            if let Some(slot) = self.ring.get_mut(self.head) {
                *slot = position_um;
            }
            self.head = if self.head + 1 == N { 0 } else { self.head + 1 };
            self.moment_um = self
                .moment_um
                .wrapping_sub(self.sum_um.wrapping_sub(oldest))
                .wrapping_add((N as i32 - 1).wrapping_mul(position_um));
            self.sum_um = self.sum_um.wrapping_sub(oldest).wrapping_add(position_um);
        }
        // 12·Σ(i − c)·y = 12·Σi·y − 6(N − 1)·Σy, wrapping: 12·Σi·y overflows i32 on a long
        // substrate, but the sums are kept mod 2^32 and the result (slope × N(N² − 1)) fits
        // i32 for any slope under 65 mm per sample, so the wrapped difference is exact.
        let num = self
            .moment_um
            .wrapping_mul(12)
            .wrapping_sub(self.sum_um.wrapping_mul(6 * (N as i32 - 1)));
        let slope_um = num as f32 / SLOPE_DEN;
        let end_um = self.sum_um as f32 / N as f32 + slope_um * ((N - 1) as f32 / 2.0);
        self.expected_um = Some(end_um + slope_um);
        Some(Line { end_um, slope_um })
    }
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
        assert_eq!(line.end_um, (1_000 + 7 * 31) as f32);
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
            let c = (N as f64 - 1.0) / 2.0;
            let mean = xs.iter().sum::<f64>() / N as f64;
            let slope = xs
                .iter()
                .enumerate()
                .map(|(i, v)| (i as f64 - c) * (v - mean))
                .sum::<f64>()
                / (N as f64 * (N as f64 * N as f64 - 1.0) / 12.0);
            let end = mean + slope * c;
            // Off the line by more than the gate? Then the fit restarted; this path stays on.
            let got = got.expect("window full");
            assert!((got.slope_um as f64 - slope).abs() < 1e-4, "{k}");
            assert!((got.end_um as f64 - end).abs() < 2e-3, "{k}");
        }
    }

    /// A dropped sample, a stall and a sample off the line each empty the window.
    #[test]
    fn gaps_and_jumps_start_over() {
        let ramp = |k: i32| 10_000 + 5 * k;
        let mut fit = LineFit::default();
        fill(&mut fit, ramp, 0, 40);
        // One period missing (200 µs step): no line until the window refills.
        assert_eq!(fit.push(ramp(41), 4_100, 100), None);
        for k in 42..41 + N as i32 - 1 {
            assert_eq!(fit.push(ramp(k), k as u32 * 100, 100), None, "{k}");
        }
        let k = 41 + N as i32 - 1;
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
        fill(&mut fit, ramp, 0, 40);
        assert!(fit.push(ramp(40) + 70, 4_000, 100).is_some());
        // The clock wrapping through u32::MAX is one period like any other.
        let mut fit = LineFit::default();
        let t0 = u32::MAX - 1_000;
        let mut line = None;
        for k in 0..40u32 {
            line = fit.push(ramp(k as i32), t0.wrapping_add(k * 100), 100);
        }
        assert_eq!(line.unwrap().slope_um, 5.0);
    }
}
