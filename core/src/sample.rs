//! Sample stage: what the ADC hands the core — an oversampled rheostat reading with its timestamp.
//!
//! The ADC converts far faster than the 10 kHz control rate, so each control sample is the sum of
//! [`OVERSAMPLE`] 12-bit conversions (F446: DMA burst summed in software; G474: the hardware
//! oversampler converts 32 and halves the sum with rounding, the same scale with a further √2
//! less noise). Summing 16 conversions gives a 16-bit code and cuts white ADC noise by √16 = 4:
//! the cheapest lever on position noise, hence on velocity error.

/// 12-bit conversions summed into one control sample.
pub const OVERSAMPLE: u32 = 16;
/// Full scale of one conversion (12-bit ADC).
pub const CONVERSION_FULL_SCALE: u32 = 4096;
/// Full scale of a control sample's code: `OVERSAMPLE × CONVERSION_FULL_SCALE` = 65 536.
pub const CODE_FULL_SCALE: u32 = OVERSAMPLE * CONVERSION_FULL_SCALE;

/// One control sample: the rheostat wiper as a 16-bit code (sum of [`OVERSAMPLE`] 12-bit
/// conversions) and the time it was taken, in µs of a free-running clock that wraps (all time
/// differences use wrapping arithmetic, so the 71-minute wrap of `u32` µs is harmless).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sample {
    /// Sum of `OVERSAMPLE` 12-bit conversions, 0 ..= 65 520.
    pub code: u16,
    /// Capture time, µs.
    pub t_us: u32,
}

impl Sample {
    /// Builds a sample from summed conversions, saturating a sum that does not fit 16 bits
    /// (it can only come from a miscounted burst; saturating lands it on the high rail,
    /// which the position stage treats as a fault — the safe side).
    pub fn from_sum(sum: u32, t_us: u32) -> Self {
        let code = if sum > u16::MAX as u32 {
            u16::MAX
        } else {
            sum as u16
        };
        Self { code, t_us }
    }
}

/// Port: where samples come from (the ADC + DMA on a board, a rheostat model on the host).
pub trait PositionSource {
    /// The next sample, or `None` when none is ready yet.
    fn next_sample(&mut self) -> Option<Sample>;
}
