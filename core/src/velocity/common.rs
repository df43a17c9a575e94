//! Shared by the estimators of this directory: sample-slot bookkeeping, configuration checks and
//! the f32 → µm/s conversion.
//!
//! The ADC is timer-triggered, so samples are taken on a fixed grid even when their timestamps
//! are read late (interrupt latency) or a sample is lost (DMA overrun). The estimators therefore
//! count *slots*: the time since the previous sample, rounded to whole sample periods. Timestamp
//! jitter smaller than half a period between consecutive samples is rounded away; a dropped
//! sample shows as a step of two slots and is bridged exactly (the estimators use the true slot
//! spacing); a silence longer than [`MAX_BRIDGED_SLOTS`] restarts the estimator.

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
    last_t_us: Option<u32>,
}

impl SlotClock {
    pub(crate) const fn new(period_us: u32) -> Self {
        Self {
            period_us,
            last_t_us: None,
        }
    }

    pub(crate) fn period_us(&self) -> u32 {
        self.period_us
    }

    pub(crate) fn tick(&mut self, t_us: u32) -> Tick {
        let Some(last) = self.last_t_us else {
            self.last_t_us = Some(t_us);
            return Tick::First;
        };
        // Wrapping difference: a timestamp that ran backwards becomes a huge step, i.e. a gap.
        let dt = t_us.wrapping_sub(last);
        let slots = (dt as u64 + self.period_us as u64 / 2) / self.period_us as u64;
        if slots == 0 {
            return Tick::Duplicate;
        }
        self.last_t_us = Some(t_us);
        if slots > MAX_BRIDGED_SLOTS as u64 {
            Tick::Gap
        } else {
            Tick::Slots(slots as u32)
        }
    }

    pub(crate) fn reset(&mut self) {
        self.last_t_us = None;
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
        assert_eq!(c.tick(1_210), Tick::Slots(1)); // back on time after the late one
        assert_eq!(c.tick(1_410), Tick::Slots(2)); // one sample lost
        assert_eq!(c.tick(1_420), Tick::Duplicate);
        assert_eq!(c.tick(1_910), Tick::Gap); // five slots: restart
        assert_eq!(c.tick(1_000), Tick::Gap); // ran backwards
    }

    #[test]
    fn rounding_saturates() {
        assert_eq!(to_um_s(2.5), 3);
        assert_eq!(to_um_s(-2.5), -3);
        assert_eq!(to_um_s(1e12), i32::MAX);
        assert_eq!(to_um_s(f32::NAN), 0);
    }
}
