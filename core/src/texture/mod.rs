//! Texture stage: what a region feels like, as the burst command it asks for.
//!
//! A texture is compiled at scene load into what the per-sample path needs: a constant texture
//! becomes precomputed timer settings, so a constant scene pays one table look-up per sample.

use crate::burst::BurstCommand;

/// The feel of one region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Texture {
    /// No SAW: the bare substrate's friction.
    Off,
    /// Bursts at a fixed f_b and duty (fig. 11 of the SAW display paper): < 30 Hz bumpy,
    /// 30–100 Hz rough, > 1 kHz smooth.
    Constant(BurstCommand),
}

impl Texture {
    /// Constant bursts at `hz` with the seed's 40 % duty.
    pub const fn constant_hz(hz: u32) -> Self {
        Texture::Constant(BurstCommand {
            burst_millihz: hz * 1000,
            duty_permille: 400,
        })
    }

    /// The command this texture asks for when it does not depend on motion.
    pub fn fixed_command(&self) -> Option<BurstCommand> {
        match self {
            Texture::Off => None,
            Texture::Constant(c) => Some(*c),
        }
    }
}
