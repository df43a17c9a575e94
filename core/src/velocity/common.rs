//! Shared by the estimators of this directory: sample-slot bookkeeping, configuration checks and
//! the f32 → µm/s conversion.
//!
//! The ADC is timer-triggered, so samples are taken on a fixed grid even when their timestamps
//! are read late (interrupt latency) or a sample is lost (DMA overrun). The estimators therefore
//! count *slots*: the time since the previous sample's place on the sampling grid, rounded to
//! whole sample periods. The grid follows the timestamps through a first-order loop (each step
//! moves it by 1/16 of the timestamp's offset), so a clock running a little fast or slow is
//! tracked while the jitter of single timestamps is not: jitter below half a period around the
//! grid is rounded away. A dropped sample shows as a step of two slots and is bridged exactly
//! (the estimators use the true slot spacing); a silence longer than [`MAX_BRIDGED_SLOTS`]
//! restarts the estimator.

use super::EstimatorError;

/// Longest step between two samples that is bridged (1 = no sample lost, 4 = three lost).
pub const MAX_BRIDGED_SLOTS: u32 = 4;

/// Why an estimator with gains or thresholds could not be configured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TuningError {
    /// Window or sample period (shared with the baseline).
    Estimator(EstimatorError),
    /// A gain, pole or threshold outside its stable / meaningful range.
    BadGain,
}

impl From<EstimatorError> for TuningError {
    fn from(e: EstimatorError) -> Self {
        TuningError::Estimator(e)
    }
}

/// The sample periods every estimator accepts (as [`super::LsqSlope`] does).
pub(crate) fn check_period(sample_period_us: u32) -> Result<(), EstimatorError> {
    if (10..=100_000).contains(&sample_period_us) {
        Ok(())
    } else {
        Err(EstimatorError::BadSamplePeriod)
    }
}

/// What the time since the previous sample means.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tick {
    /// No previous sample: start.
    First,
    /// This many whole periods since the previous sample (1 normally, 2..=MAX with drops).
    Slots(u32),
    /// Less than half a period since the previous sample: a repeated reading, ignored.
    Duplicate,
    /// Longer than [`MAX_BRIDGED_SLOTS`] periods, or time ran backwards: restart.
    Gap,
}

/// Turns timestamps into slot steps (see the module doc).
#[derive(Clone, Copy, Debug)]
pub(crate) struct SlotClock {
    period_us: u32,
    /// Where the previous sample sits on the sampling grid, µs (wrapping).
    grid_us: Option<u32>,
    /// Sub-µs part of the grid, 1/256 µs.
    grid_frac: i32,
}

impl SlotClock {
    pub(crate) const fn new(period_us: u32) -> Self {
        Self {
            period_us,
            grid_us: None,
            grid_frac: 0,
        }
    }

    pub(crate) fn period_us(&self) -> u32 {
        self.period_us
    }

    pub(crate) fn tick(&mut self, t_us: u32) -> Tick {
        let Some(grid) = self.grid_us else {
            self.grid_us = Some(t_us);
            return Tick::First;
        };
        // Signed offset from the previous grid point; a timestamp that ran backwards by more
        // than half a period is a gap (restart), not a duplicate.
        let dt = t_us.wrapping_sub(grid) as i32 as i64;
        let p = self.period_us as i64;
        if dt < -p / 2 {
            self.grid_us = Some(t_us);
            return Tick::Gap;
        }
        let slots = (dt + p / 2).div_euclid(p);
        if slots <= 0 {
            return Tick::Duplicate;
        }
        if slots > MAX_BRIDGED_SLOTS as i64 {
            self.grid_us = Some(t_us);
            return Tick::Gap;
        }
        let on_grid = grid.wrapping_add((slots * p) as u32);
        // Move the grid by 1/16 of the offset, in 1/256 µs so small offsets still count.
        let offset = t_us.wrapping_sub(on_grid) as i32;
        self.grid_frac += offset.clamp(-1 << 20, 1 << 20) * 16;
        let whole = self.grid_frac >> 8;
        self.grid_frac -= whole << 8;
        self.grid_us = Some(on_grid.wrapping_add(whole as u32));
        Tick::Slots(slots as u32)
    }

    pub(crate) fn reset(&mut self) {
        self.grid_us = None;
        self.grid_frac = 0;
    }
}

/// µm/s from a float, rounded to nearest, saturating (NaN → 0, which cannot happen with finite
/// inputs but keeps the output bounded whatever arrives).
pub(crate) fn to_um_s(v: f32) -> i32 {
    libm::roundf(v) as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_round_jitter_and_count_drops() {
        let mut c = SlotClock::new(100);
        assert_eq!(c.tick(1_000), Tick::First);
        assert_eq!(c.tick(1_140), Tick::Slots(1)); // 40 µs late
        assert_eq!(c.tick(1_160), Tick::Slots(1)); // 40 µs early: only 20 µs after the last
        assert_eq!(c.tick(1_400), Tick::Slots(2)); // one sample lost
        assert_eq!(c.tick(1_420), Tick::Duplicate);
        assert_eq!(c.tick(1_900), Tick::Gap); // five slots: restart
        assert_eq!(c.tick(1_000), Tick::Gap); // ran backwards
    }

    #[test]
    fn grid_follows_a_slow_clock_and_ignores_jitter() {
        // Period really 100.01 µs (100 ppm slow) with ±30 µs jitter: never a wrong slot count
        // (the grid itself wanders by σ ≈ 3 µs, so the margin is not the full ±50 µs).
        let mut c = SlotClock::new(100);
        c.tick(0);
        let mut lcg = 12_345u32;
        for k in 1..20_000u32 {
            lcg = lcg.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let jitter = (lcg >> 16) % 61;
            let t = (k as f64 * 100.01) as u32 + jitter;
            assert_eq!(c.tick(t.wrapping_sub(30)), Tick::Slots(1), "sample {k}");
        }
    }

    #[test]
    fn rounding_saturates() {
        assert_eq!(to_um_s(2.5), 3);
        assert_eq!(to_um_s(-2.5), -3);
        assert_eq!(to_um_s(1e12), i32::MAX);
        assert_eq!(to_um_s(f32::NAN), 0);
    }
}
