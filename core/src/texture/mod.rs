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

use crate::burst::BurstCommand;

pub mod grating;
pub mod lines;
pub mod material;
pub mod random;

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

/// Why a texture's parameters were rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum TextureError {
    /// Grating period zero or above the substrate.
    BadWavelength,
    /// Speed threshold negative or above 1 m/s.
    BadSpeedThreshold,
    /// A material parameter is not finite or not positive (Δμ may be zero).
    BadMaterial,
    /// Random spread outside 0 ..= 1000 ‰ or amplitude outside 1 ..= 1000 ‰.
    BadSpread,
    /// Line positions unsorted, out of the substrate, or too many.
    BadLines,
    /// Line pulse empty or longer than the on-time cap.
    BadPulse,
    /// Grating re-arm distance not below half the period.
    BadRearm,
}
