//! The shape of a scene file: the TOML tables and keys it may hold, as read by serde before any
//! value is converted, and which fields each region kind takes. Every value keeps its span
//! (`Spanned`) so a later refusal can point at it.

extern crate std;

use core::ops::Range;
use std::format;
use std::string::{String, ToString};
use std::vec::Vec as StdVec;

use serde::Deserialize;
use toml::Spanned;

use super::ctx::Ctx;
use super::SceneFileError;

/// The whole file: every table optional but `[[region]]`, which [`super::regions`] requires.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct File {
    pub(super) substrate: Option<Spanned<Substrate>>,
    pub(super) limits: Option<Spanned<Limits>>,
    pub(super) drive: Option<Spanned<Drive>>,
    pub(super) hysteresis_mm: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) region: StdVec<Spanned<RegionSpec>>,
    pub(super) lines: Option<Spanned<LinesSpec>>,
}

/// Reads the TOML into a [`File`]. A syntax error, an unknown key or a value of the wrong type is
/// located where the `toml` crate points; an unknown key or value is named with the nearest
/// one the table takes, or a short list of them ([`super::keys::unknown`]).
pub(super) fn read(cx: &Ctx<'_>) -> Result<File, SceneFileError> {
    read_as(cx)
}

/// Reads the TOML into any of the reader's file shapes (1D [`File`], 2D `spec2d::File2d`),
/// with [`read`]'s located errors and sentences.
pub(super) fn read_as<T: serde::de::DeserializeOwned>(cx: &Ctx<'_>) -> Result<T, SceneFileError> {
    let text = cx.text;
    toml::from_str(text).map_err(|e| {
        let span = e.span().unwrap_or(0..0);
        // The whole line holding the error: its key names the field.
        let start = span.start.min(text.len());
        let line_start = text[..start].rfind('\n').map_or(0, |i| i + 1);
        let line_text = text[line_start..].split('\n').next().unwrap_or("");
        let key = line_text.split('=').next().unwrap_or("").trim();
        let header = key.starts_with('[');
        let field = if key.is_empty() {
            "(file)".to_string()
        } else if header {
            // A table's header (`[[regin]]  # …`): the table's name, as its keys are named.
            let inside = key.split('#').next().unwrap_or("");
            inside
                .trim_matches(|c: char| c == '[' || c == ']' || c.is_whitespace())
                .to_string()
        } else if text.parse::<toml::Table>().is_err() {
            // Not TOML: the tables are not known, only the line the parser stopped at.
            key.to_string()
        } else {
            qualified(&text[..line_start], key)
        };
        match super::keys::unknown(e.message(), region_kind_at(text, start).as_deref()) {
            Some(sentence) => cx.err(span, &field, sentence),
            None => cx.err(span, &field, e.message()),
        }
    })
}

/// `key` as the checks after the read name a field: under the table the text `before` it last
/// opened (`[limits]` → `limits.max_duty`, the third `[[window]]` → `window[2].outline`), bare
/// at the top.
fn qualified(before: &str, key: &str) -> String {
    let headers: StdVec<(&str, bool)> = before.lines().filter_map(header).collect();
    match headers.last() {
        None => key.to_string(),
        Some(&(name, false)) => format!("{name}.{key}"),
        Some(&(name, true)) => {
            // The array's index: how many of its headers came before, this one included.
            let index = headers.iter().filter(|&&h| h == (name, true)).count() - 1;
            format!("{name}[{index}].{key}")
        }
    }
}

/// A table's header line: `[name]` (false) or `[[name]]` (true), its comment left off.
fn header(line: &str) -> Option<(&str, bool)> {
    let line = line.split('#').next().unwrap_or("").trim();
    if let Some(name) = line.strip_prefix("[[").and_then(|l| l.strip_suffix("]]")) {
        return Some((name.trim(), true));
    }
    line.strip_prefix('[')
        .and_then(|l| l.strip_suffix(']'))
        .map(|name| (name.trim(), false))
}

/// The `kind` of the `[[region]]` table that holds byte `at`, if the file reads that far: the
/// last region starting at or before it (a key in a later table is not a region's, and the
/// caller only asks about a region's key).
fn region_kind_at(text: &str, at: usize) -> Option<String> {
    /// Every region's kind, and nothing else checked: the file failed the strict read.
    #[derive(Deserialize)]
    struct Loose {
        #[serde(default)]
        region: StdVec<Spanned<LooseRegion>>,
    }
    #[derive(Deserialize)]
    struct LooseRegion {
        kind: Option<String>,
    }
    let loose: Loose = toml::from_str(text).ok()?;
    loose
        .region
        .iter()
        .rfind(|r| r.span().start <= at)
        .and_then(|r| r.get_ref().kind.clone())
}

/// The fields kind `kind` takes besides `kind` and `until_mm`; None for no kind.
pub(super) fn kind_fields(kind: &str) -> Option<&'static [&'static str]> {
    KINDS.iter().find(|(k, _)| *k == kind).map(|(_, f)| *f)
}

/// `[substrate]`: the rheostat calibration.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Substrate {
    pub(super) length_mm: Spanned<f64>,
    pub(super) code_at_start: Spanned<u16>,
    pub(super) code_at_end: Spanned<u16>,
    pub(super) rail_margin_code: Option<Spanned<u16>>,
}

/// `[limits]`: the carrier caps and the stale-sensor limit.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct Limits {
    pub(super) max_duty_percent: Option<Spanned<f64>>,
    pub(super) max_level_percent: Option<Spanned<f64>>,
    pub(super) max_on_time_ms: Option<Spanned<f64>>,
    pub(super) stale_after_ms: Option<Spanned<f64>>,
}

/// `drive = "standing"` (the default) or `"progressive"`.
#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
pub(super) enum Drive {
    Standing,
    Progressive,
}

/// How a grating is rendered (`render = "position"`, the default, `"hybrid"` or
/// `"velocity"`).
#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
pub(super) enum RenderSpec {
    Position,
    Hybrid,
    Velocity,
}

/// The lines' pulse shape (`envelope = "triangle"`, the default, or `"rectangle"`).
#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "kebab-case")]
pub(super) enum EnvelopeSpec {
    Triangle,
    Rectangle,
}

/// One `[[region]]` table. Flat rather than a tagged enum so every value keeps its span; which
/// fields a kind takes is checked by hand ([`RegionSpec::check_fields`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RegionSpec {
    pub(super) kind: Spanned<String>,
    pub(super) until_mm: Option<Spanned<f64>>,
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
    // Eq. 12 parameters, used when `delta_mu` is absent.
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
    pub(super) fn present(&self) -> StdVec<(&'static str, Range<usize>)> {
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
    /// `prefix` names the table in errors (`region[1]`, `window[0]`).
    pub(super) fn check_fields(
        &self,
        cx: &Ctx<'_>,
        prefix: &str,
    ) -> Result<&'static str, SceneFileError> {
        let kind = self.kind.get_ref().as_str();
        let Some((name, allowed)) = KINDS.iter().find(|(k, _)| *k == kind) else {
            let names: StdVec<&str> = KINDS.iter().map(|(k, _)| *k).collect();
            return Err(cx.err(
                self.kind.span(),
                &std::format!("{prefix}.kind"),
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
                    &std::format!("{prefix}.{field}"),
                    format_args!("`{field}` is not a field of kind `{kind}`"),
                ));
            }
        }
        Ok(name)
    }
}

/// `[lines]`: tangible lines drawn over the regions.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct LinesSpec {
    /// Each position with its own span, so a bad one is located at itself.
    pub(super) positions_mm: Spanned<StdVec<Spanned<f64>>>,
    pub(super) pulse_ms: Option<Spanned<f64>>,
    pub(super) envelope: Option<EnvelopeSpec>,
    pub(super) amplitude_percent: Option<Spanned<f64>>,
    pub(super) rearm_mm: Option<Spanned<f64>>,
}
