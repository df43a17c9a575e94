//! Scene files: the TOML a user writes, read into a [`Config`] with every error naming the file,
//! the line and the field. Host only (feature `scene-file`); the firmware receives compiled
//! configurations and ships the default scene built in ([`crate::default_config`], which
//! `scenes/default.toml` reproduces exactly — a test holds the two together).
//!
//! Reading is all-or-nothing: a file is parsed, every value converted and range-checked, then
//! dry-run through a [`Controller`] for the board, so a file that reads fine can still be refused
//! for the board it is loaded on (an f_b above its limit), with the region's line named.
//!
//! - `spec.rs`: the file's shape (tables, keys, which fields each region kind takes);
//! - `sections.rs`: `[substrate]`, `[limits]`, `hysteresis_mm`, `drive` and `[lines]` converted;
//! - `regions.rs`: the `[[region]]` tables, one function per texture kind;
//! - `ctx.rs`: errors located in the file, and the range checks that raise them;
//! - `keys.rs`: the keys each table takes, and the sentence for one it does not ("did you
//!   mean");
//! - `write.rs`: a configuration written back as a scene file;
//! - 2D scenes (issue #36, a file with `[sensor] kind = "4-wire"`): `spec2d.rs` their shape,
//!   `plane2d.rs` [`sensor_of`]'s reading and the conversion to a [`crate::plane::Config2d`]
//!   (dry-run through a [`crate::plane::Controller2d`], its refusals located), `write2d.rs`
//!   the writer. The 1D reader refuses a 2D file at its `[sensor]`, the 2D reader a 1D file.
//!
//! Every refusal points at `file:line:col` of the value at fault (an unknown key: the key), the
//! board's checks included (an f_b above the board's limit at its `f_b_hz`, a boundary before
//! the one before it at its `until_mm`); only what no single key holds (a missing key, a
//! calibration as a whole) points at its table.

extern crate std;

mod ctx;
mod keys;
mod plane2d;
mod regions;
mod sections;
mod spec;
mod spec2d;
mod write;
mod write2d;

pub use keys::{keys, TABLES, TABLES_2D};
pub use write::to_scene_file;
pub use write2d::to_scene_file_2d;

use core::fmt;
use core::ops::Range;
use std::collections::BTreeMap;
use std::string::{String, ToString};

use crate::burst::BurstTimer;
use crate::controller::{ConfigError, Controller};
use crate::scene::{Config, Scene};

use ctx::Ctx;
use spec::File;

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

/// Where each table and value of a parsed file sits, by the name a refusal gives it
/// (`region[1]`, `region[1].f_b_hz`, `lines.positions_mm[2]`), to locate the errors the
/// controller finds later at the value they are about.
#[derive(Clone, Debug, Default)]
struct Spans(BTreeMap<String, Range<usize>>);

impl Spans {
    fn of(doc: &File) -> Self {
        let mut m = BTreeMap::new();
        let mut put = |name: String, span: Range<usize>| {
            m.insert(name, span);
        };
        if let Some(h) = &doc.hysteresis_mm {
            put("hysteresis_mm".into(), h.span());
        }
        if let Some(t) = &doc.substrate {
            put("substrate".into(), t.span());
            let s = t.get_ref();
            put("substrate.length_mm".into(), s.length_mm.span());
            put("substrate.code_at_start".into(), s.code_at_start.span());
            put("substrate.code_at_end".into(), s.code_at_end.span());
            if let Some(m) = &s.rail_margin_code {
                put("substrate.rail_margin_code".into(), m.span());
            }
        }
        for (i, r) in doc.region.iter().enumerate() {
            put(std::format!("region[{i}]"), r.span());
            let spec = r.get_ref();
            if let Some(u) = &spec.until_mm {
                put(std::format!("region[{i}].until_mm"), u.span());
            }
            for (name, span) in spec.present() {
                put(std::format!("region[{i}].{name}"), span);
            }
        }
        if let Some(t) = &doc.lines {
            put("lines".into(), t.span());
            let l = t.get_ref();
            put("lines.positions_mm".into(), l.positions_mm.span());
            for (j, p) in l.positions_mm.get_ref().iter().enumerate() {
                put(std::format!("lines.positions_mm[{j}]"), p.span());
            }
            for (name, v) in [
                ("pulse_ms", &l.pulse_ms),
                ("amplitude_percent", &l.amplitude_percent),
                ("rearm_mm", &l.rearm_mm),
            ] {
                if let Some(v) = v {
                    put(std::format!("lines.{name}"), v.span());
                }
            }
        }
        let mut spans = Spans(m);
        spans.put_limits(doc.limits.as_ref());
        spans
    }

    /// `[limits]` and each key it writes (1D and 2D files share the table).
    fn put_limits(&mut self, limits: Option<&toml::Spanned<spec::Limits>>) {
        let Some(t) = limits else { return };
        self.0.insert("limits".into(), t.span());
        let l = t.get_ref();
        for (name, v) in [
            ("max_duty_percent", &l.max_duty_percent),
            ("max_level_percent", &l.max_level_percent),
            ("max_on_time_ms", &l.max_on_time_ms),
            ("stale_after_ms", &l.stale_after_ms),
        ] {
            if let Some(v) = v {
                self.0.insert(std::format!("limits.{name}"), v.span());
            }
        }
    }

    /// The first of `names` the file writes, with its span; else `table` (the key was left to
    /// its default, or no single key holds the fault); else the whole file.
    fn find(&self, names: &[String], table: &str) -> (Range<usize>, String) {
        names
            .iter()
            .chain(core::iter::once(&table.to_string()))
            .find_map(|n| self.0.get(n).map(|s| (s.clone(), n.clone())))
            .unwrap_or((0..0, "(file)".to_string()))
    }
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

/// Parses and converts a scene file; `file` names it in errors. Board limits are not checked
/// here: see [`load_for_board`].
///
/// The sections are read in a fixed order (substrate, limits, hysteresis, regions, lines), and
/// the first bad value met is the one refused.
pub fn parse(file: &str, text: &str) -> Result<SceneDoc, SceneFileError> {
    let cx = Ctx { file, text };
    // A 2D file is refused at its sensor, before its tables read as unknown 1D keys.
    if let (SensorKind::FourWire, Some(kind)) = plane2d::sensor(&cx)? {
        return Err(plane2d::refuse_in_1d(&cx, kind));
    }
    let doc = spec::read(&cx)?;

    let calibration = sections::calibration(&cx, doc.substrate.as_ref())?;
    let (limits, stale_after_us) = sections::limits(&cx, doc.limits.as_ref())?;
    let hysteresis_um = sections::hysteresis_um(&cx, doc.hysteresis_mm.as_ref())?;
    // Regions are bounded by what the sections above settled: the substrate's length and the
    // duty cap.
    let (boundaries_um, textures) = regions::regions(
        &cx,
        &doc.region,
        calibration.length_um as f64 / 1000.0,
        limits.max_duty_permille as f64 / 10.0,
    )?;
    let lines = sections::lines(&cx, doc.lines.as_ref())?;
    let drive = sections::drive(doc.drive.as_ref());

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
        spans: Spans::of(&doc),
        config,
    })
}

impl SceneDoc {
    /// Locates an error the controller found in this file's configuration: at the value of the
    /// key it is about ([`fault_keys`]), or at its table when the file leaves that key to its
    /// default.
    pub fn locate(&self, e: &ConfigError) -> SceneFileError {
        let cx = Ctx {
            file: &self.file,
            text: &self.text,
        };
        let (names, table) = fault_keys(e, |i| self.spans.0.contains_key(&until(i)));
        let (span, field) = self.spans.find(&names, &table);
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

/// `region[i].until_mm`.
fn until(i: usize) -> String {
    std::format!("region[{i}].until_mm")
}

/// The keys a controller refusal is about, most telling first, and the table to fall back on.
/// `has_until(i)`: whether region `i` writes `until_mm` (the last region does not).
fn fault_keys(
    e: &ConfigError,
    has_until: impl Fn(usize) -> bool,
) -> (std::vec::Vec<String>, String) {
    use crate::burst::BurstError as B;
    use crate::position::CalibrationError as C;
    use crate::region::RegionError as R;
    use crate::texture::{LineFault as L, TextureError as T};
    let one = |k: &str| std::vec![k.to_string()];
    let region = |i: u8, keys: &[&str]| {
        (
            keys.iter()
                .map(|k| std::format!("region[{i}].{k}"))
                .collect(),
            std::format!("region[{i}]"),
        )
    };
    match *e {
        ConfigError::Calibration(c) => {
            let key = match c {
                C::EndInRail { at_start: true, .. } => "substrate.code_at_start",
                C::EndsSwapped { .. } | C::EndsTooClose { .. } | C::EndInRail { .. } => {
                    "substrate.code_at_end"
                }
                C::BadLength { .. } => "substrate.length_mm",
                C::BadRailMargin { .. } => "substrate.rail_margin_code",
            };
            (one(key), "substrate".into())
        }
        ConfigError::Limits(b) => {
            let key = match b {
                B::NoOnTime { .. } => "limits.max_on_time_ms",
                _ => "limits.max_duty_percent",
            };
            (one(key), "limits".into())
        }
        ConfigError::StaleLimit { .. } => (one("limits.stale_after_ms"), "limits".into()),
        ConfigError::Region(r) => match r {
            R::Unsorted { index, .. } | R::OutOfRange { index, .. } => (
                std::vec![until(index as usize)],
                std::format!("region[{index}]"),
            ),
            // A region too narrow ends at its `until_mm`, or, the last, starts at the one before.
            R::TooNarrow { index, .. } => {
                let i = index as usize;
                let key = if has_until(i) || i == 0 {
                    until(i)
                } else {
                    until(i - 1)
                };
                (std::vec![key], std::format!("region[{index}]"))
            }
            R::HysteresisTooLarge { .. } => (one("hysteresis_mm"), "hysteresis_mm".into()),
            _ => (std::vec![], "region[0]".into()),
        },
        ConfigError::Texture { region: i, error } => region(i, burst_keys(&error)),
        ConfigError::TextureParams { region: i, error } => region(i, texture_keys(&error)),
        ConfigError::Lines(t) => {
            let keys = match t {
                T::BadLines(L::OutOfRange { index, .. } | L::Unsorted { index, .. }) => {
                    std::vec![std::format!("lines.positions_mm[{index}]")]
                }
                T::BadLines(L::Rearm { .. }) => one("lines.rearm_mm"),
                T::BadLines(_) | T::LevelAboveCap { .. } | T::BadSpread { .. } => {
                    one("lines.amplitude_percent")
                }
                T::BadPulse { .. } => one("lines.pulse_ms"),
                _ => std::vec![],
            };
            (keys, "lines".into())
        }
        ConfigError::LinePulse(_) => (one("lines.pulse_ms"), "lines".into()),
        _ => (std::vec![], "(file)".into()),
    }
}

/// The keys of a texture's table a burst refusal is about, most telling first (none: the table).
fn burst_keys(e: &crate::burst::BurstError) -> &'static [&'static str] {
    use crate::burst::BurstError as B;
    match e {
        B::ZeroFrequency | B::AboveBoardLimit { .. } | B::BelowTimerRange { .. } => &["f_b_hz"],
        B::BadDuty { .. } | B::DutyAboveCap { .. } => &["duty_percent"],
        B::NoOnTime { .. } => &["duty_percent", "f_b_hz"],
        _ => &[],
    }
}

/// The keys of a texture's table a parameter refusal is about (none: the table).
fn texture_keys(e: &crate::texture::TextureError) -> &'static [&'static str] {
    use crate::texture::{MaterialParam as M, SpreadParam as S, TextureError as T};
    match e {
        T::BadWavelength { .. } => &["wavelength_mm", "ridge_mm"],
        T::BadSpeedThreshold { .. } => &["min_speed_mm_s"],
        T::BadMaterial { param, .. } => match param {
            M::DeltaMu => &["delta_mu"],
            M::NormalForce => &["normal_force_n"],
            M::Mass => &["mass_g"],
            M::Stiffness => &["stiffness_n_per_m"],
        },
        T::BadSpread { param, .. } => match param {
            S::Spread => &["spread_percent"],
            S::Amplitude => &["amplitude_percent"],
            S::AmplitudeSpread => &["amplitude_spread_percent"],
        },
        T::LevelAboveCap { .. } => &["amplitude_percent"],
        T::BadRearm { .. } => &["rearm_mm"],
        _ => &[],
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

/// The sensor a scene file asks for: the 1D slide rheostat (every scene before issue #36) or
/// the 2D 4-wire touch overlay (a file with `[sensor] kind = "4-wire"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SensorKind {
    /// The slide rheostat: a 1D scene, [`load_for_board`].
    Rheostat,
    /// The 4-wire resistive overlay: a 2D scene, [`load_2d_for_board`].
    FourWire,
}

/// Which sensor a scene file names (`[sensor] kind`); a file without `[sensor]` is 1D. Only
/// `[sensor]` is read (and the file's TOML syntax): a 1D file with a bad value elsewhere is
/// still `Rheostat`, for [`load_for_board`] to refuse with its sentence. A `kind` other than
/// `"4-wire"` is refused at its value, naming the one allowed.
pub fn sensor_of(file: &str, text: &str) -> Result<SensorKind, SceneFileError> {
    plane2d::sensor(&Ctx { file, text }).map(|(kind, _)| kind)
}

/// Reads a 2D scene file (issue #36) and checks it against a board whose touch frames come
/// every `frame_period_us`: the configuration, ready for [`crate::plane::Controller2d::load`].
///
/// As [`load_for_board`]: parsed, every value converted and range-checked, then dry-run through
/// a [`crate::plane::Controller2d`] for the board; every refusal at `file:line:col` of the
/// value at fault. A 1D file (no `[sensor]`) is refused with a sentence saying so.
pub fn load_2d_for_board(
    file: &str,
    text: &str,
    timer: BurstTimer,
    frame_period_us: u32,
) -> Result<crate::plane::Config2d, SceneFileError> {
    plane2d::load(&Ctx { file, text }, timer, frame_period_us)
}

/// The plate a 2D scene file declares (`[screen] size_mm`), µm (width, height): the area its
/// coordinates lie on, which [`crate::plane::Config2d`] does not hold (for a simulated finger's
/// travel, or [`to_scene_file_2d`]). The file is read and range-checked, not dry-run.
pub fn plate_um_of(file: &str, text: &str) -> Result<(u32, u32), SceneFileError> {
    plane2d::plate_um(&Ctx { file, text })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::{GratingRender, Texture};

    const TIMER: BurstTimer = crate::burst::TEST_TIMER;
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
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].colour"), "{e}");
        assert!(e.message.contains("colour"), "{e}");
        assert!(e.to_string().starts_with("bad.toml:4:"), "{e}");
    }

    #[test]
    fn out_of_range_value_is_located() {
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = -3\n");
        assert_eq!((e.line, e.field.as_str()), (3, "region[0].f_b_hz"), "{e}");
    }

    #[test]
    fn board_limit_is_located_at_the_value() {
        let text = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n[[region]]\nkind = \"constant\"\nf_b_hz = 9000\n";
        let e = err(text);
        assert_eq!(
            (e.line, e.column, e.field.as_str()),
            (8, 10, "region[1].f_b_hz"),
            "{e}"
        );
        assert!(e.message.contains("above this board's limit"), "{e}");
    }

    #[test]
    fn unsorted_boundaries_are_located() {
        let text = "[[region]]\nkind = \"off\"\nuntil_mm = 30\n[[region]]\nkind = \"off\"\nuntil_mm = 20\n[[region]]\nkind = \"off\"\n";
        let e = err(text);
        assert_eq!(
            (e.line, e.column, e.field.as_str()),
            (6, 12, "region[1].until_mm"),
            "{e}"
        );
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
        let h = g("[[region]]\nkind = \"grating\"\nwavelength_mm = 0.2\nrender = \"hybrid\"\n");
        assert_eq!((h.render, h.rearm_um), (GratingRender::Hybrid, 50));
        let e = err("[[region]]\nkind = \"grating\"\nwavelength_mm = 0.2\nrender = \"hybrid\"\nrearm_mm = 0.1\n");
        assert!(e.message.contains("half the period"), "{e}");
        let e = err("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrearm_mm = 0.5\n");
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].rearm_mm"), "{e}");
        assert!(e.message.contains("half the period"), "{e}");
        let e = err("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"phase\"\n");
        assert_eq!(e.line, 4, "{e}");
        let e = err("[[region]]\nkind = \"constant\"\nf_b_hz = 80\nrender = \"velocity\"\n");
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].render"), "{e}");
    }

    /// Every shipped scene loads on a 16-bit and a 32-bit burst timer.
    /// A material region's values arrive in the core's SI units: grams to kilograms, the rest
    /// as written (expected values converted by hand).
    #[test]
    fn material_values_in_si_units() {
        let text = "[[region]]\nkind = \"material\"\ndelta_mu = 0.5\nnormal_force_n = 2\n\
                    mass_g = 10\nstiffness_n_per_m = 800\n";
        let cfg = load_for_board("m.toml", text, TIMER, 100).unwrap();
        let Texture::Material(m) = cfg.scene.textures[0] else {
            panic!("{:?}", cfg.scene.textures[0]);
        };
        assert_eq!(
            (m.delta_mu, m.normal_force_n, m.mass_kg, m.stiffness_n_per_m),
            (0.5, 2.0, 0.01, 800.0)
        );
    }

    /// Eq. 12 of the SAW display paper: μs − μc = π (s − s') β / (E σ) with
    /// 1/E = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o. Worked by hand for E_s = 1 MPa, ν_s = 0.5,
    /// E_o = 2 MPa, ν_o = 0.3: 1/E = 0.75e-6 + 0.455e-6 = 1.205e-6 /Pa; with s − s' = 0.1 MPa and
    /// β/σ = 20 µm / 10 µm, μs − μc = π · 1e5 · 2 · 1.205e-6 = 0.241 π.
    #[test]
    fn a_bare_material_names_delta_mu_first() {
        let e = err("[[region]]\nkind = \"material\"\n");
        assert_eq!(e.field, "region[0].delta_mu", "{e}");
        assert!(
            e.message
                .starts_with("kind `material` needs `delta_mu` (μs − μc, 0 to 100), or all of"),
            "{e}"
        );
        // Both ways at once: refused at the eq. 12 parameter, which would be ignored.
        let e = err("[[region]]\nkind = \"material\"\ndelta_mu = 0.5\nsigma_um = 10\n");
        assert_eq!((e.line, e.field.as_str()), (4, "region[0].sigma_um"), "{e}");
        assert!(e.message.contains("not both"), "{e}");
        // One eq. 12 parameter given: the next missing one is named.
        let e = err("[[region]]\nkind = \"material\"\ne_object_pa = 2e6\n");
        assert_eq!(e.field, "region[0].nu_object", "{e}");
    }

    #[test]
    fn material_delta_mu_from_eq_12() {
        let text = "[[region]]\nkind = \"material\"\ne_skin_pa = 1e6\nnu_skin = 0.5\n\
                    e_object_pa = 2e6\nnu_object = 0.3\nsigma_um = 10\nbeta_um = 20\n\
                    shear_strength_diff_pa = 1e5\n";
        let cfg = load_for_board("m.toml", text, TIMER, 100).unwrap();
        let Texture::Material(m) = cfg.scene.textures[0] else {
            panic!("{:?}", cfg.scene.textures[0]);
        };
        let expected = 0.241 * core::f32::consts::PI;
        assert!(
            (m.delta_mu - expected).abs() < 1e-6,
            "{} vs {expected}",
            m.delta_mu
        );
        // Ten thousand times the shear strength difference: μs − μc = 2410 π, above 100.
        let e = err(&text.replace("= 1e5", "= 1e9"));
        assert_eq!(e.field, "region[0].delta_mu", "{e}");
        assert!(
            e.message.starts_with("eq. 12 gives μs − μc = 7571.")
                && e.message.ends_with(", outside the allowed 0 to 100"),
            "{e}"
        );
    }

    #[test]
    fn drive_mode_is_read() {
        let text = "drive = \"progressive\"\n\n[[region]]\nkind = \"off\"\n";
        let cfg = load_for_board("d.toml", text, TIMER, 100).unwrap();
        assert_eq!(cfg.scene.drive, crate::gate::DriveMode::Progressive);
        let cfg = load_for_board("d.toml", "[[region]]\nkind = \"off\"\n", TIMER, 100).unwrap();
        assert_eq!(cfg.scene.drive, crate::gate::DriveMode::Standing);
    }

    /// A line position must be a number of mm at or after 0; one the u32 µm count cannot hold
    /// is refused here too, before the substrate check.
    #[test]
    fn line_positions_that_are_no_position_are_refused() {
        for (p, shown) in [("-1", "-1"), ("5e9", "5000000000")] {
            let e = err(&std::format!(
                "[lines]\npositions_mm = [10, {p}]\n\n[[region]]\nkind = \"off\"\n"
            ));
            assert_eq!(
                (e.line, e.field.as_str(), e.message.as_str()),
                (
                    2,
                    "lines.positions_mm",
                    &*std::format!(
                        "{shown} mm is not a position: it must be a finite number of mm, at least 0"
                    )
                ),
            );
        }
    }

    /// The inputs the planted panics (features `fuzz-plant-*`, docs/fuzzing.md) fire on load
    /// in an ordinary build: 1 µm in 5 of hysteresis, and 6 lines. Fails if a plant is built in.
    #[test]
    fn no_planted_panic_in_this_build() {
        let text = "hysteresis_mm = 0.011\n\n[lines]\npositions_mm = [5, 10, 15, 20, 25, 30]\n\n\
                    [[region]]\nkind = \"off\"\n";
        let cfg = load_for_board("p.toml", text, TIMER, 100).unwrap();
        assert_eq!(cfg.scene.hysteresis_um, 11);
        assert_eq!(cfg.scene.lines.positions_um.len(), 6);
    }

    /// A file writing every key a refusal can be about, one per line (line numbers below).
    const EVERY_KEY: &str = "hysteresis_mm = 0.1\n\
        [substrate]\nlength_mm = 63\ncode_at_start = 1310\ncode_at_end = 64225\n\
        rail_margin_code = 655\n\
        [limits]\nmax_duty_percent = 50\nmax_level_percent = 100\nmax_on_time_ms = 50\n\
        stale_after_ms = 5\n\
        [[region]]\nkind = \"constant\"\nuntil_mm = 10\nf_b_hz = 80\nduty_percent = 40\n\
        [[region]]\nkind = \"grating\"\nuntil_mm = 20\nwavelength_mm = 1\nmin_speed_mm_s = 15\n\
        amplitude_percent = 100\nrearm_mm = 0.1\n\
        [[region]]\nkind = \"material\"\nuntil_mm = 30\ndelta_mu = 0.5\nnormal_force_n = 1\n\
        mass_g = 1\nstiffness_n_per_m = 500\n\
        [[region]]\nkind = \"random\"\nf_b_hz = 60\nspread_percent = 25\n\
        amplitude_percent = 100\namplitude_spread_percent = 10\n\
        [lines]\npositions_mm = [5, 15]\npulse_ms = 10\namplitude_percent = 100\nrearm_mm = 0.2\n";

    /// Every controller refusal is located at the value it is about (field and line by hand from
    /// [`EVERY_KEY`]), or at its table when the file leaves that key to its default. Errors are
    /// built by hand: the reader's own ranges keep most of them from a file.
    #[test]
    fn every_controller_refusal_is_located_at_its_key() {
        use crate::burst::BurstError as B;
        use crate::position::CalibrationError as C;
        use crate::region::RegionError as R;
        use crate::texture::{
            LineFault as L, MaterialParam as M, ParamValue, SpreadParam as S, TextureError as T,
        };
        let doc = parse("every.toml", EVERY_KEY).unwrap();
        let tex = |region, error| ConfigError::Texture { region, error };
        let par = |region, error| ConfigError::TextureParams { region, error };
        let f_b = B::AboveBoardLimit {
            burst_millihz: 1,
            max_millihz: 1,
        };
        let no_on = B::NoOnTime {
            burst_millihz: 1,
            max_duty_permille: 1,
            max_on_time_us: 1,
        };
        let mat = |param| T::BadMaterial {
            param,
            value: ParamValue(-1.0),
        };
        let spread = |param| T::BadSpread { param, permille: 1 };
        let narrow = |index| {
            ConfigError::Region(R::TooNarrow {
                index,
                width_um: 1,
                min_width_um: 2,
            })
        };
        let pulse = T::BadPulse {
            pulse_us: 1,
            max_on_time_us: 1,
        };
        let cases: &[(ConfigError, &str, usize)] = &[
            (
                ConfigError::Calibration(C::EndsSwapped {
                    code_at_start: 1,
                    code_at_end: 1,
                }),
                "substrate.code_at_end",
                5,
            ),
            (
                ConfigError::Calibration(C::EndsTooClose {
                    span_code: 1,
                    min_span_code: 2,
                }),
                "substrate.code_at_end",
                5,
            ),
            (
                ConfigError::Calibration(C::EndInRail {
                    at_start: true,
                    code: 1,
                    rail_code: 2,
                }),
                "substrate.code_at_start",
                4,
            ),
            (
                ConfigError::Calibration(C::EndInRail {
                    at_start: false,
                    code: 1,
                    rail_code: 2,
                }),
                "substrate.code_at_end",
                5,
            ),
            (
                ConfigError::Calibration(C::BadLength { length_um: 0 }),
                "substrate.length_mm",
                3,
            ),
            (
                ConfigError::Calibration(C::BadRailMargin {
                    margin_code: 0,
                    limit_code: 1,
                }),
                "substrate.rail_margin_code",
                6,
            ),
            (
                ConfigError::Limits(B::BadDuty { duty_permille: 0 }),
                "limits.max_duty_percent",
                8,
            ),
            (ConfigError::Limits(no_on), "limits.max_on_time_ms", 10),
            (
                ConfigError::StaleLimit {
                    stale_after_us: 1,
                    min_us: 2,
                },
                "limits.stale_after_ms",
                11,
            ),
            (
                ConfigError::Region(R::Unsorted {
                    index: 1,
                    at_um: 1,
                    previous_um: 2,
                }),
                "region[1].until_mm",
                19,
            ),
            (
                ConfigError::Region(R::OutOfRange {
                    index: 2,
                    at_um: 1,
                    length_um: 1,
                }),
                "region[2].until_mm",
                26,
            ),
            (narrow(0), "region[0].until_mm", 14),
            (narrow(1), "region[1].until_mm", 19),
            // The last region has no `until_mm`: it starts at the one before.
            (narrow(3), "region[2].until_mm", 26),
            (
                ConfigError::Region(R::HysteresisTooLarge { hysteresis_um: 1 }),
                "hysteresis_mm",
                1,
            ),
            (
                ConfigError::Region(R::BadCount { regions: 9 }),
                "region[0]",
                12,
            ),
            (tex(0, f_b), "region[0].f_b_hz", 15),
            (tex(0, B::ZeroFrequency), "region[0].f_b_hz", 15),
            (
                tex(
                    3,
                    B::BelowTimerRange {
                        burst_millihz: 1,
                        min_millihz: 2,
                    },
                ),
                "region[3].f_b_hz",
                33,
            ),
            (
                tex(0, B::BadDuty { duty_permille: 0 }),
                "region[0].duty_percent",
                16,
            ),
            (
                tex(
                    0,
                    B::DutyAboveCap {
                        duty_permille: 2,
                        cap_permille: 1,
                    },
                ),
                "region[0].duty_percent",
                16,
            ),
            (tex(0, no_on), "region[0].duty_percent", 16),
            // A grating writes neither key: its table.
            (tex(1, no_on), "region[1]", 17),
            (
                tex(
                    0,
                    B::PulseTooLong {
                        pulse_us: 2,
                        max_us: 1,
                    },
                ),
                "region[0]",
                12,
            ),
            (
                par(
                    1,
                    T::BadWavelength {
                        wavelength_um: 0,
                        length_um: 1,
                    },
                ),
                "region[1].wavelength_mm",
                20,
            ),
            (
                par(1, T::BadSpeedThreshold { min_speed_um_s: 1 }),
                "region[1].min_speed_mm_s",
                21,
            ),
            (par(2, mat(M::DeltaMu)), "region[2].delta_mu", 27),
            (par(2, mat(M::NormalForce)), "region[2].normal_force_n", 28),
            (par(2, mat(M::Mass)), "region[2].mass_g", 29),
            (par(2, mat(M::Stiffness)), "region[2].stiffness_n_per_m", 30),
            (par(3, spread(S::Spread)), "region[3].spread_percent", 34),
            (
                par(3, spread(S::Amplitude)),
                "region[3].amplitude_percent",
                35,
            ),
            (
                par(3, spread(S::AmplitudeSpread)),
                "region[3].amplitude_spread_percent",
                36,
            ),
            (
                par(
                    1,
                    T::LevelAboveCap {
                        permille: 2,
                        max_level_permille: 1,
                    },
                ),
                "region[1].amplitude_percent",
                22,
            ),
            (
                par(
                    1,
                    T::BadRearm {
                        rearm_um: 1,
                        wavelength_um: 1,
                    },
                ),
                "region[1].rearm_mm",
                23,
            ),
            (par(0, pulse), "region[0]", 12),
            (
                ConfigError::Lines(T::BadLines(L::OutOfRange {
                    index: 1,
                    at_um: 1,
                    length_um: 1,
                })),
                "lines.positions_mm[1]",
                38,
            ),
            (
                ConfigError::Lines(T::BadLines(L::Unsorted {
                    index: 0,
                    at_um: 1,
                    previous_um: 1,
                })),
                "lines.positions_mm[0]",
                38,
            ),
            (
                ConfigError::Lines(T::BadLines(L::Rearm { rearm_um: 1 })),
                "lines.rearm_mm",
                41,
            ),
            (
                ConfigError::Lines(T::BadLines(L::Amplitude { permille: 0 })),
                "lines.amplitude_percent",
                40,
            ),
            (
                ConfigError::Lines(T::LevelAboveCap {
                    permille: 2,
                    max_level_permille: 1,
                }),
                "lines.amplitude_percent",
                40,
            ),
            (
                ConfigError::Lines(spread(S::Amplitude)),
                "lines.amplitude_percent",
                40,
            ),
            (ConfigError::Lines(pulse), "lines.pulse_ms", 39),
            (
                ConfigError::Lines(T::BadSpeedThreshold { min_speed_um_s: 1 }),
                "lines",
                37,
            ),
            (
                ConfigError::LinePulse(B::PulseTooLong {
                    pulse_us: 2,
                    max_us: 1,
                }),
                "lines.pulse_ms",
                39,
            ),
            (
                ConfigError::TextureCount {
                    textures: 1,
                    boundaries: 1,
                },
                "(file)",
                1,
            ),
        ];
        for (e, field, line) in cases {
            let got = doc.locate(e);
            assert_eq!(
                (got.field.as_str(), got.line),
                (*field, *line),
                "{e:?}: {got}"
            );
        }
        // Columns: at the value (`positions_mm = [5, 15]`: 5 at column 17, 15 at column 20).
        let at = |index| {
            let e = doc.locate(&ConfigError::Lines(T::BadLines(L::OutOfRange {
                index,
                at_um: 1,
                length_um: 1,
            })));
            e.column
        };
        assert_eq!((at(0), at(1)), (17, 20));
        assert_eq!(doc.locate(&tex(0, f_b)).column, 10);
    }

    /// Every shipped scene loads on a 16-bit and a 32-bit burst timer, each by the loader of
    /// the sensor it names: 1D scenes at the rheostat's 100 µs, 2D scenes at the F446's touch
    /// frame period (2 889 Hz, docs/touch.md) and the G474's (3 921 Hz).
    #[test]
    fn shipped_scenes_load() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
        let (mut n1, mut n2) = (0, 0);
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                let name = path.display().to_string();
                let t16 = BurstTimer {
                    clock_hz: 150_000_000,
                    counter_bits: 16,
                    max_burst_hz: 5_000,
                };
                let sensor = sensor_of(&name, &text).unwrap_or_else(|e| panic!("{e}"));
                for timer in [TIMER, t16] {
                    match sensor {
                        SensorKind::Rheostat => load_for_board(&name, &text, timer, 100).map(drop),
                        _ => [346, 255].into_iter().try_for_each(|frame_us| {
                            load_2d_for_board(&name, &text, timer, frame_us).map(drop)
                        }),
                    }
                    .unwrap_or_else(|e| panic!("{e}"));
                }
                match sensor {
                    SensorKind::Rheostat => n1 += 1,
                    _ => n2 += 1,
                }
            }
        }
        assert!(n1 >= 5 && n2 >= 2, "{n1} 1D and {n2} 2D scenes");
    }
}
