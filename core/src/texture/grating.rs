//! Grating texture: a virtual grating of spatial period λ rendered by velocity synthesis,
//! f = |V|/λ (Konyo et al., eq. 1), so the felt spatial period does not depend on hand speed.
//!
//! Below `min_speed_um_s` no bursts are made: at rest the velocity estimate is noise, and
//! |noise|/λ would buzz the finger with spurious bursts. The threshold has hysteresis (off below
//! half of it) so a slow stroke near the threshold does not flicker.

use super::TextureError;

/// A grating region's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Grating {
    /// Spatial period λ, µm (grooved tile: ridge width + groove width).
    pub wavelength_um: u32,
    /// Duty of each burst, ‰.
    pub duty_permille: u16,
    /// Bursts start above this speed, µm/s, and stop below half of it.
    pub min_speed_um_s: u32,
    /// Drive amplitude, ‰ (tile-to-scene sets it from the skin model's A).
    pub amplitude_permille: u16,
}

impl Grating {
    /// A grating of period `wavelength_um` with 40 % duty, a 15 mm/s start threshold (below it, noise at rest would fire bursts: docs/estimators.md), full drive.
    pub const fn new(wavelength_um: u32) -> Self {
        Self {
            wavelength_um,
            duty_permille: 400,
            min_speed_um_s: 15_000,
            amplitude_permille: 1000,
        }
    }

    /// Checks the parameters against a substrate of `length_um`.
    pub fn validate(&self, length_um: u32) -> Result<(), TextureError> {
        if self.wavelength_um == 0 || self.wavelength_um > length_um {
            return Err(TextureError::BadWavelength);
        }
        if self.min_speed_um_s > 1_000_000 {
            return Err(TextureError::BadSpeedThreshold);
        }
        if self.amplitude_permille == 0 || self.amplitude_permille > 1000 {
            return Err(TextureError::BadSpread);
        }
        Ok(())
    }

    /// f_b in Hz at speed `speed_um_s` (≥ 0), before the threshold.
    pub fn burst_hz(&self, speed_um_s: f32) -> f32 {
        speed_um_s / self.wavelength_um as f32
    }
}
