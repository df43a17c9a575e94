//! Innovation gate: an outlier guard that wraps any estimator and holds a sample that lands
//! further than a gate from where the current slope says it should be.
//!
//! Each sample is compared with the prediction `x_ref + v·T_s`: the position last handed to
//! the inner estimator plus one period at the inner estimator's last answer. Inside
//! `gate_um` of it the sample passes unchanged; outside, the prediction is handed on instead
//! (the sample is held), at most `max_held` times in a row: the next sample that is still
//! outside is taken as a real jump, and the inner estimator starts over on it (None until its
//! window refills, as after a silence). A clean stroke never reaches the gate, so the
//! inner estimator sees exactly the samples it would see alone: no added lag, bit-exact
//! output (issue #35; `docs/conversion-budget.md`, "Outlier guards").
//!
//! A sample outside the gate that is inside it from the position handed on before (two steps
//! back) is passed too: the previous sample was an outlier just inside the gate, and holding
//! its good neighbour against it would stretch it.
//!
//! Cost per sample: one 32×32→64 multiply (the predicted step), two subtract-and-absolute
//! compares and a counter; no division. Not removed: an outlier smaller than the gate (it
//! reaches the slope at its full size), and more than `max_held` outliers in a row.
//! After a silence (the slot clock's gap rule) or a reset the first sample is taken as it
//! comes.

use super::{VelocityEstimator, MAX_BRIDGED_SLOTS};

/// Innovation gate around `E`.
#[derive(Clone, Debug)]
pub struct InnovationGate<E> {
    inner: E,
    /// Largest distance from the prediction a sample may have and pass, µm.
    gate_um: u32,
    /// Samples held in a row before one outside the gate is taken as a real jump.
    max_held: u8,
    /// Samples held in a row so far.
    held: u8,
    /// The position last handed to the inner estimator, µm.
    x_ref: i32,
    /// The one handed on before it, µm.
    x_prev: i32,
    /// Its timestamp, µs.
    t_ref: u32,
    /// The inner estimator's last answer, µm/s (0 while it has none).
    v_um_s: i32,
    /// The sample period in seconds, Q32 (T_s·2³²/10⁶): a step of speed v µm/s over one
    /// period is (v·this + 2³¹) >> 32 µm, rounded.
    period_q32: i32,
    /// False after a reset or a gap: the next sample is taken as it comes.
    primed: bool,
    /// ⌊period/2⌋ and (MAX_BRIDGED_SLOTS + 1) periods, as the median's gap test.
    half_us: u32,
    gap_us: u32,
}

impl<E: VelocityEstimator> InnovationGate<E> {
    /// Wraps `inner`, whose samples come every `sample_period_us`; a sample further than
    /// `gate_um` from the prediction is held, at most `max_held` times in a row.
    pub fn new(inner: E, sample_period_us: u32, gate_um: u32, max_held: u8) -> Self {
        Self {
            inner,
            gate_um,
            max_held,
            held: 0,
            x_ref: 0,
            x_prev: 0,
            t_ref: 0,
            v_um_s: 0,
            // ≤ 2³¹ − 1 up to a 0.5 s period (the estimators take ≤ 100 ms): one 32×32→64
            // multiply per sample.
            period_q32: (((sample_period_us as i64) << 32) / 1_000_000).min(i32::MAX as i64) as i32,
            primed: false,
            half_us: sample_period_us / 2,
            gap_us: sample_period_us.saturating_mul(MAX_BRIDGED_SLOTS + 1),
        }
    }

    /// The wrapped estimator.
    pub fn inner(&self) -> &E {
        &self.inner
    }

    /// The position to hand on for a sample at `position_um`, `t_us`, given the inner
    /// estimator's current answer `v_um_s`.
    #[inline(always)]
    fn gate(&mut self, position_um: i32, t_us: u32, v_um_s: i32) -> i32 {
        // A gap (or time run backwards): start over on this sample.
        if t_us.wrapping_sub(self.t_ref).wrapping_add(self.half_us) >= self.gap_us {
            self.primed = false;
        }
        self.t_ref = t_us;
        let out = if !self.primed {
            self.primed = true;
            self.held = 0;
            self.x_ref = position_um;
            position_um
        } else {
            let step = ((v_um_s as i64 * self.period_q32 as i64 + (1 << 31)) >> 32) as i32;
            let predicted = self.x_ref.wrapping_add(step);
            let off = position_um.wrapping_sub(predicted).unsigned_abs();
            // An outlier just inside the gate has passed and become the reference: the good
            // sample after it is judged against the line before it too, so that it is not held
            // against the outlier (which would stretch the outlier over more samples).
            let off_prev = position_um
                .wrapping_sub(self.x_prev.wrapping_add(step.wrapping_mul(2)))
                .unsigned_abs();
            if off <= self.gate_um || (self.held == 0 && off_prev <= self.gate_um) {
                self.held = 0;
                position_um
            } else if self.held >= self.max_held {
                // A real jump: the slope's window still holds the old place, and its slope
                // across the jump would throw the next predictions off (and hold good
                // samples). Start the inner estimator over on it, as after a silence.
                self.held = 0;
                self.inner.reset();
                position_um
            } else {
                self.held += 1;
                predicted
            }
        };
        self.x_prev = self.x_ref;
        self.x_ref = out;
        out
    }
}

impl<E: VelocityEstimator> VelocityEstimator for InnovationGate<E> {
    #[inline(always)]
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        let x = self.gate(position_um, t_us, self.v_um_s);
        let v = self.inner.update(x, t_us);
        self.v_um_s = v.unwrap_or(0);
        v
    }

    fn reset(&mut self) {
        self.primed = false;
        self.v_um_s = 0;
        self.inner.reset();
    }

    fn group_delay_us(&self) -> u32 {
        self.inner.group_delay_us()
    }

    /// A rest gates as an update does (the prediction reads the inner estimator's estimate,
    /// which a resting estimator keeps in O(1)) and rests the inner estimator.
    #[inline(always)]
    fn rests(&self) -> bool {
        self.inner.rests()
    }

    #[inline(always)]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        let v = self.inner.estimate().unwrap_or(0);
        let x = self.gate(position_um, t_us, v);
        self.inner.rest(x, t_us);
    }

    fn wake(&mut self) {
        self.inner.wake();
        self.v_um_s = self.inner.estimate().unwrap_or(0);
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

    fn gate16() -> InnovationGate<LsqSlope<16>> {
        InnovationGate::new(LsqSlope::<16>::new(T).unwrap(), T, 100, 2)
    }

    #[test]
    fn a_clean_ramp_gives_the_bare_slope_bit_exact() {
        assert_a_clean_ramp_is_untouched(gate16(), LsqSlope::<16>::new(T).unwrap(), T);
    }

    #[test]
    fn a_single_sample_spike_moves_the_slope_by_little() {
        let (mut g, mut bare) = (gate16(), LsqSlope::<16>::new(T).unwrap());
        let mut worst = 0i64;
        let mut worst_bare = 0i64;
        for i in 0..200u32 {
            let x = ramp(i) + if i == 100 { 2_000 } else { 0 };
            let (a, b) = (g.update(x, i * T), bare.update(x, i * T));
            if i >= 20 {
                worst = worst.max((a.unwrap() as i64 - 20_000).abs());
                worst_bare = worst_bare.max((b.unwrap() as i64 - 20_000).abs());
            }
        }
        // The dither alone moves a 16-sample slope by a few mm/s; the spike adds at most the
        // prediction's error (a step of the lagging slope, ≤ 1 µm here).
        assert!(worst <= 3_000, "gated {worst} µm/s");
        // Without the gate the spike shows at the slope's largest weight (≈ 440 mm/s).
        assert!(worst_bare >= 400_000, "bare {worst_bare} µm/s");
    }

    /// A spike just inside the gate passes, as it would without the gate, and the good sample
    /// after it (outside the gate from the spike) is not held against it: the output is the
    /// bare slope's at every sample.
    #[test]
    fn a_spike_inside_the_gate_is_not_stretched() {
        let (mut g, mut bare) = (gate16(), LsqSlope::<16>::new(T).unwrap());
        for i in 0..200u32 {
            let x = 10_000 + 2 * i as i32 + if i == 100 { 99 } else { 0 };
            assert_eq!(g.update(x, i * T), bare.update(x, i * T), "sample {i}");
        }
    }

    #[test]
    fn a_real_jump_is_followed_after_max_held_samples() {
        let mut g = gate16();
        let mut seen = std::vec::Vec::new();
        for i in 0..60u32 {
            let x = if i < 40 { 10_000 } else { 15_000 };
            g.update(x, i * T);
            seen.push(g.x_ref);
        }
        // Samples 40 and 41 are held at the old position, 42 is taken: max_held = 2.
        assert_eq!(
            &seen[38..44],
            &[10_000, 10_000, 10_000, 10_000, 15_000, 15_000]
        );
        // And from then on the jump is the position: the slope restarted on it, and reads 0
        // once its window has refilled.
        assert!(seen[44..].iter().all(|&x| x == 15_000));
        assert_eq!(g.update(15_000, 60 * T), Some(0));
    }

    #[test]
    fn a_gap_restarts_the_gate() {
        let mut g = gate16();
        for i in 0..30u32 {
            g.update(10_000, i * T);
        }
        // Ten periods of silence, then somewhere else: taken at once.
        g.update(30_000, 40 * T);
        assert_eq!(g.x_ref, 30_000);
        g.reset();
        g.update(50_000, 50 * T);
        assert_eq!(g.x_ref, 50_000);
    }
}
