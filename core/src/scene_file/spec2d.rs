//! The shape of a 2D scene file (issue #36): the `[sensor]`, `[screen]`, `[[window]]`,
//! `[[edge]]` and `[edges]` tables as serde reads them, every value with its span. A window's
//! (and the background's) texture takes exactly a `[[region]]`'s texture keys, declared once
//! here ([`textured!`]) and handed to the 1D per-kind readers as a [`RegionSpec`].

extern crate std;

use std::string::String;
use std::vec::Vec as StdVec;

use serde::Deserialize;
use toml::Spanned;

use super::spec::{Drive, EnvelopeSpec, Limits, RegionSpec, RenderSpec};

/// A point or a list of numbers, each number with its span.
pub(super) type Numbers = Spanned<StdVec<Spanned<f64>>>;

/// The whole 2D file. `[sensor]` is required (it is what makes the file 2D); the rest is
/// checked by hand so a missing table gets a sentence, not serde's.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct File2d {
    #[allow(
        dead_code,
        reason = "read by `plane2d::sensor` before the strict read; declared so that \
                  `deny_unknown_fields` takes it"
    )]
    pub(super) sensor: Spanned<SensorSpec>,
    pub(super) drive: Option<Spanned<Drive>>,
    pub(super) limits: Option<Spanned<Limits>>,
    pub(super) screen: Option<Spanned<ScreenSpec>>,
    #[serde(default)]
    pub(super) window: StdVec<Spanned<WindowSpec>>,
    #[serde(default)]
    pub(super) edge: StdVec<Spanned<EdgeSpec>>,
    pub(super) edges: Option<Spanned<EdgesSpec>>,
}

/// `[sensor]`: the sensor the scene needs.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SensorSpec {
    pub(super) kind: Spanned<String>,
}

/// Only `[sensor]`, every other key ignored: what [`super::sensor_of`] reads, so a 1D file
/// with a fault elsewhere is still recognised as 1D (and refused by the 1D reader's sentence).
#[derive(Deserialize)]
pub(super) struct SensorOnly {
    pub(super) sensor: Option<Spanned<SensorSpec>>,
}

/// `[screen]`: the plate's size, the band, the background.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ScreenSpec {
    pub(super) size_mm: Option<Numbers>,
    pub(super) band_mm: Option<Spanned<f64>>,
    pub(super) background: Option<Spanned<BackgroundSpec>>,
}

/// Declares a struct with the given keys first, then every texture key of a `[[region]]` (but
/// `until_mm`) and `ridge_angle_deg`, and its `texture()`: those keys as a [`RegionSpec`].
macro_rules! textured {
    ($(#[$meta:meta])* $name:ident { $($field:ident: $ty:ty,)* }) => {
        $(#[$meta])*
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        pub(super) struct $name {
            $(pub(super) $field: $ty,)*
            pub(super) kind: Spanned<String>,
            /// An oriented grating: the direction of the ridges' normal, degrees from +x
            /// towards +y.
            pub(super) ridge_angle_deg: Option<Spanned<f64>>,
            pub(super) f_b_hz: Option<Spanned<f64>>,
            pub(super) duty_percent: Option<Spanned<f64>>,
            pub(super) wavelength_mm: Option<Spanned<f64>>,
            pub(super) ridge_mm: Option<Spanned<f64>>,
            pub(super) groove_mm: Option<Spanned<f64>>,
            pub(super) min_speed_mm_s: Option<Spanned<f64>>,
            pub(super) amplitude_percent: Option<Spanned<f64>>,
            pub(super) render: Option<Spanned<RenderSpec>>,
            pub(super) rearm_mm: Option<Spanned<f64>>,
            pub(super) delta_mu: Option<Spanned<f64>>,
            pub(super) e_object_pa: Option<Spanned<f64>>,
            pub(super) nu_object: Option<Spanned<f64>>,
            pub(super) e_skin_pa: Option<Spanned<f64>>,
            pub(super) nu_skin: Option<Spanned<f64>>,
            pub(super) sigma_um: Option<Spanned<f64>>,
            pub(super) beta_um: Option<Spanned<f64>>,
            pub(super) shear_strength_diff_pa: Option<Spanned<f64>>,
            pub(super) normal_force_n: Option<Spanned<f64>>,
            pub(super) mass_g: Option<Spanned<f64>>,
            pub(super) stiffness_n_per_m: Option<Spanned<f64>>,
            pub(super) spread_percent: Option<Spanned<f64>>,
            pub(super) amplitude_spread_percent: Option<Spanned<f64>>,
            pub(super) seed: Option<Spanned<u64>>,
        }

        impl $name {
            /// The texture keys as a region's, for the 1D per-kind readers.
            pub(super) fn texture(&self) -> RegionSpec {
                RegionSpec {
                    kind: self.kind.clone(),
                    until_mm: None,
                    f_b_hz: self.f_b_hz.clone(),
                    duty_percent: self.duty_percent.clone(),
                    wavelength_mm: self.wavelength_mm.clone(),
                    ridge_mm: self.ridge_mm.clone(),
                    groove_mm: self.groove_mm.clone(),
                    min_speed_mm_s: self.min_speed_mm_s.clone(),
                    amplitude_percent: self.amplitude_percent.clone(),
                    render: self.render.clone(),
                    rearm_mm: self.rearm_mm.clone(),
                    delta_mu: self.delta_mu.clone(),
                    e_object_pa: self.e_object_pa.clone(),
                    nu_object: self.nu_object.clone(),
                    e_skin_pa: self.e_skin_pa.clone(),
                    nu_skin: self.nu_skin.clone(),
                    sigma_um: self.sigma_um.clone(),
                    beta_um: self.beta_um.clone(),
                    shear_strength_diff_pa: self.shear_strength_diff_pa.clone(),
                    normal_force_n: self.normal_force_n.clone(),
                    mass_g: self.mass_g.clone(),
                    stiffness_n_per_m: self.stiffness_n_per_m.clone(),
                    spread_percent: self.spread_percent.clone(),
                    amplitude_spread_percent: self.amplitude_spread_percent.clone(),
                    seed: self.seed.clone(),
                }
            }
        }
    };
}

textured!(
    /// `[[window]]`: an outline (`rect_mm` or `polygon_mm`), whether it pulses, a texture.
    WindowSpec {
        rect_mm: Option<Numbers>,
        polygon_mm: Option<Spanned<StdVec<Numbers>>>,
        outline: Option<Spanned<bool>>,
    }
);

textured!(
    /// `[screen] background = { … }`: the texture outside every window.
    BackgroundSpec {}
);

/// `[[edge]]`: a free segment that pulses when crossed.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct EdgeSpec {
    pub(super) from_mm: Numbers,
    pub(super) to_mm: Numbers,
}

/// `[edges]`: the pulse every edge fires, and its re-arm distance.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct EdgesSpec {
    pub(super) pulse_ms: Option<Spanned<f64>>,
    pub(super) envelope: Option<EnvelopeSpec>,
    pub(super) amplitude_percent: Option<Spanned<f64>>,
    pub(super) rearm_mm: Option<Spanned<f64>>,
}
