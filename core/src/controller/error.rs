//! Why a scene was refused: [`ConfigError`], and the sentence a person reads (`Display`, on
//! hosts; the firmware logs the defmt form).

use crate::burst::BurstError;
use crate::position::CalibrationError;
use crate::region::RegionError;
use crate::texture::TextureError;
use crate::velocity::EstimatorError;

/// Why a configuration was rejected (the previous one stays active).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum ConfigError {
    /// The rheostat calibration.
    Calibration(CalibrationError),
    /// The region layout.
    Region(RegionError),
    /// The carrier caps.
    Limits(BurstError),
    /// Region `region`'s burst cannot be rendered on this board.
    Texture {
        /// Index of the region.
        region: u8,
        /// What is wrong with its burst.
        error: BurstError,
    },
    /// Region `region`'s texture parameters are invalid.
    TextureParams {
        /// Index of the region.
        region: u8,
        /// What is wrong.
        error: TextureError,
    },
    /// The lines are invalid.
    Lines(TextureError),
    /// The line pulse cannot be rendered on this board.
    LinePulse(BurstError),
    /// Textures must number one more than boundaries.
    TextureCount {
        /// Textures given.
        textures: usize,
        /// Boundaries given.
        boundaries: usize,
    },
    /// Stale limit shorter than two sample periods or above one second.
    StaleLimit {
        /// The limit asked for, µs.
        stale_after_us: u32,
        /// Two sample periods, µs.
        min_us: u32,
    },
    /// The velocity estimator rejected the sample period.
    Estimator(EstimatorError),
    /// A live edit named a region the scene does not have.
    NoSuchRegion {
        /// The region asked for.
        index: u8,
        /// Regions in the scene.
        regions: u8,
    },
    /// A live edit named a boundary the scene does not have.
    NoSuchBoundary {
        /// The boundary asked for.
        index: u8,
        /// Boundaries in the scene.
        boundaries: u8,
    },
}

/// Longest stale limit, µs.
pub(super) const MAX_STALE_US: u32 = 1_000_000;

/// One sentence per refusal, for hosts (the scene-file reader, host-sim). The firmware logs the
/// defmt form instead, so this is never linked on target.
impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::{Deci, Milli};
        match *self {
            ConfigError::Calibration(e) => e.fmt(f),
            ConfigError::Region(e) => e.fmt(f),
            // The caps' own checks reuse the burst errors; named here as the caps they are.
            ConfigError::Limits(BurstError::BadDuty { duty_permille }) => write!(
                f,
                "duty cap {} % must be above 0 % and at most 100 %",
                Deci(duty_permille as u64)
            ),
            ConfigError::Limits(e) => e.fmt(f),
            ConfigError::Texture { region, error } => write!(f, "region {region}: {error}"),
            ConfigError::TextureParams { region, error } => write!(f, "region {region}: {error}"),
            ConfigError::Lines(e) => e.fmt(f),
            ConfigError::LinePulse(e) => write!(f, "line pulse: {e}"),
            ConfigError::TextureCount {
                textures,
                boundaries,
            } => write!(
                f,
                "{textures} textures for {boundaries} boundaries, and a scene needs one texture \
                 more than boundaries"
            ),
            ConfigError::StaleLimit {
                stale_after_us,
                min_us,
            } => write!(
                f,
                "stale limit {} ms must be at least two sample periods ({} ms) and at most {} ms",
                Milli(stale_after_us as u64),
                Milli(min_us as u64),
                Milli(MAX_STALE_US as u64)
            ),
            ConfigError::Estimator(e) => e.fmt(f),
            ConfigError::NoSuchRegion { index, regions } => write!(
                f,
                "region {index} does not exist: the scene has {regions} regions (0 to {})",
                regions.saturating_sub(1)
            ),
            ConfigError::NoSuchBoundary {
                index,
                boundaries: 0,
            } => write!(
                f,
                "boundary {index} does not exist: the scene is one region with no boundaries"
            ),
            ConfigError::NoSuchBoundary { index, boundaries } => write!(
                f,
                "boundary {index} does not exist: the scene has {boundaries} boundaries (0 to {})",
                boundaries - 1
            ),
        }
    }
}
