//! The 2D scene as stated ([`Scene2d`], [`Config2d`]) and its compiled form: windows with a
//! texture each over a background texture, the edges that pulse when crossed, the drive mode,
//! and the refusals ([`Config2dError`]). Compiling is all-or-nothing: either every part
//! validates and compiles, or nothing is returned.
//!
//! Textures per kind in the plane (docs/plane.md, "Controller"):
//! - off, constant, random: read nothing of the finger (as in 1D);
//! - material and a velocity-synthesis grating: read the speed |V| (stick-slip and f = |V|/λ
//!   have no direction);
//! - a position-phase or hybrid grating has ridges, so it needs their orientation: given as a
//!   plain [`Texture`] it is refused; as an [`OrientedGrating`] it reads r·n and V·n.

use heapless::Vec;

use super::edges::{CompiledEdges, EdgeError, EdgePulse, Edges, MAX_EDGES};
use super::geometry::{Polygon, SegmentUm, MAX_COORD_UM};
use super::grating::{CompiledOriented, OrientedError, OrientedGrating};
use super::screen::{CompiledScreen, Screen, ScreenError, Window, DEFAULT_BAND_UM, MAX_WINDOWS};
use crate::burst::{BurstError, BurstTimer, SafetyLimits, TimerSettings};
use crate::gate::DriveMode;
use crate::texture::compiled::{CompileError, Compiled, Need};
use crate::texture::lines::{refractory_us, Lines};
use crate::texture::{GratingRender, Texture, TextureError};

/// The plane's span, µm: a plain texture's "substrate length" (a grating's λ may not exceed
/// it). Coordinates are within ±[`MAX_COORD_UM`].
pub const PLANE_SPAN_UM: u32 = 2 * MAX_COORD_UM as u32;

/// A window's (or the background's) texture.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum PlaneTexture {
    /// A 1D texture: off, constant, random, material, or a velocity-synthesis grating (fed
    /// |V|). A position-phase or hybrid grating is refused here: it needs a normal.
    Plain(Texture),
    /// A grating whose ridges lie across a normal: fed r·n and V·n.
    Oriented(OrientedGrating),
}

impl Default for PlaneTexture {
    fn default() -> Self {
        PlaneTexture::Plain(Texture::Off)
    }
}

/// One window as the scene states it.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Window2d {
    /// Its outline (3–16 vertices, simple).
    pub outline: Polygon,
    /// What it feels like inside.
    pub texture: PlaneTexture,
    /// Its outline pulses when crossed (one edge per side, counted in [`MAX_EDGES`]).
    pub edge: bool,
}

/// A 2D scene: windows (topmost first) over a background, edges, the drive mode.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Scene2d {
    /// The windows, topmost first (at most [`MAX_WINDOWS`]).
    pub windows: Vec<Window2d, MAX_WINDOWS>,
    /// Outside every window.
    pub background: PlaneTexture,
    /// Hysteresis band around every outline, µm (band/2 either side).
    pub band_um: u32,
    /// Free edge segments, after the flagged outlines' sides (together at most [`MAX_EDGES`]).
    pub free_edges: Vec<SegmentUm, MAX_EDGES>,
    /// The pulse every edge fires.
    pub edge_pulse: EdgePulse,
    /// Distance clear of an edge that re-arms it, µm.
    pub rearm_um: u32,
    /// Standing or progressive waves.
    pub drive: DriveMode,
}

impl Default for Scene2d {
    /// No windows, the background off, the 1D defaults for band, pulse and re-arm.
    fn default() -> Self {
        let edges = Edges::default();
        Self {
            windows: Vec::new(),
            background: PlaneTexture::default(),
            band_um: DEFAULT_BAND_UM,
            free_edges: Vec::new(),
            edge_pulse: edges.pulse,
            rearm_um: edges.rearm_um,
            drive: DriveMode::Standing,
        }
    }
}

/// Everything [`super::Controller2d`] needs besides the board. The touch sensor is not in it:
/// the caller runs `touch::frame::TouchSensor` (its own config: pressure, rail bands, the
/// affine calibration) and hands the controller its `Reading`s, so one sensor setup serves
/// any scene and a scene load never resets the landing run.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Config2d {
    /// The scene.
    pub scene: Scene2d,
    /// Carrier caps.
    pub limits: SafetyLimits,
    /// With no reading for this long the sensor is stale and the carrier stops, µs.
    pub stale_after_us: u32,
}

impl Default for Config2d {
    /// The default scene, default caps, stale after 5 ms (the 1D default).
    fn default() -> Self {
        Self {
            scene: Scene2d::default(),
            limits: SafetyLimits::default(),
            stale_after_us: 5_000,
        }
    }
}

/// Which texture a refusal names: a window's or the background's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Owner {
    /// Window `i`.
    Window(u8),
    /// The background.
    Background,
}

impl core::fmt::Display for Owner {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Owner::Window(i) => write!(f, "window {i}"),
            Owner::Background => f.write_str("the background"),
        }
    }
}

/// Why a 2D configuration was refused (the previous one stays active).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Config2dError {
    /// The windows, band or outlines.
    Screen(ScreenError),
    /// The edges (count, segments, pulse, re-arm).
    Edges(EdgeError),
    /// The carrier caps.
    Limits(BurstError),
    /// A texture's parameters.
    Texture {
        /// Whose texture.
        owner: Owner,
        /// What is wrong.
        error: TextureError,
    },
    /// A texture's bursts cannot be rendered on this board within the caps.
    Burst {
        /// Whose texture.
        owner: Owner,
        /// What is wrong.
        error: BurstError,
    },
    /// An oriented grating's normal.
    Oriented {
        /// Whose texture.
        owner: Owner,
        /// What is wrong.
        error: OrientedError,
    },
    /// A position-phase or hybrid grating given without a normal.
    GratingNeedsNormal {
        /// Whose texture.
        owner: Owner,
    },
    /// The edge pulse's amplitude above the level cap.
    EdgeLevel {
        /// The amplitude asked for, ‰.
        permille: u16,
        /// The cap, ‰.
        max_level_permille: u16,
    },
    /// The edge pulse cannot be rendered on this board.
    EdgePulse(BurstError),
    /// Stale limit shorter than two sample periods or above one second.
    StaleLimit {
        /// The limit asked for, µs.
        stale_after_us: u32,
        /// Two sample periods, µs.
        min_us: u32,
    },
    /// The velocity estimator rejected the sample period.
    Estimator(crate::velocity::EstimatorError),
}

/// Longest stale limit, µs (the 1D controller's).
pub const MAX_STALE_US: u32 = 1_000_000;

impl core::fmt::Display for Config2dError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::{Deci, Milli};
        match *self {
            Config2dError::Screen(e) => e.fmt(f),
            Config2dError::Edges(e) => e.fmt(f),
            Config2dError::Limits(BurstError::BadDuty { duty_permille }) => write!(
                f,
                "duty cap {} % must be above 0 % and at most 100 %",
                Deci(duty_permille as u64)
            ),
            Config2dError::Limits(e) => e.fmt(f),
            Config2dError::Texture { owner, error } => write!(f, "{owner}: {error}"),
            Config2dError::Burst { owner, error } => write!(f, "{owner}: {error}"),
            Config2dError::Oriented { owner, error } => write!(f, "{owner}: {error}"),
            Config2dError::GratingNeedsNormal { owner } => write!(
                f,
                "{owner}: a position-phase or hybrid grating needs the ridges' normal in the \
                 plane: give it as an oriented grating"
            ),
            Config2dError::EdgeLevel {
                permille,
                max_level_permille,
            } => write!(
                f,
                "edge amplitude {} % is above the level cap of {} %",
                Deci(permille as u64),
                Deci(max_level_permille as u64)
            ),
            Config2dError::EdgePulse(e) => write!(f, "edge pulse: {e}"),
            Config2dError::StaleLimit {
                stale_after_us,
                min_us,
            } => write!(
                f,
                "stale limit {} ms must be at least two sample periods ({} ms) and at most {} ms",
                Milli(stale_after_us as u64),
                Milli(min_us as u64),
                Milli(MAX_STALE_US as u64)
            ),
            Config2dError::Estimator(e) => e.fmt(f),
        }
    }
}

/// A texture compiled for the plane.
#[derive(Clone, Debug)]
#[allow(
    clippy::large_enum_variant,
    reason = "no_std without an allocator: nothing to box into (as texture::compiled)"
)]
pub(crate) enum PlaneCompiled {
    /// A 1D texture fed |V| (material, velocity synthesis) or nothing (off, constant, random).
    Plain(Compiled),
    /// Fed r·n and V·n.
    Oriented(CompiledOriented),
}

impl PlaneCompiled {
    /// The settings it asks on every sample when its request never varies (a plain off or
    /// constant texture), else None ([`Compiled::fixed_settings`]).
    pub(crate) fn fixed_settings(&self) -> Option<Option<TimerSettings>> {
        match self {
            PlaneCompiled::Plain(c) => c.fixed_settings(),
            PlaneCompiled::Oriented(_) => None,
        }
    }

    /// What it reads per sample (the sample path's contract).
    pub(crate) fn need(&self) -> Need {
        match self {
            PlaneCompiled::Plain(c) => c.need(),
            PlaneCompiled::Oriented(o) => o.need(),
        }
    }

    /// Forgets the finger (window change, fault, lift).
    pub(crate) fn reset(&mut self) {
        match self {
            PlaneCompiled::Plain(c) => crate::texture::compiled::Render::reset(c),
            PlaneCompiled::Oriented(o) => o.reset(),
        }
    }
}

/// The edge pulse compiled: its one-pulse settings and the window (pulse + rest) it owns the
/// gate for, which keeps pulse / (pulse + rest) within the duty cap as 1D lines do.
#[derive(Clone, Copy, Debug)]
pub(crate) struct EdgeFire {
    pub pulse: TimerSettings,
    pub window_us: u32,
    pub amplitude_permille: u16,
    pub envelope: crate::gate::Envelope,
}

/// A validated, compiled 2D scene.
#[derive(Clone, Debug)]
pub(crate) struct CompiledScene2d {
    pub screen: CompiledScreen,
    /// Window i's texture at i, the background's last.
    pub textures: Vec<PlaneCompiled, { MAX_WINDOWS + 1 }>,
    /// None when the scene draws no edges.
    pub edges: Option<(CompiledEdges, EdgeFire)>,
    pub drive: DriveMode,
}

fn compile_texture(
    owner: Owner,
    texture: &PlaneTexture,
    timer: &BurstTimer,
    limits: &SafetyLimits,
    sample_period_us: u32,
) -> Result<PlaneCompiled, Config2dError> {
    match texture {
        PlaneTexture::Plain(Texture::Grating(g))
            if g.render != GratingRender::VelocitySynthesis =>
        {
            Err(Config2dError::GratingNeedsNormal { owner })
        }
        PlaneTexture::Plain(t) => {
            Compiled::compile(t, timer, limits, PLANE_SPAN_UM, sample_period_us)
                .map(|(c, _capped)| PlaneCompiled::Plain(c))
                .map_err(|e| match e {
                    CompileError::Params(error) => Config2dError::Texture { owner, error },
                    CompileError::Burst(error) => Config2dError::Burst { owner, error },
                })
        }
        PlaneTexture::Oriented(o) => o
            .compile(timer, limits, PLANE_SPAN_UM, sample_period_us)
            .map(PlaneCompiled::Oriented)
            .map_err(|e| match e {
                OrientedError::Texture(error) => Config2dError::Texture { owner, error },
                OrientedError::Burst(error) => Config2dError::Burst { owner, error },
                error => Config2dError::Oriented { owner, error },
            }),
    }
}

impl Scene2d {
    /// Validates and compiles the scene for this board, these caps and this sample period.
    /// All or nothing: the first refusal is returned and nothing is kept.
    pub(crate) fn compile(
        &self,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        sample_period_us: u32,
    ) -> Result<CompiledScene2d, Config2dError> {
        limits.validate().map_err(Config2dError::Limits)?;
        // The screen sees window i's texture as index i, the background's as the last.
        let mut windows: Vec<Window, MAX_WINDOWS> = Vec::new();
        for (i, w) in self.windows.iter().enumerate() {
            // Capacity: as many as the scene's windows.
            let _ = windows.push(Window {
                outline: w.outline.clone(),
                texture: i as u8,
            });
        }
        let n = self.windows.len();
        let screen = Screen {
            windows,
            background_texture: n as u8,
            band_um: self.band_um,
        }
        .compile(n + 1)
        .map_err(Config2dError::Screen)?;
        let mut textures = Vec::new();
        for (i, w) in self.windows.iter().enumerate() {
            let c = compile_texture(
                Owner::Window(i as u8),
                &w.texture,
                timer,
                limits,
                sample_period_us,
            )?;
            let _ = textures.push(c);
        }
        let bg = compile_texture(
            Owner::Background,
            &self.background,
            timer,
            limits,
            sample_period_us,
        )?;
        let _ = textures.push(bg);
        let edges = self.compile_edges(timer, limits, sample_period_us)?;
        Ok(CompiledScene2d {
            screen,
            textures,
            edges,
            drive: self.drive,
        })
    }

    /// The flagged outlines' sides, then the free segments; None when there are none.
    fn compile_edges(
        &self,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        sample_period_us: u32,
    ) -> Result<Option<(CompiledEdges, EdgeFire)>, Config2dError> {
        let mut edges = Edges {
            segments: Vec::new(),
            pulse: self.edge_pulse,
            rearm_um: self.rearm_um,
        };
        for w in self.windows.iter().filter(|w| w.edge) {
            edges
                .push_outline(&w.outline)
                .map_err(Config2dError::Edges)?;
        }
        let total = edges.segments.len() + self.free_edges.len();
        if total > MAX_EDGES {
            return Err(Config2dError::Edges(EdgeError::TooMany { edges: total }));
        }
        for s in &self.free_edges {
            let _ = edges.segments.push(*s);
        }
        if edges.segments.is_empty() {
            return Ok(None);
        }
        let compiled = edges
            .compile(limits.max_on_time_us, sample_period_us)
            .map_err(Config2dError::Edges)?;
        let p = self.edge_pulse;
        if p.amplitude_permille > limits.max_level_permille {
            return Err(Config2dError::EdgeLevel {
                permille: p.amplitude_permille,
                max_level_permille: limits.max_level_permille,
            });
        }
        let clocks = p.pulse_us as u64 * timer.clock_hz as u64 / 1_000_000;
        let pulse = timer.one_pulse(clocks).map_err(Config2dError::EdgePulse)?;
        // The 1D lines' rest after a pulse, for the same pulse length and cap.
        let rest_us = refractory_us(
            &Lines {
                pulse_us: p.pulse_us,
                ..Lines::default()
            },
            limits,
        );
        Ok(Some((
            compiled,
            EdgeFire {
                pulse,
                window_us: p.pulse_us.saturating_add(rest_us),
                amplitude_permille: p.amplitude_permille,
                envelope: p.envelope,
            },
        )))
    }
}
