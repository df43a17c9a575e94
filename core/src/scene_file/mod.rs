//! Scene files: the TOML a user writes, read into a [`Config`] with every error naming the file,
//! the line and the field. Host only (feature `scene-file`); the firmware receives compiled
//! configurations and ships the default scene built in ([`crate::default_config`], which
//! `scenes/default.toml` reproduces exactly — a test holds the two together).
//!
//! Reading is all-or-nothing: a file is parsed, every value converted and range-checked, then
//! dry-run through a [`Controller`] for the board, so a file that reads fine can still be refused
//! for the board it is loaded on (an f_b above its limit), with the region's line named.

extern crate std;

use core::fmt;
use core::ops::Range;
use std::string::{String, ToString};
use std::vec::Vec as StdVec;

use serde::Deserialize;
use toml::Spanned;

use crate::burst::{BurstCommand, BurstTimer, SafetyLimits};
use crate::controller::{ConfigError, Controller};
use crate::gate::DriveMode;
use crate::position::{Calibration, DEFAULT_RAIL_MARGIN_CODE};
use crate::region::DEFAULT_HYSTERESIS_UM;
use crate::scene::{Config, Scene};
use crate::texture::{Envelope, Grating, GratingRender, Lines, Material, RandomBurst, Texture};

/// A scene file that cannot be used, located in the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneFileError {
    /// The file's name as given.
    pub file: String,
    /// 1-based line.
    pub line: usize,
    /// 1-based column.
    pub column: usize,
    /// The field (or table) at fault.
    pub field: String,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for SceneFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: `{}`: {}",
            self.file, self.line, self.column, self.field, self.message
        )
    }
}

impl std::error::Error for SceneFileError {}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    substrate: Option<Spanned<Substrate>>,
    limits: Option<Spanned<Limits>>,
    drive: Option<Spanned<Drive>>,
    hysteresis_mm: Option<Spanned<f64>>,
    #[serde(default)]
    region: StdVec<Spanned<RegionSpec>>,
    lines: Option<Spanned<LinesSpec>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Substrate {
    length_mm: Spanned<f64>,
    code_at_start: u16,
    code_at_end: u16,
    rail_margin_code: Option<u16>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Limits {
    max_duty_percent: Option<Spanned<f64>>,
    max_on_time_ms: Option<Spanned<f64>>,
    stale_after_ms: Option<Spanned<f64>>,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum Drive {
    Standing,
    Progressive,
}

/// How a grating is rendered (`render = "position"`, the default, or `"velocity"`).
#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum RenderSpec {
    Position,
    Velocity,
}

#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
enum EnvelopeSpec {
    Triangle,
    Rectangle,
}

/// One `[[region]]` table. Flat rather than a tagged enum so every value keeps its span; which
/// fields a kind takes is checked by hand ([`RegionSpec::check_fields`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RegionSpec {
    kind: Spanned<String>,
    until_mm: Option<Spanned<f64>>,
    f_b_hz: Option<Spanned<f64>>,
    duty_percent: Option<Spanned<f64>>,
    wavelength_mm: Option<Spanned<f64>>,
    ridge_mm: Option<Spanned<f64>>,
    groove_mm: Option<Spanned<f64>>,
    min_speed_mm_s: Option<Spanned<f64>>,
    amplitude_percent: Option<Spanned<f64>>,
    render: Option<Spanned<RenderSpec>>,
    rearm_mm: Option<Spanned<f64>>,
    delta_mu: Option<Spanned<f64>>,
    // Eq. 12 parameters, used when `delta_mu` is absent.
    e_object_pa: Option<Spanned<f64>>,
    nu_object: Option<Spanned<f64>>,
    e_skin_pa: Option<Spanned<f64>>,
    nu_skin: Option<Spanned<f64>>,
    sigma_um: Option<Spanned<f64>>,
    beta_um: Option<Spanned<f64>>,
    shear_strength_diff_pa: Option<Spanned<f64>>,
    normal_force_n: Option<Spanned<f64>>,
    mass_g: Option<Spanned<f64>>,
    stiffness_n_per_m: Option<Spanned<f64>>,
    spread_percent: Option<Spanned<f64>>,
    amplitude_spread_percent: Option<Spanned<f64>>,
    seed: Option<Spanned<u64>>,
}

/// The region kinds and the fields each takes (besides `kind` and `until_mm`).
const KINDS: &[(&str, &[&str])] = &[
    ("off", &[]),
    ("constant", &["f_b_hz", "duty_percent"]),
    (
        "grating",
        &[
            "wavelength_mm",
            "ridge_mm",
            "groove_mm",
            "duty_percent",
            "min_speed_mm_s",
            "amplitude_percent",
            "render",
            "rearm_mm",
        ],
    ),
    (
        "material",
        &[
            "delta_mu",
            "e_object_pa",
            "nu_object",
            "e_skin_pa",
            "nu_skin",
            "sigma_um",
            "beta_um",
            "shear_strength_diff_pa",
            "normal_force_n",
            "mass_g",
            "stiffness_n_per_m",
            "duty_percent",
            "min_speed_mm_s",
        ],
    ),
    (
        "random",
        &[
            "f_b_hz",
            "spread_percent",
            "amplitude_percent",
            "amplitude_spread_percent",
            "duty_percent",
            "seed",
        ],
    ),
];

impl RegionSpec {
    /// Every optional field that is present, with its span.
    fn present(&self) -> StdVec<(&'static str, Range<usize>)> {
        let f = |name: &'static str, v: &Option<Spanned<f64>>| v.as_ref().map(|v| (name, v.span()));
        [
            f("f_b_hz", &self.f_b_hz),
            f("duty_percent", &self.duty_percent),
            f("wavelength_mm", &self.wavelength_mm),
            f("ridge_mm", &self.ridge_mm),
            f("groove_mm", &self.groove_mm),
            f("min_speed_mm_s", &self.min_speed_mm_s),
            f("amplitude_percent", &self.amplitude_percent),
            f("delta_mu", &self.delta_mu),
            f("e_object_pa", &self.e_object_pa),
            f("nu_object", &self.nu_object),
            f("e_skin_pa", &self.e_skin_pa),
            f("nu_skin", &self.nu_skin),
            f("sigma_um", &self.sigma_um),
            f("beta_um", &self.beta_um),
            f("shear_strength_diff_pa", &self.shear_strength_diff_pa),
            f("normal_force_n", &self.normal_force_n),
            f("mass_g", &self.mass_g),
            f("stiffness_n_per_m", &self.stiffness_n_per_m),
            f("spread_percent", &self.spread_percent),
            f("amplitude_spread_percent", &self.amplitude_spread_percent),
            self.seed.as_ref().map(|v| ("seed", v.span())),
            self.render.as_ref().map(|v| ("render", v.span())),
            f("rearm_mm", &self.rearm_mm),
        ]
        .into_iter()
        .flatten()
        .collect()
    }

    /// The kind, checked, with a field that does not belong to it refused at its span.
    fn check_fields(&self, cx: &Ctx<'_>, i: usize) -> Result<&'static str, SceneFileError> {
        let kind = self.kind.get_ref().as_str();
        let Some((name, allowed)) = KINDS.iter().find(|(k, _)| *k == kind) else {
            let names: StdVec<&str> = KINDS.iter().map(|(k, _)| *k).collect();
            return Err(cx.err(
                self.kind.span(),
                &std::format!("region[{i}].kind"),
                format_args!(
                    "unknown kind `{kind}`, expected one of {}",
                    names.join(", ")
                ),
            ));
        };
        for (field, span) in self.present() {
            if !allowed.contains(&field) {
                return Err(cx.err(
                    span,
                    &std::format!("region[{i}].{field}"),
                    format_args!("`{field}` is not a field of kind `{kind}`"),
                ));
            }
        }
        Ok(name)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LinesSpec {
    positions_mm: Spanned<StdVec<f64>>,
    pulse_ms: Option<Spanned<f64>>,
    envelope: Option<EnvelopeSpec>,
    amplitude_percent: Option<Spanned<f64>>,
    rearm_mm: Option<Spanned<f64>>,
}

/// Where each part of a parsed file sits, to locate errors the controller finds later.
#[derive(Clone, Debug, Default)]
struct Spans {
    substrate: Option<Range<usize>>,
    limits: Option<Range<usize>>,
    lines: Option<Range<usize>>,
    regions: StdVec<Range<usize>>,
}

/// A scene file read and converted, with the spans needed to locate later errors.
#[derive(Clone, Debug)]
pub struct SceneDoc {
    file: String,
    text: String,
    spans: Spans,
    /// The configuration the file describes.
    pub config: Config,
}

struct Ctx<'a> {
    file: &'a str,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, span: Range<usize>, field: &str, message: impl ToString) -> SceneFileError {
        let start = span.start.min(self.text.len());
        let before = &self.text[..start];
        let line = before.matches('\n').count() + 1;
        let column = start - before.rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;
        SceneFileError {
            file: self.file.to_string(),
            line,
            column,
            field: field.to_string(),
            message: message.to_string(),
        }
    }

    /// `v` within `lo ..= hi`, else an error naming `field` at its span.
    fn range(
        &self,
        v: &Spanned<f64>,
        field: &str,
        lo: f64,
        hi: f64,
    ) -> Result<f64, SceneFileError> {
        let x = *v.get_ref();
        if !(x.is_finite() && lo <= x && x <= hi) {
            return Err(self.err(
                v.span(),
                field,
                format_args!("{x} is outside {lo} ..= {hi}"),
            ));
        }
        Ok(x)
    }

    fn opt(
        &self,
        v: &Option<Spanned<f64>>,
        field: &str,
        lo: f64,
        hi: f64,
        default: f64,
    ) -> Result<f64, SceneFileError> {
        v.as_ref()
            .map_or(Ok(default), |v| self.range(v, field, lo, hi))
    }

    /// A percentage as ‰.
    fn permille(
        &self,
        v: &Option<Spanned<f64>>,
        field: &str,
        lo: f64,
        default: f64,
    ) -> Result<u16, SceneFileError> {
        Ok((self.opt(v, field, lo, 100.0, default)? * 10.0).round() as u16)
    }
}

/// Parses and converts a scene file; `file` names it in errors. Board limits are not checked
/// here: see [`load_for_board`].
pub fn parse(file: &str, text: &str) -> Result<SceneDoc, SceneFileError> {
    let cx = Ctx { file, text };
    let doc: File = toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        // The whole line holding the error: its key names the field.
        let start = span.start.min(text.len());
        let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
        let line_text = text[line_start..].split('\n').next().unwrap_or("");
        let field = line_text.split('=').next().unwrap_or("").trim();
        let field = if field.is_empty() { "(file)" } else { field };
        cx.err(span, field, e.message())
    })?;
    let mut spans = Spans::default();

    let calibration = match &doc.substrate {
        None => Calibration::default(),
        Some(s) => {
            spans.substrate = Some(s.span());
            let s = s.get_ref();
            let length_mm = cx.range(&s.length_mm, "substrate.length_mm", 1.0, 1000.0)?;
            Calibration {
                code_at_start: s.code_at_start,
                code_at_end: s.code_at_end,
                length_um: (length_mm * 1000.0).round() as u32,
                rail_margin_code: s.rail_margin_code.unwrap_or(DEFAULT_RAIL_MARGIN_CODE),
            }
        }
    };
    let length_mm = calibration.length_um as f64 / 1000.0;

    let defaults = SafetyLimits::default();
    let (limits, stale_after_us) = match &doc.limits {
        None => (defaults, 5_000),
        Some(l) => {
            spans.limits = Some(l.span());
            let l = l.get_ref();
            let duty = cx.opt(
                &l.max_duty_percent,
                "limits.max_duty_percent",
                0.1,
                100.0,
                50.0,
            )?;
            let on = cx.opt(
                &l.max_on_time_ms,
                "limits.max_on_time_ms",
                0.001,
                1000.0,
                50.0,
            )?;
            let stale = cx.opt(&l.stale_after_ms, "limits.stale_after_ms", 0.2, 1000.0, 5.0)?;
            let limits = SafetyLimits {
                max_duty_permille: (duty * 10.0).round() as u16,
                max_on_time_us: (on * 1000.0).round() as u32,
            };
            (limits, (stale * 1000.0).round() as u32)
        }
    };
    let duty_cap_percent = limits.max_duty_permille as f64 / 10.0;

    let hysteresis_um = match &doc.hysteresis_mm {
        None => DEFAULT_HYSTERESIS_UM,
        Some(h) => (cx.range(h, "hysteresis_mm", 0.0, 5.0)? * 1000.0).round() as u32,
    };

    if doc.region.is_empty() {
        return Err(cx.err(0..0, "region", "a scene needs at least one [[region]]"));
    }
    let mut boundaries_um = heapless::Vec::new();
    let mut textures = heapless::Vec::new();
    let n = doc.region.len();
    for (i, r) in doc.region.iter().enumerate() {
        spans.regions.push(r.span());
        let field = |name: &str| std::format!("region[{i}].{name}");
        let spec = r.get_ref();
        let kind = spec.check_fields(&cx, i)?;
        match (spec.until_mm.as_ref(), i + 1 == n) {
            (Some(u), false) => {
                let um = (cx.range(u, &field("until_mm"), 0.0, length_mm)? * 1000.0).round() as u32;
                boundaries_um
                    .push(um)
                    .map_err(|_| cx.err(r.span(), "region", "more than 8 regions"))?;
            }
            (None, false) => {
                return Err(cx.err(
                    r.span(),
                    &field("until_mm"),
                    "every region but the last needs `until_mm`",
                ))
            }
            (Some(u), true) => {
                return Err(cx.err(
                    u.span(),
                    &field("until_mm"),
                    "the last region runs to the end: remove `until_mm`",
                ))
            }
            (None, true) => {}
        }
        let duty = |d: &Option<Spanned<f64>>| {
            cx.permille(
                d,
                &field("duty_percent"),
                0.1,
                40.0f64.min(duty_cap_percent),
            )
        };
        let speed = |s: &Option<Spanned<f64>>| -> Result<u32, SceneFileError> {
            Ok((cx.opt(s, &field("min_speed_mm_s"), 0.0, 1000.0, 15.0)? * 1000.0).round() as u32)
        };
        let need = |v: &Option<Spanned<f64>>, name: &str, lo: f64, hi: f64| match v {
            Some(v) => cx.range(v, &field(name), lo, hi),
            None => Err(cx.err(
                r.span(),
                &field(name),
                format_args!("kind `{kind}` needs `{name}`"),
            )),
        };
        let texture = match kind {
            "constant" => Texture::Constant(BurstCommand {
                burst_millihz: (need(&spec.f_b_hz, "f_b_hz", 0.001, 1e6)? * 1000.0).round() as u32,
                duty_permille: duty(&spec.duty_percent)?,
            }),
            "grating" => {
                let wavelength = match (&spec.wavelength_mm, &spec.ridge_mm, &spec.groove_mm) {
                    (Some(w), None, None) => {
                        cx.range(w, &field("wavelength_mm"), 0.001, length_mm)?
                    }
                    (None, Some(ridge), Some(groove)) => {
                        cx.range(ridge, &field("ridge_mm"), 0.0, length_mm)?
                            + cx.range(groove, &field("groove_mm"), 0.0, length_mm)?
                    }
                    _ => {
                        return Err(cx.err(
                            r.span(),
                            &field("wavelength_mm"),
                            "give `wavelength_mm`, or `ridge_mm` and `groove_mm`",
                        ))
                    }
                };
                let base = Grating::new((wavelength * 1000.0).round() as u32);
                let render = match spec.render.as_ref().map(|r| *r.get_ref()) {
                    None | Some(RenderSpec::Position) => GratingRender::PositionPhase,
                    Some(RenderSpec::Velocity) => GratingRender::VelocitySynthesis,
                };
                // A fired ridge must re-arm before the next one: below half the period.
                let rearm_um = match &spec.rearm_mm {
                    Some(v) => {
                        let half_mm = base.wavelength_um as f64 / 2000.0;
                        let mm = *v.get_ref();
                        if !(0.0..half_mm).contains(&mm) {
                            return Err(cx.err(
                                v.span(),
                                &field("rearm_mm"),
                                format_args!(
                                    "{mm} must be ≥ 0 and below half the period ({half_mm} mm)"
                                ),
                            ));
                        }
                        (mm * 1000.0).round() as u32
                    }
                    None => base.rearm_um,
                };
                Texture::Grating(Grating {
                    duty_permille: duty(&spec.duty_percent)?,
                    min_speed_um_s: speed(&spec.min_speed_mm_s)?,
                    amplitude_permille: cx.permille(
                        &spec.amplitude_percent,
                        &field("amplitude_percent"),
                        0.1,
                        100.0,
                    )?,
                    render,
                    rearm_um,
                    ..base
                })
            }
            "material" => {
                let delta_mu = match &spec.delta_mu {
                    Some(d) => cx.range(d, &field("delta_mu"), 0.0, 100.0)?,
                    None => {
                        // Eq. 12: μs − μc = π (s − s') β / (E σ), 1/E = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o.
                        let e_o = need(&spec.e_object_pa, "e_object_pa", 1.0, 1e13)?;
                        let nu_o = need(&spec.nu_object, "nu_object", 0.0, 0.5)?;
                        let e_s = need(&spec.e_skin_pa, "e_skin_pa", 1.0, 1e13)?;
                        let nu_s = need(&spec.nu_skin, "nu_skin", 0.0, 0.5)?;
                        let sigma = need(&spec.sigma_um, "sigma_um", 1e-3, 1e4)?;
                        let beta = need(&spec.beta_um, "beta_um", 1e-3, 1e4)?;
                        let ds = need(
                            &spec.shear_strength_diff_pa,
                            "shear_strength_diff_pa",
                            0.0,
                            1e10,
                        )?;
                        let e = 1.0 / ((1.0 - nu_s * nu_s) / e_s + (1.0 - nu_o * nu_o) / e_o);
                        let d = core::f64::consts::PI * ds * beta / (e * sigma);
                        if !(d.is_finite() && d <= 100.0) {
                            return Err(cx.err(
                                r.span(),
                                &field("delta_mu"),
                                format_args!("eq. 12 gives μs − μc = {d}, outside 0 ..= 100"),
                            ));
                        }
                        d
                    }
                };
                Texture::Material(Material {
                    delta_mu: delta_mu as f32,
                    normal_force_n: cx.opt(
                        &spec.normal_force_n,
                        &field("normal_force_n"),
                        1e-3,
                        100.0,
                        1.0,
                    )? as f32,
                    mass_kg: (cx.opt(&spec.mass_g, &field("mass_g"), 1e-3, 1e4, 1.0)? * 1e-3)
                        as f32,
                    stiffness_n_per_m: cx.opt(
                        &spec.stiffness_n_per_m,
                        &field("stiffness_n_per_m"),
                        1e-3,
                        1e7,
                        500.0,
                    )? as f32,
                    duty_permille: duty(&spec.duty_percent)?,
                    min_speed_um_s: speed(&spec.min_speed_mm_s)?,
                })
            }
            "random" => Texture::Random(RandomBurst {
                center_millihz: (need(&spec.f_b_hz, "f_b_hz", 0.001, 1e6)? * 1000.0).round() as u32,
                spread_permille: cx
                    .permille(&spec.spread_percent, &field("spread_percent"), 0.0, 25.0)?
                    .min(999),
                amplitude_permille: cx.permille(
                    &spec.amplitude_percent,
                    &field("amplitude_percent"),
                    0.1,
                    100.0,
                )?,
                amplitude_spread_permille: cx.permille(
                    &spec.amplitude_spread_percent,
                    &field("amplitude_spread_percent"),
                    0.0,
                    0.0,
                )?,
                duty_permille: duty(&spec.duty_percent)?,
                seed: spec.seed.as_ref().map_or(1, |s| *s.get_ref()),
            }),
            _ => Texture::Off,
        };
        textures
            .push(texture)
            .map_err(|_| cx.err(r.span(), "region", "more than 8 regions"))?;
    }

    let mut lines = Lines::default();
    if let Some(l) = &doc.lines {
        spans.lines = Some(l.span());
        let l = l.get_ref();
        for &p in l.positions_mm.get_ref() {
            let um = (p * 1000.0).round();
            if !(p.is_finite() && um >= 0.0 && um <= u32::MAX as f64) {
                return Err(cx.err(
                    l.positions_mm.span(),
                    "lines.positions_mm",
                    format_args!("{p} is not a position"),
                ));
            }
            lines.positions_um.push(um as u32).map_err(|_| {
                cx.err(
                    l.positions_mm.span(),
                    "lines.positions_mm",
                    "more than 16 lines",
                )
            })?;
        }
        lines.pulse_us =
            (cx.opt(&l.pulse_ms, "lines.pulse_ms", 0.001, 1000.0, 10.0)? * 1000.0).round() as u32;
        lines.envelope = match l.envelope {
            None | Some(EnvelopeSpec::Triangle) => Envelope::Triangular,
            Some(EnvelopeSpec::Rectangle) => Envelope::Rectangular,
        };
        lines.amplitude_permille =
            cx.permille(&l.amplitude_percent, "lines.amplitude_percent", 0.1, 100.0)?;
        lines.hysteresis_um =
            (cx.opt(&l.rearm_mm, "lines.rearm_mm", 0.0, 5.0, 0.2)? * 1000.0).round() as u32;
    }

    let drive = match doc.drive.as_ref().map(|d| *d.get_ref()) {
        None | Some(Drive::Standing) => DriveMode::Standing,
        Some(Drive::Progressive) => DriveMode::Progressive,
    };
    let config = Config {
        calibration,
        scene: Scene {
            boundaries_um,
            textures,
            hysteresis_um,
            lines,
            drive,
        },
        limits,
        stale_after_us,
    };
    Ok(SceneDoc {
        file: file.to_string(),
        text: text.to_string(),
        spans,
        config,
    })
}

impl SceneDoc {
    /// Locates an error the controller found in this file's configuration.
    pub fn locate(&self, e: &ConfigError) -> SceneFileError {
        let cx = Ctx {
            file: &self.file,
            text: &self.text,
        };
        let region = |i: u8| self.spans.regions.get(i as usize).cloned().unwrap_or(0..0);
        let (span, field) = match e {
            ConfigError::Calibration(_) => (
                self.spans.substrate.clone().unwrap_or(0..0),
                "substrate".to_string(),
            ),
            ConfigError::Limits(_) | ConfigError::StaleLimit { .. } => (
                self.spans.limits.clone().unwrap_or(0..0),
                "limits".to_string(),
            ),
            ConfigError::Region(re) => {
                use crate::region::RegionError as R;
                match re {
                    R::Unsorted { index, .. } | R::OutOfRange { index, .. } => {
                        (region(*index), std::format!("region[{index}].until_mm"))
                    }
                    R::TooNarrow { index, .. } => (region(*index), std::format!("region[{index}]")),
                    _ => (0..0, "hysteresis_mm".to_string()),
                }
            }
            ConfigError::Texture { region: i, .. }
            | ConfigError::TextureParams { region: i, .. } => {
                (region(*i), std::format!("region[{i}]"))
            }
            ConfigError::Lines(_) | ConfigError::LinePulse(_) => (
                self.spans.lines.clone().unwrap_or(0..0),
                "lines".to_string(),
            ),
            _ => (0..0, "(file)".to_string()),
        };
        // The located field already names the region (or the lines), so the sentence is the
        // inner error's; every other refusal reads whole.
        match e {
            ConfigError::Texture { error, .. } | ConfigError::LinePulse(error) => {
                cx.err(span, &field, error)
            }
            ConfigError::TextureParams { error, .. } => cx.err(span, &field, error),
            _ => cx.err(span, &field, e),
        }
    }
}

/// Reads a scene file and checks it against a board: the configuration, ready to load.
pub fn load_for_board(
    file: &str,
    text: &str,
    timer: BurstTimer,
    sample_period_us: u32,
) -> Result<Config, SceneFileError> {
    let doc = parse(file, text)?;
    let mut dry = Controller::new(timer, sample_period_us).map_err(|e| doc.locate(&e))?;
    dry.load(&doc.config).map_err(|e| doc.locate(&e))?;
    Ok(doc.config)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TIMER: BurstTimer = BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 5_000,
    };
    const DEFAULT: &str = include_str!("../../../scenes/default.toml");

    #[test]
    fn default_file_is_the_built_in_default() {
        let cfg = load_for_board("default.toml", DEFAULT, TIMER, 100).unwrap();
        assert_eq!(cfg, crate::default_config());
    }

    fn err(text: &str) -> SceneFileError {
        load_for_board("bad.toml", text, TIMER, 100).unwrap_err()
    }

    #[test]
    fn unknown_field_is_located() {
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = 80\ncolour = \"red\"\n");
        assert_eq!((e.line, e.field.as_str()), (4, "colour"), "{e}");
        assert!(e.message.contains("colour"), "{e}");
        assert!(e.to_string().starts_with("bad.toml:4:"), "{e}");
    }

    #[test]
    fn out_of_range_value_is_located() {
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = -3\n");
        assert_eq!((e.line, e.field.as_str()), (3, "region[0].f_b_hz"), "{e}");
    }

    #[test]
    fn board_limit_is_located_at_the_region() {
        let text = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n[[region]]\nkind = \"constant\"\nf_b_hz = 9000\n";
        let e = err(text);
        assert_eq!((e.line, e.field.as_str()), (6, "region[1]"), "{e}");
        assert!(e.message.contains("above this board's limit"), "{e}");
    }

    #[test]
    fn unsorted_boundaries_are_located() {
        let text = "[[region]]\nkind = \"off\"\nuntil_mm = 30\n[[region]]\nkind = \"off\"\nuntil_mm = 20\n[[region]]\nkind = \"off\"\n";
        let e = err(text);
        assert_eq!((e.line, e.field.as_str()), (4, "region[1].until_mm"), "{e}");
    }

    #[test]
    fn malformed_toml_is_located() {
        let e = err("[[region]]\nkind = \"constant\nf_b_hz = 80\n");
        assert_eq!(e.line, 2, "{e}");
    }

    #[test]
    fn field_of_another_kind_and_unknown_kind_are_refused() {
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = 80\nwavelength_mm = 1\n");
        assert_eq!(
            (e.line, e.field.as_str()),
            (4, "region[0].wavelength_mm"),
            "{e}"
        );
        let e = err("[[region]]\nkind = \"velvet\"\n");
        assert_eq!((e.line, e.field.as_str()), (2, "region[0].kind"), "{e}");
        assert!(e.message.contains("grating"), "{e}");
    }

    #[test]
    fn grating_render_and_rearm() {
        let g = |text: &str| match load_for_board("t.toml", text, TIMER, 100)
            .map(|c| c.scene.textures[0])
        {
            Ok(Texture::Grating(g)) => g,
            other => panic!("{other:?}"),
        };
        let d = g("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\n");
        assert_eq!((d.render, d.rearm_um), (GratingRender::PositionPhase, 100));
        let v = g("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"velocity\"\nrearm_mm = 0.2\n");
        assert_eq!(
            (v.render, v.rearm_um),
            (GratingRender::VelocitySynthesis, 200)
        );
        let e = err("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrearm_mm = 0.5\n");
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].rearm_mm"), "{e}");
        assert!(e.message.contains("half the period"), "{e}");
        let e = err("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"phase\"\n");
        assert_eq!(e.line, 4, "{e}");
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = 80\nrender = \"velocity\"\n");
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].render"), "{e}");
    }

    /// Every shipped scene loads on a 16-bit and a 32-bit burst timer.
    #[test]
    fn shipped_scenes_load() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                let t16 = BurstTimer {
                    clock_hz: 150_000_000,
                    counter_bits: 16,
                    max_burst_hz: 5_000,
                };
                for timer in [TIMER, t16] {
                    load_for_board(&path.display().to_string(), &text, timer, 100)
                        .unwrap_or_else(|e| panic!("{e}"));
                }
                n += 1;
            }
        }
        assert!(n >= 5, "{n} scenes");
    }
}
