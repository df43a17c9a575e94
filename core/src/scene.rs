//! Scene: the layout of regions and their textures, plus the default scene of fig. 11.

use heapless::Vec;

use crate::burst::SafetyLimits;
use crate::controller::ConfigError;
use crate::gate::DriveMode;
use crate::position::{Calibration, DEFAULT_LENGTH_UM};
use crate::region::{DEFAULT_HYSTERESIS_UM, MAX_REGIONS};
use crate::texture::{Lines, Texture};

/// Regions and textures, left to right.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Scene {
    /// Boundaries between regions, µm from the start end, strictly increasing.
    pub boundaries_um: Vec<u32, { MAX_REGIONS - 1 }>,
    /// One texture per region (one more than boundaries).
    pub textures: Vec<Texture, MAX_REGIONS>,
    /// Half-width of the boundary hysteresis band, µm.
    pub hysteresis_um: u32,
    /// Tangible lines drawn over the regions (fig. 12); none by default.
    pub lines: Lines,
    /// Standing (both IDTs) or progressive (one IDT) waves.
    pub drive: DriveMode,
}

/// Everything the controller needs besides the board.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Config {
    /// Rheostat calibration.
    pub calibration: Calibration,
    /// The scene to render.
    pub scene: Scene,
    /// Carrier caps.
    pub limits: SafetyLimits,
    /// With no sample for this long the sensor counts as stale and the carrier stops, µs.
    pub stale_after_us: u32,
}

impl Config {
    /// This configuration with boundary `index` (where region `index` ends) moved to `at_um`:
    /// a live edit (fig. 11's sliders). Only the index is checked here; the layout is checked
    /// when the result is loaded, like any configuration.
    pub fn with_boundary(&self, index: u8, at_um: u32) -> Result<Config, ConfigError> {
        let mut next = self.clone();
        let boundaries = next.scene.boundaries_um.len();
        match next.scene.boundaries_um.get_mut(index as usize) {
            Some(b) => *b = at_um,
            None => {
                return Err(ConfigError::NoSuchBoundary {
                    index,
                    boundaries: boundaries as u8,
                })
            }
        }
        Ok(next)
    }

    /// This configuration with region `index`'s texture replaced (checked when loaded).
    pub fn with_texture(&self, index: u8, texture: Texture) -> Result<Config, ConfigError> {
        let mut next = self.clone();
        let regions = next.scene.textures.len();
        match next.scene.textures.get_mut(index as usize) {
            Some(t) => *t = texture,
            None => {
                return Err(ConfigError::NoSuchRegion {
                    index,
                    regions: regions as u8,
                })
            }
        }
        Ok(next)
    }

    /// This configuration with another drive mode.
    pub fn with_drive(&self, drive: DriveMode) -> Config {
        let mut next = self.clone();
        next.scene.drive = drive;
        next
    }
}

/// Fig. 11's screen ran 0–5000 across the substrate with boundaries at 1505 and 3495.
const FIG11_SCALE: u32 = 5_000;

/// The default scene: three regions like fig. 11 of the SAW display paper — bumpy 20 Hz,
/// rough 80 Hz, smooth 1 kHz — split where the figure draws its boundaries.
pub fn default_scene() -> Scene {
    let mut boundaries_um = Vec::new();
    let mut textures = Vec::new();
    for b in [1_505, 3_495] {
        let _ = boundaries_um.push(DEFAULT_LENGTH_UM * b / FIG11_SCALE);
    }
    for hz in [20, 80, 1_000] {
        let _ = textures.push(Texture::constant_hz(hz));
    }
    Scene {
        boundaries_um,
        textures,
        hysteresis_um: DEFAULT_HYSTERESIS_UM,
        lines: Lines::default(),
        drive: DriveMode::Standing,
    }
}

/// The configuration with the longest encoding: 8 regions of the widest texture (random, every
/// field at its maximum) and every line. Not a valid scene: buffers that carry a `Config` (the
/// link's frames, the flash store's item) are sized and tested against it.
pub fn largest_config() -> Config {
    let mut c = default_config();
    c.scene.textures.clear();
    c.scene.boundaries_um.clear();
    let widest = Texture::Random(crate::texture::RandomBurst {
        center_millihz: u32::MAX,
        spread_permille: u16::MAX,
        amplitude_permille: u16::MAX,
        amplitude_spread_permille: u16::MAX,
        duty_permille: u16::MAX,
        seed: u64::MAX,
    });
    // Each list filled to its capacity with the longest value postcard encodes.
    while c.scene.textures.push(widest).is_ok() {}
    while c.scene.boundaries_um.push(u32::MAX).is_ok() {}
    while c.scene.lines.positions_um.push(u32::MAX).is_ok() {}
    c
}

/// Default calibration, default caps, the default scene, stale after 5 ms (50 samples at 10 kHz).
pub fn default_config() -> Config {
    Config {
        calibration: Calibration::default(),
        scene: default_scene(),
        limits: SafetyLimits::default(),
        stale_after_us: 5_000,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn live_edits_change_one_thing_and_refuse_a_missing_index() {
        let base = default_config();
        // The default scene: boundaries at 18.963 and 44.037 mm, 20 / 80 / 1000 Hz.
        let moved = base.with_boundary(1, 50_000).unwrap();
        assert_eq!(moved.scene.boundaries_um.as_slice(), &[18_963, 50_000]);
        assert_eq!(moved.scene.textures, base.scene.textures);
        assert_eq!(
            base.with_boundary(2, 50_000),
            Err(ConfigError::NoSuchBoundary {
                index: 2,
                boundaries: 2
            })
        );
        let retextured = base.with_texture(2, Texture::Off).unwrap();
        assert_eq!(retextured.scene.textures[2], Texture::Off);
        assert_eq!(retextured.scene.textures[..2], base.scene.textures[..2]);
        assert_eq!(retextured.scene.boundaries_um, base.scene.boundaries_um);
        assert_eq!(
            base.with_texture(3, Texture::Off),
            Err(ConfigError::NoSuchRegion {
                index: 3,
                regions: 3
            })
        );
        let progressive = base.with_drive(DriveMode::Progressive);
        assert_eq!(progressive.scene.drive, DriveMode::Progressive);
        assert_eq!(progressive.scene.textures, base.scene.textures);
    }
}
