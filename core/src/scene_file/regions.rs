//! The `[[region]]` tables, left to right: where each region ends and the texture it renders,
//! one function per kind. Values are range-checked here; whether the board can play them (an
//! f_b above its limit, a region narrower than the hysteresis) is the controller's dry run.

extern crate std;

use core::ops::Range;
use std::string::String;

use heapless::Vec;
use toml::Spanned;

use crate::burst::BurstCommand;
use crate::region::MAX_REGIONS;
use crate::texture::{Grating, GratingRender, Material, RandomBurst, Texture};

use super::ctx::{milli, Ctx};
use super::spec::{RegionSpec, RenderSpec};
use super::SceneFileError;

/// The boundaries between regions, µm (as [`crate::Scene::boundaries_um`]).
type Boundaries = Vec<u32, { MAX_REGIONS - 1 }>;
/// One texture per region (as [`crate::Scene::textures`]).
type Textures = Vec<Texture, MAX_REGIONS>;

/// The regions: their boundaries and textures. `length_mm` bounds every boundary and
/// wavelength; `duty_cap_percent` (`[limits]`) lowers the default duty when it is below 40 %.
pub(super) fn regions(
    cx: &Ctx<'_>,
    specs: &[Spanned<RegionSpec>],
    length_mm: f64,
    duty_cap_percent: f64,
) -> Result<(Boundaries, Textures), SceneFileError> {
    if specs.is_empty() {
        return Err(cx.err(0..0, "region", "a scene needs at least one [[region]]"));
    }
    let mut boundaries_um = Boundaries::new();
    let mut textures = Textures::new();
    for (i, r) in specs.iter().enumerate() {
        let spec = r.get_ref();
        let prefix = std::format!("region[{i}]");
        let region = Region {
            cx,
            kind: spec.check_fields(cx, &prefix)?,
            prefix,
            span: r.span(),
            spec,
            length_mm,
            duty_cap_percent,
        };
        if let Some(um) = region.end_um(i + 1 == specs.len())? {
            boundaries_um.push(um).map_err(|_| region.too_many())?;
        }
        let texture = region.texture()?;
        textures.push(texture).map_err(|_| region.too_many())?;
    }
    Ok((boundaries_um, textures))
}

/// One texture as a region's keys state it, outside a `[[region]]` (a 2D window or the
/// background): `prefix` names its fields in errors (`window[1]` → `window[1].f_b_hz`), `span`
/// is its table (a missing key is refused there), `extent_mm` bounds a grating's period.
/// `until_mm` is not read: the caller refuses it.
pub(super) fn texture(
    cx: &Ctx<'_>,
    prefix: &str,
    span: Range<usize>,
    spec: &RegionSpec,
    extent_mm: f64,
    duty_cap_percent: f64,
) -> Result<Texture, SceneFileError> {
    Region {
        cx,
        kind: spec.check_fields(cx, prefix)?,
        prefix: prefix.into(),
        span,
        spec,
        length_mm: extent_mm,
        duty_cap_percent,
    }
    .texture()
}

/// One `[[region]]` being read: where it stands in the file and what bounds its values.
struct Region<'a> {
    cx: &'a Ctx<'a>,
    /// How errors name it: `region[i]` (then `region[i].field`).
    prefix: String,
    /// The whole table: errors about a missing field point here.
    span: Range<usize>,
    /// Its kind, checked, with no field of another kind.
    kind: &'static str,
    spec: &'a RegionSpec,
    /// The substrate's length: no boundary or wavelength beyond it.
    length_mm: f64,
    /// `[limits].max_duty_percent`, the default duty when below 40 %.
    duty_cap_percent: f64,
}

impl Region<'_> {
    /// `region[i].name`, as errors name a field.
    fn field(&self, name: &str) -> String {
        std::format!("{}.{name}", self.prefix)
    }

    /// The texture its kind and keys describe.
    fn texture(&self) -> Result<Texture, SceneFileError> {
        Ok(match self.kind {
            "constant" => self.constant()?,
            "grating" => self.grating()?,
            "material" => self.material()?,
            "random" => self.random()?,
            // `off`, the one other kind `check_fields` lets through: it takes no fields.
            _ => Texture::Off,
        })
    }

    /// Refused when this region would be one more than a scene holds ([`MAX_REGIONS`]).
    fn too_many(&self) -> SceneFileError {
        self.cx
            .err(self.span.clone(), "region", "more than 8 regions")
    }

    /// Where this region ends, µm: every region but the last says so, the last runs to the end.
    fn end_um(&self, last: bool) -> Result<Option<u32>, SceneFileError> {
        let field = self.field("until_mm");
        match (self.spec.until_mm.as_ref(), last) {
            (Some(u), false) => {
                let mm = self.cx.range(u, &field, 0.0, self.length_mm)?;
                Ok(Some(milli(mm)))
            }
            (None, false) => Err(self.cx.err(
                self.span.clone(),
                &field,
                "every region but the last needs `until_mm`",
            )),
            (Some(u), true) => Err(self.cx.err(
                u.span(),
                &field,
                "the last region runs to the end: remove `until_mm`",
            )),
            (None, true) => Ok(None),
        }
    }

    /// A field the kind cannot do without, within `lo ..= hi`.
    fn need(
        &self,
        v: &Option<Spanned<f64>>,
        name: &str,
        lo: f64,
        hi: f64,
    ) -> Result<f64, SceneFileError> {
        match v {
            Some(v) => self.cx.range(v, &self.field(name), lo, hi),
            None => Err(self.cx.err(
                self.span.clone(),
                &self.field(name),
                format_args!("kind `{}` needs `{name}`", self.kind),
            )),
        }
    }

    /// `duty_percent` as ‰: 40 % unless given, or the duty cap if that is lower.
    fn duty_permille(&self) -> Result<u16, SceneFileError> {
        self.cx.permille(
            &self.spec.duty_percent,
            &self.field("duty_percent"),
            0.1,
            40.0f64.min(self.duty_cap_percent),
        )
    }

    /// `min_speed_mm_s` as µm/s, 15 mm/s unless given.
    fn min_speed_um_s(&self) -> Result<u32, SceneFileError> {
        Ok(milli(self.cx.opt(
            &self.spec.min_speed_mm_s,
            &self.field("min_speed_mm_s"),
            0.0,
            1000.0,
            15.0,
        )?))
    }

    /// `amplitude_percent` as ‰, full amplitude unless given.
    fn amplitude_permille(&self) -> Result<u16, SceneFileError> {
        self.cx.permille(
            &self.spec.amplitude_percent,
            &self.field("amplitude_percent"),
            0.1,
            100.0,
        )
    }

    /// `f_b_hz` (required) as mHz.
    fn f_b_millihz(&self) -> Result<u32, SceneFileError> {
        Ok(milli(self.need(&self.spec.f_b_hz, "f_b_hz", 0.001, 1e6)?))
    }
}

/// One function per kind, reading the fields in a fixed order: with several bad values, the
/// first in that order is the one refused.
impl Region<'_> {
    /// `kind = "constant"`: one f_b and duty over the whole region.
    fn constant(&self) -> Result<Texture, SceneFileError> {
        Ok(Texture::Constant(BurstCommand {
            burst_millihz: self.f_b_millihz()?,
            duty_permille: self.duty_permille()?,
        }))
    }

    /// `kind = "grating"`: ridges every `wavelength_mm` (or `ridge_mm` + `groove_mm`).
    fn grating(&self) -> Result<Texture, SceneFileError> {
        let base = Grating::new(milli(self.wavelength_mm()?));
        let render = match self.spec.render.as_ref().map(|r| *r.get_ref()) {
            None | Some(RenderSpec::Position) => GratingRender::PositionPhase,
            Some(RenderSpec::Velocity) => GratingRender::VelocitySynthesis,
            Some(RenderSpec::Hybrid) => GratingRender::Hybrid,
        };
        let rearm_um = self.rearm_um(&base)?;
        Ok(Texture::Grating(Grating {
            duty_permille: self.duty_permille()?,
            min_speed_um_s: self.min_speed_um_s()?,
            amplitude_permille: self.amplitude_permille()?,
            render,
            rearm_um,
            ..base
        }))
    }

    /// A grating's period: `wavelength_mm`, or `ridge_mm` + `groove_mm`, never both.
    fn wavelength_mm(&self) -> Result<f64, SceneFileError> {
        let (cx, s) = (self.cx, self.spec);
        match (&s.wavelength_mm, &s.ridge_mm, &s.groove_mm) {
            (Some(w), None, None) => {
                cx.range(w, &self.field("wavelength_mm"), 0.001, self.length_mm)
            }
            (None, Some(ridge), Some(groove)) => {
                Ok(
                    cx.range(ridge, &self.field("ridge_mm"), 0.0, self.length_mm)?
                        + cx.range(groove, &self.field("groove_mm"), 0.0, self.length_mm)?,
                )
            }
            _ => Err(cx.err(
                self.span.clone(),
                &self.field("wavelength_mm"),
                "give `wavelength_mm`, or `ridge_mm` and `groove_mm`",
            )),
        }
    }

    /// A grating's `rearm_mm` as µm, the default for its period unless given.
    fn rearm_um(&self, base: &Grating) -> Result<u32, SceneFileError> {
        let Some(v) = &self.spec.rearm_mm else {
            return Ok(base.rearm_um);
        };
        // A fired ridge must re-arm before the next one: below half the period.
        let half_mm = base.wavelength_um as f64 / 2000.0;
        let mm = *v.get_ref();
        if !(0.0..half_mm).contains(&mm) {
            return Err(self.cx.err(
                v.span(),
                &self.field("rearm_mm"),
                format_args!("{mm} must be ≥ 0 and below half the period ({half_mm} mm)"),
            ));
        }
        Ok(milli(mm))
    }

    /// `kind = "material"`: the stick-slip frequency of a material at the hand's speed.
    fn material(&self) -> Result<Texture, SceneFileError> {
        let (cx, s) = (self.cx, self.spec);
        let delta_mu = self.delta_mu()?;
        Ok(Texture::Material(Material {
            delta_mu: delta_mu as f32,
            normal_force_n: cx.opt(
                &s.normal_force_n,
                &self.field("normal_force_n"),
                1e-3,
                100.0,
                1.0,
            )? as f32,
            mass_kg: (cx.opt(&s.mass_g, &self.field("mass_g"), 1e-3, 1e4, 1.0)? * 1e-3) as f32,
            stiffness_n_per_m: cx.opt(
                &s.stiffness_n_per_m,
                &self.field("stiffness_n_per_m"),
                1e-3,
                1e7,
                500.0,
            )? as f32,
            duty_permille: self.duty_permille()?,
            min_speed_um_s: self.min_speed_um_s()?,
        }))
    }

    /// A material's μs − μc: `delta_mu` as given, else from the eq. 12 parameters.
    fn delta_mu(&self) -> Result<f64, SceneFileError> {
        let s = self.spec;
        let eq12 = [
            ("e_object_pa", &s.e_object_pa),
            ("nu_object", &s.nu_object),
            ("e_skin_pa", &s.e_skin_pa),
            ("nu_skin", &s.nu_skin),
            ("sigma_um", &s.sigma_um),
            ("beta_um", &s.beta_um),
            ("shear_strength_diff_pa", &s.shear_strength_diff_pa),
        ];
        if let Some(d) = &s.delta_mu {
            // Both ways at once: one would be silently ignored, so neither is guessed.
            if let Some((name, v)) = eq12.iter().find_map(|(n, v)| v.as_ref().map(|v| (n, v))) {
                return Err(self.cx.err(
                    v.span(),
                    &self.field(name),
                    format_args!(
                        "give `delta_mu` or the eq. 12 parameters, not both (`{name}` would be ignored)"
                    ),
                ));
            }
            return self.cx.range(d, &self.field("delta_mu"), 0.0, 100.0);
        }
        // Neither `delta_mu` nor any eq. 12 parameter: name the simple way first.
        if eq12.iter().all(|(_, v)| v.is_none()) {
            return Err(self.cx.err(
                self.span.clone(),
                &self.field("delta_mu"),
                format_args!(
                    "kind `material` needs `delta_mu` (μs − μc, 0 to 100), or all of \
                     e_object_pa, nu_object, e_skin_pa, nu_skin, sigma_um, beta_um and \
                     shear_strength_diff_pa to compute it from eq. 12"
                ),
            ));
        }
        // Eq. 12: μs − μc = π (s − s') β / (E σ), 1/E = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o.
        let e_o = self.need(&s.e_object_pa, "e_object_pa", 1.0, 1e13)?;
        let nu_o = self.need(&s.nu_object, "nu_object", 0.0, 0.5)?;
        let e_s = self.need(&s.e_skin_pa, "e_skin_pa", 1.0, 1e13)?;
        let nu_s = self.need(&s.nu_skin, "nu_skin", 0.0, 0.5)?;
        let sigma = self.need(&s.sigma_um, "sigma_um", 1e-3, 1e4)?;
        let beta = self.need(&s.beta_um, "beta_um", 1e-3, 1e4)?;
        let ds = self.need(
            &s.shear_strength_diff_pa,
            "shear_strength_diff_pa",
            0.0,
            1e10,
        )?;
        let e = 1.0 / ((1.0 - nu_s * nu_s) / e_s + (1.0 - nu_o * nu_o) / e_o);
        let d = core::f64::consts::PI * ds * beta / (e * sigma);
        if !(d.is_finite() && d <= 100.0) {
            return Err(self.cx.err(
                self.span.clone(),
                &self.field("delta_mu"),
                format_args!("eq. 12 gives μs − μc = {d}, outside the allowed 0 to 100"),
            ));
        }
        Ok(d)
    }

    /// `kind = "random"`: f_b and amplitude drawn about central values once per burst.
    fn random(&self) -> Result<Texture, SceneFileError> {
        let (cx, s) = (self.cx, self.spec);
        Ok(Texture::Random(RandomBurst {
            center_millihz: self.f_b_millihz()?,
            spread_permille: cx
                .permille(&s.spread_percent, &self.field("spread_percent"), 0.0, 25.0)?
                .min(999),
            amplitude_permille: self.amplitude_permille()?,
            amplitude_spread_permille: cx.permille(
                &s.amplitude_spread_percent,
                &self.field("amplitude_spread_percent"),
                0.0,
                0.0,
            )?,
            duty_permille: self.duty_permille()?,
            seed: s.seed.as_ref().map_or(1, |s| *s.get_ref()),
        }))
    }
}
