//! Compiled textures: what a region does per sample. At scene load each region's [`Texture`]
//! is validated and turned into its prepared constants and its per-sample state; per sample the
//! controller asks the region under the finger for a [`Request`] through one interface
//! ([`Render`]). A new texture kind adds a variant here and its own file; the controller does
//! not change.

use crate::burst::{self, BurstError, BurstTimer, SafetyLimits, TimerSettings};
use crate::gate::Gate;
use crate::velocity::VelocityEstimator;

use super::grating::{GratingRender, Ridges, Synthesis};
use super::material::StickSlip;
use super::random::RandomDraws;
use super::{Texture, TextureError, FULL_AMPLITUDE};

/// What a texture wants from the gate on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Want {
    /// Periodic bursts of the request's settings, or off when None.
    Periodic,
    /// One pulse of the request's settings now.
    Pulse,
    /// End the running pulse now (the finger has left its ridge).
    EndPulse,
}

/// What a texture asks for on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Request {
    /// Periodic settings (off when None), or the pulse's when `want` is [`Want::Pulse`].
    pub settings: Option<TimerSettings>,
    /// Ridge crossings passed without a pulse on this sample.
    pub skipped: u32,
    /// Drive amplitude, ‰; `u16::MAX` leaves it as it is.
    pub amplitude: u16,
    pub want: Want,
    /// The f_b asked for was above the board's limit and was clamped to it.
    pub clamped: bool,
}

impl Request {
    /// Line off at full amplitude.
    pub const OFF: Request = Request {
        settings: None,
        skipped: 0,
        amplitude: FULL_AMPLITUDE,
        want: Want::Periodic,
        clamped: false,
    };

    /// Periodic bursts from a fast planner's result (off when it planned none).
    #[inline]
    pub fn planned(plan: Option<(TimerSettings, bool)>, amplitude: u16) -> Request {
        match plan {
            Some((settings, clamped)) => Request {
                settings: Some(settings),
                amplitude,
                clamped,
                ..Request::OFF
            },
            None => Request::OFF,
        }
    }
}

/// What a compiled texture needs computed per sample: the sample path's contract
/// (docs/sample-contract.md). The controller computes nothing a region in force does not need.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Need {
    /// The position alone (off, constant, random): the velocity estimator rests.
    Position,
    /// The estimator's velocity (gratings, materials; lines everywhere in their scene).
    Velocity,
    /// A fit of its own that also gives the velocity (the hybrid grating's 64-sample line):
    /// the shared estimator rests, as for [`Need::Position`].
    OwnFit,
}

/// What a texture sees of one sample.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Moment<'a> {
    pub position_um: i32,
    /// None until the estimator has a full window.
    pub velocity_um_s: Option<i32>,
    pub t_us: u32,
    /// The gate: what the line is doing now.
    pub gate: &'a Gate,
    pub timer: &'a BurstTimer,
}

/// The interface of a compiled texture.
pub(crate) trait Render {
    /// Forgets motion and draw state (region change, fault).
    fn reset(&mut self);
    /// What the texture asks of the gate on this sample.
    fn request(&mut self, now: &Moment<'_>) -> Request;
}

/// Why a texture (or the lines) did not compile; the controller names the region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum CompileError {
    /// The parameters are invalid.
    Params(TextureError),
    /// The bursts cannot be rendered on this board within the caps.
    Burst(BurstError),
}

impl From<TextureError> for CompileError {
    fn from(e: TextureError) -> Self {
        CompileError::Params(e)
    }
}

impl From<BurstError> for CompileError {
    fn from(e: BurstError) -> Self {
        CompileError::Burst(e)
    }
}

/// A region's texture, compiled: only what its per-sample path needs.
#[derive(Clone, Debug)]
#[allow(
    clippy::large_enum_variant,
    reason = "no_std without an allocator: nothing to box into; the regions' textures sit in a heapless Vec, read in place per sample (the lint fired once FastPlanner shrank to 32-bit fields and the random texture with it)"
)]
pub(crate) enum Compiled {
    Off,
    /// A constant texture: its timer settings, planned once.
    Fixed(TimerSettings),
    Ridges(Ridges),
    Synthesis(Synthesis),
    StickSlip(StickSlip),
    Random(RandomDraws),
}

impl Compiled {
    /// Validates `texture` and prepares it for this board and these caps, on a substrate of
    /// `length_um` sampled every `sample_period_us`. The flag is true when a constant burst's
    /// on-time was capped.
    pub fn compile(
        texture: &Texture,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        length_um: u32,
        sample_period_us: u32,
    ) -> Result<(Self, bool), CompileError> {
        // An amplitude of the texture's own above the level cap is a contradiction in the
        // scene: refused, like a duty above the duty cap. ("Full drive" plays at the cap.)
        let asked = match texture {
            Texture::Grating(g) => Some(g.amplitude_permille),
            Texture::Random(r) => Some(r.amplitude_permille),
            _ => None,
        };
        if let Some(permille) = asked.filter(|&a| a > limits.max_level_permille) {
            return Err(TextureError::LevelAboveCap {
                permille,
                max_level_permille: limits.max_level_permille,
            }
            .into());
        }
        Ok(match texture {
            Texture::Off => (Compiled::Off, false),
            Texture::Constant(cmd) => {
                let (s, capped) = burst::plan(timer, limits, cmd)?;
                (Compiled::Fixed(s), capped)
            }
            Texture::Grating(g) => {
                g.validate(length_um)?;
                let c = match g.render {
                    GratingRender::PositionPhase | GratingRender::Hybrid => {
                        Compiled::Ridges(Ridges::new(g, timer, limits, sample_period_us)?)
                    }
                    GratingRender::VelocitySynthesis => {
                        Compiled::Synthesis(Synthesis::new(g, timer, limits)?)
                    }
                };
                (c, false)
            }
            Texture::Material(m) => (
                Compiled::StickSlip(StickSlip::new(m, timer, limits)?),
                false,
            ),
            Texture::Random(r) => (Compiled::Random(RandomDraws::new(r, timer, limits)?), false),
        })
    }
}

impl Compiled {
    /// The settings a kind whose request never varies asks on every sample ([`Request::OFF`]
    /// with these settings): off, constant. None for the kinds that read the sample or draw.
    pub fn fixed_settings(&self) -> Option<Option<TimerSettings>> {
        match self {
            Compiled::Off => Some(None),
            Compiled::Fixed(s) => Some(Some(*s)),
            _ => None,
        }
    }

    /// What this texture reads per sample.
    pub fn need(&self) -> Need {
        match self {
            Compiled::Off | Compiled::Fixed(_) | Compiled::Random(_) => Need::Position,
            Compiled::Ridges(r) if r.is_hybrid() => Need::OwnFit,
            Compiled::Ridges(_) | Compiled::Synthesis(_) | Compiled::StickSlip(_) => Need::Velocity,
        }
    }
}

impl Compiled {
    /// The velocity of a texture with a fit of its own ([`Need::OwnFit`]), µm/s; None for
    /// every other kind, or before its fit has a full window.
    pub(crate) fn own_velocity_um_s(&self) -> Option<i32> {
        match self {
            Compiled::Ridges(r) => r.own_velocity_um_s(),
            _ => None,
        }
    }

    /// Feeds the newest `k` positions of a texture's own fit to `estimator` (from scratch):
    /// the estimator slept in its region and wakes seeded, not empty. Feeds nothing for a kind
    /// without a fit of its own.
    pub(crate) fn seed<E: VelocityEstimator + ?Sized>(&self, estimator: &mut E, k: usize) {
        estimator.reset();
        if let Compiled::Ridges(r) = self {
            for (position_um, t_us) in r.own_history(k) {
                let _ = estimator.update(position_um, t_us);
            }
        }
    }
}

impl Render for Compiled {
    fn reset(&mut self) {
        match self {
            Compiled::Off | Compiled::Fixed(_) => {}
            Compiled::Ridges(r) => r.reset(),
            Compiled::Synthesis(s) => s.reset(),
            Compiled::StickSlip(m) => m.reset(),
            Compiled::Random(r) => r.reset(),
        }
    }

    // Inlined into the controller's one call site, so the sample's fields stay in registers
    // and a kind that reads none of them (off, constant) pays for none.
    #[inline(always)]
    fn request(&mut self, now: &Moment<'_>) -> Request {
        match self {
            Compiled::Off => Request::OFF,
            Compiled::Fixed(s) => Request {
                settings: Some(*s),
                ..Request::OFF
            },
            Compiled::Ridges(r) => r.request(now),
            Compiled::Synthesis(s) => s.request(now),
            Compiled::StickSlip(m) => m.request(now),
            Compiled::Random(r) => r.request(now),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::TEST_TIMER;
    use crate::texture::{Grating, GratingRender, Material, RandomBurst};

    /// A kind that names fixed settings asks exactly `Request::OFF` with them on every sample
    /// (any position, velocity, time, gate state); the kinds that read the sample or draw
    /// name none, and do vary. (The controller's short way for a fixed texture rests on this:
    /// `plane::controller::tests::the_fixed_texture_step_changes_no_output`.)
    #[test]
    fn only_off_and_constant_ask_fixed_settings_and_they_never_vary() {
        let limits = SafetyLimits::default();
        let kinds = [
            Texture::Off,
            Texture::constant_hz(80),
            Texture::constant_hz(5_000),
            Texture::Grating(Grating {
                render: GratingRender::VelocitySynthesis,
                ..Grating::new(1_000)
            }),
            Texture::Grating(Grating::new(1_000)),
            Texture::Material(Material::fig5(0.3)),
            Texture::Random(RandomBurst {
                center_millihz: 40_000,
                spread_permille: 300,
                amplitude_permille: 800,
                amplitude_spread_permille: 200,
                duty_permille: 400,
                seed: 5,
            }),
        ];
        let gate = Gate::default();
        for (k, texture) in kinds.iter().enumerate() {
            let (mut c, _) =
                Compiled::compile(texture, &TEST_TIMER, &limits, 100_000, 100).unwrap();
            let fixed = c.fixed_settings();
            let mut seen = std::vec::Vec::new();
            let mut x = 1u32;
            for i in 0..4_000u32 {
                // A small LCG: positions over the substrate, speeds ±400 mm/s, times 0.1 ms apart.
                x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let now = Moment {
                    position_um: (x >> 15) as i32 % 100_000,
                    velocity_um_s: (i % 7 != 0).then_some((x >> 8) as i32 % 400_000 - 200_000),
                    t_us: i * 100,
                    gate: &gate,
                    timer: &TEST_TIMER,
                };
                let r = c.request(&now);
                if let Some(settings) = fixed {
                    assert_eq!(
                        r,
                        Request {
                            settings,
                            ..Request::OFF
                        },
                        "kind {k}"
                    );
                }
                if !seen.contains(&r) {
                    seen.push(r);
                }
            }
            match texture {
                Texture::Off | Texture::Constant(_) => assert!(fixed.is_some(), "kind {k}"),
                _ => {
                    assert_eq!(fixed, None, "kind {k}");
                    assert!(seen.len() > 1, "kind {k} never varied");
                }
            }
        }
    }
}
