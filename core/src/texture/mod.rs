//! Texture stage: what a region feels like, compiled at scene load into what the per-sample path
//! needs, so a scene only pays for the models it uses ("model no more than a scene needs").
//!
//! - [`Texture::Constant`]: fixed f_b (fig. 11 of the SAW display paper) — planned once at load,
//!   one table look-up per sample.
//! - [`Texture::Grating`]: a virtual grating of period λ (Konyo et al., eq. 1): one burst per
//!   ridge crossing placed by position, or f = |V|/λ by velocity synthesis.
//! - [`Texture::Material`]: the stick-slip frequency of a material at the live hand speed
//!   (SAW display paper, eq. 10–12).
//! - [`Texture::Random`]: f_b and amplitude drawn about central values each burst (the paper's
//!   "Randomness button"), from a seeded PRNG so runs reproduce.
//!
//! Tangible lines (fig. 12) overlay any region: see [`lines`].
//!
//! At scene load each region's texture is compiled (`compiled.rs`: validated, its constants
//! prepared, its per-sample state created); per sample the controller asks the region under
//! the finger what it wants from the gate. Each kind's compiled form lives in its own file with
//! its parameters; the speed threshold of the velocity-driven kinds in `motion.rs`.

use crate::burst::BurstCommand;

pub(crate) mod compiled;
pub mod grating;
pub mod lines;
pub mod material;
mod motion;
pub mod predict;
pub mod random;

pub use compiled::Need;
pub use grating::{Grating, GratingRender};
pub use lines::{Envelope, Lines};
pub use material::Material;
pub use random::RandomBurst;

/// Full drive amplitude, ‰.
pub const FULL_AMPLITUDE: u16 = 1000;

/// The feel of one region.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Texture {
    /// No SAW: the bare substrate's friction.
    Off,
    /// Bursts at a fixed f_b and duty (fig. 11): < 30 Hz bumpy, 30–100 Hz rough, > 1 kHz smooth.
    Constant(BurstCommand),
    /// A virtual grating of period λ: a burst per ridge crossing, none at rest.
    Grating(Grating),
    /// A material's stick-slip frequency at the hand speed.
    Material(Material),
    /// Random f_b and amplitude about central values.
    Random(RandomBurst),
}

impl Texture {
    /// Constant bursts at `hz` with the seed's 40 % duty.
    pub const fn constant_hz(hz: u32) -> Self {
        Texture::Constant(BurstCommand {
            burst_millihz: hz * 1000,
            duty_permille: 400,
        })
    }

    /// The command this texture asks for when it does not depend on motion or chance.
    pub fn fixed_command(&self) -> Option<BurstCommand> {
        match self {
            Texture::Constant(c) => Some(*c),
            _ => None,
        }
    }

    /// Short name for logs and reports.
    pub fn kind(&self) -> &'static str {
        match self {
            Texture::Off => "off",
            Texture::Constant(_) => "constant",
            Texture::Grating(_) => "grating",
            Texture::Material(_) => "material",
            Texture::Random(_) => "random",
        }
    }
}

/// Why a texture's parameters were rejected. Each variant carries the values its sentence
/// (`Display`) names, shown in the scene file's units (mm, mm/s, %, ms).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum TextureError {
    /// Grating period zero or above the substrate.
    BadWavelength {
        /// The period asked for, µm.
        wavelength_um: u32,
        /// Substrate length, µm.
        length_um: u32,
    },
    /// Speed threshold above 1 m/s.
    BadSpeedThreshold {
        /// The threshold asked for, µm/s.
        min_speed_um_s: u32,
    },
    /// A material parameter is not finite or not positive (Δμ may be zero).
    BadMaterial {
        /// Which parameter.
        param: MaterialParam,
        /// Its value, in the [`Material`] field's unit.
        value: ParamValue,
    },
    /// Random spread at or above 1000 ‰, amplitude spread above 1000 ‰, or an amplitude
    /// outside 1 ..= 1000 ‰.
    BadSpread {
        /// Which parameter.
        param: SpreadParam,
        /// Its value, ‰.
        permille: u16,
    },
    /// A line out of the substrate or not after the one before it, or the lines' amplitude or
    /// re-arm distance out of range.
    BadLines(LineFault),
    /// Line pulse empty or longer than the on-time cap.
    BadPulse {
        /// The pulse asked for, µs.
        pulse_us: u32,
        /// The on-time cap, µs.
        max_on_time_us: u32,
    },
    /// An amplitude above the scene's level cap (`limits.max_level_percent`).
    LevelAboveCap {
        /// The amplitude asked for, ‰.
        permille: u16,
        /// The cap, ‰.
        max_level_permille: u16,
    },
    /// Grating re-arm distance not below half the period.
    BadRearm {
        /// The re-arm distance asked for, µm.
        rearm_um: u32,
        /// The grating's period, µm.
        wavelength_um: u32,
    },
}

/// The [`Material`] parameter a [`TextureError::BadMaterial`] names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum MaterialParam {
    /// `delta_mu`, μs − μc.
    DeltaMu,
    /// `normal_force_n`, N.
    NormalForce,
    /// `mass_kg` (shown in g, as a scene file's `mass_g`).
    Mass,
    /// `stiffness_n_per_m`, N/m.
    Stiffness,
}

/// A float parameter as an error carries it. Compared bit for bit, so an error holding a NaN
/// still equals itself and the error types keep `Eq`.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ParamValue(pub f32);

impl PartialEq for ParamValue {
    fn eq(&self, other: &Self) -> bool {
        self.0.to_bits() == other.0.to_bits()
    }
}

impl Eq for ParamValue {}

/// The ‰ parameter a [`TextureError::BadSpread`] names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum SpreadParam {
    /// A random texture's f_b spread (below 1000 ‰).
    Spread,
    /// A drive amplitude (1 ..= 1000 ‰).
    Amplitude,
    /// A random texture's amplitude spread (up to 1000 ‰).
    AmplitudeSpread,
}

/// What is wrong with the lines ([`TextureError::BadLines`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum LineFault {
    /// Line `index` is at 0 or at or beyond the substrate's far end.
    OutOfRange {
        /// Index of the line.
        index: u8,
        /// Its position, µm.
        at_um: u32,
        /// Substrate length, µm.
        length_um: u32,
    },
    /// Line `index` is not after the line before it.
    Unsorted {
        /// Index of the line.
        index: u8,
        /// Its position, µm.
        at_um: u32,
        /// The line before it, µm.
        previous_um: u32,
    },
    /// The lines' amplitude outside 1 ..= 1000 ‰.
    Amplitude {
        /// The amplitude asked for, ‰.
        permille: u16,
    },
    /// The lines' re-arm distance above 5 mm.
    Rearm {
        /// The re-arm distance asked for, µm.
        rearm_um: u32,
    },
}

/// Longest line re-arm distance, µm.
pub(crate) const MAX_LINE_REARM_UM: u32 = 5_000;

impl core::fmt::Display for TextureError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::{Deci, Milli};
        let mm = |um: u32| Milli(um as u64);
        match *self {
            TextureError::BadWavelength {
                wavelength_um,
                length_um,
            } => write!(
                f,
                "wavelength {} mm must be above 0 mm and at most the substrate's length, {} mm",
                mm(wavelength_um),
                mm(length_um)
            ),
            TextureError::BadSpeedThreshold { min_speed_um_s } => write!(
                f,
                "speed threshold {} mm/s must be at most 1000 mm/s",
                mm(min_speed_um_s)
            ),
            TextureError::BadMaterial { param, value } => {
                let v = value.0;
                match param {
                    MaterialParam::DeltaMu => {
                        write!(f, "μs − μc {v} must be finite and at least 0")
                    }
                    MaterialParam::NormalForce => {
                        write!(f, "normal force {v} N must be finite and above 0 N")
                    }
                    MaterialParam::Mass => {
                        write!(f, "mass {} g must be finite and above 0 g", v * 1000.0)
                    }
                    MaterialParam::Stiffness => {
                        write!(f, "stiffness {v} N/m must be finite and above 0 N/m")
                    }
                }
            }
            TextureError::BadSpread { param, permille } => {
                let pct = Deci(permille as u64);
                match param {
                    SpreadParam::Spread => write!(f, "spread {pct} % must be below 100 %"),
                    SpreadParam::Amplitude => {
                        write!(f, "amplitude {pct} % must be above 0 % and at most 100 %")
                    }
                    SpreadParam::AmplitudeSpread => {
                        write!(f, "amplitude spread {pct} % must be at most 100 %")
                    }
                }
            }
            TextureError::BadLines(LineFault::OutOfRange {
                index,
                at_um,
                length_um,
            }) => write!(
                f,
                "line {index} at {} mm must be strictly between 0 mm and the substrate's end at \
                 {} mm",
                mm(at_um),
                mm(length_um)
            ),
            TextureError::BadLines(LineFault::Unsorted {
                index,
                at_um,
                previous_um,
            }) => write!(
                f,
                "line {index} at {} mm must be after line {} ({} mm)",
                mm(at_um),
                index.saturating_sub(1),
                mm(previous_um)
            ),
            TextureError::BadLines(LineFault::Amplitude { permille }) => write!(
                f,
                "line amplitude {} % must be above 0 % and at most 100 %",
                Deci(permille as u64)
            ),
            TextureError::BadLines(LineFault::Rearm { rearm_um }) => write!(
                f,
                "line re-arm distance {} mm must be at most {} mm",
                mm(rearm_um),
                mm(MAX_LINE_REARM_UM)
            ),
            TextureError::BadPulse {
                pulse_us,
                max_on_time_us,
            } => write!(
                f,
                "line pulse {} ms must be above 0 ms and at most the on-time cap of {} ms",
                Milli(pulse_us as u64),
                Milli(max_on_time_us as u64)
            ),
            TextureError::LevelAboveCap {
                permille,
                max_level_permille,
            } => write!(
                f,
                "amplitude {} % is above the level cap of {} % (limits.max_level_percent)",
                Deci(permille as u64),
                Deci(max_level_permille as u64)
            ),
            TextureError::BadRearm {
                rearm_um,
                wavelength_um,
            } => write!(
                f,
                "re-arm distance {} mm must be below half the wavelength of {} mm",
                mm(rearm_um),
                mm(wavelength_um)
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Errors compare their float values bit for bit: a NaN equals itself (so an error holding
    /// one equals itself), different values differ, and so do 0 and −0.
    #[test]
    fn param_values_compare_bit_for_bit() {
        assert_eq!(ParamValue(f32::NAN), ParamValue(f32::NAN));
        assert_ne!(ParamValue(1.0), ParamValue(2.0));
        assert_ne!(ParamValue(0.0), ParamValue(-0.0));
    }

    /// Each refusal reads as one sentence in the scene file's units.
    #[test]
    fn errors_read_as_sentences() {
        let cases = [
            (
                TextureError::BadWavelength {
                    wavelength_um: 80_000,
                    length_um: 63_000,
                },
                "wavelength 80 mm must be above 0 mm and at most the substrate's length, 63 mm",
            ),
            (
                TextureError::BadSpeedThreshold {
                    min_speed_um_s: 1_000_001,
                },
                "speed threshold 1000.001 mm/s must be at most 1000 mm/s",
            ),
            (
                TextureError::BadMaterial {
                    param: MaterialParam::DeltaMu,
                    value: ParamValue(-0.5),
                },
                "μs − μc -0.5 must be finite and at least 0",
            ),
            (
                TextureError::BadMaterial {
                    param: MaterialParam::NormalForce,
                    value: ParamValue(f32::NAN),
                },
                "normal force NaN N must be finite and above 0 N",
            ),
            (
                TextureError::BadMaterial {
                    param: MaterialParam::Mass,
                    value: ParamValue(0.0),
                },
                "mass 0 g must be finite and above 0 g",
            ),
            (
                TextureError::BadMaterial {
                    param: MaterialParam::Stiffness,
                    value: ParamValue(f32::INFINITY),
                },
                "stiffness inf N/m must be finite and above 0 N/m",
            ),
            (
                TextureError::BadSpread {
                    param: SpreadParam::Spread,
                    permille: 1000,
                },
                "spread 100 % must be below 100 %",
            ),
            (
                TextureError::BadSpread {
                    param: SpreadParam::Amplitude,
                    permille: 0,
                },
                "amplitude 0 % must be above 0 % and at most 100 %",
            ),
            (
                TextureError::BadSpread {
                    param: SpreadParam::AmplitudeSpread,
                    permille: 1001,
                },
                "amplitude spread 100.1 % must be at most 100 %",
            ),
            (
                TextureError::BadLines(LineFault::OutOfRange {
                    index: 1,
                    at_um: 63_000,
                    length_um: 63_000,
                }),
                "line 1 at 63 mm must be strictly between 0 mm and the substrate's end at 63 mm",
            ),
            (
                TextureError::BadLines(LineFault::Unsorted {
                    index: 1,
                    at_um: 20_000,
                    previous_um: 30_000,
                }),
                "line 1 at 20 mm must be after line 0 (30 mm)",
            ),
            (
                TextureError::BadLines(LineFault::Amplitude { permille: 1001 }),
                "line amplitude 100.1 % must be above 0 % and at most 100 %",
            ),
            (
                TextureError::BadLines(LineFault::Rearm { rearm_um: 5_001 }),
                "line re-arm distance 5.001 mm must be at most 5 mm",
            ),
            (
                TextureError::BadPulse {
                    pulse_us: 60_000,
                    max_on_time_us: 50_000,
                },
                "line pulse 60 ms must be above 0 ms and at most the on-time cap of 50 ms",
            ),
            (
                TextureError::BadRearm {
                    rearm_um: 500,
                    wavelength_um: 1_000,
                },
                "re-arm distance 0.5 mm must be below half the wavelength of 1 mm",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence, "{e:?}");
        }
    }
}
