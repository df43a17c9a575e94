//! Property tests (fuzzing in CI's budget): scene files and sample streams from an adversary,
//! checked for what a user would see.
//!
//! - A file the reader accepts, run through a [`Controller`] under a finger sweeping the
//!   substrate (with rail blips), drives an enable line that keeps the caps *as written in the
//!   file* (`[limits]`, read here with the `toml` crate, not through the core): every pulse's
//!   on-time ≤ the on-time cap, the on-time in every duty window (docs/duty-window.md) ≤ the
//!   duty cap, in kernel clocks of a timer modelled in `common` from the gate actions alone; and
//!   the line is low while a sample sits at a rail.
//! - A file it refuses yields one sentence `file:line:column: `field`: message` whose field is
//!   a scene field (or, for text that is not TOML, the key on the line it points at). Generated
//!   files with one value put out of range must be refused at exactly that field and line; the
//!   same files in range must load.
//!
//! Needs the `scene-file` feature, which core/Cargo.toml's self dev-dependency turns on for every
//! test build: no `cfg` gate here, so a build without it fails to compile rather than passing
//! with nothing run.

use proptest::prelude::*;
use proptest::test_runner::TestCaseError;
use saw_core::burst::BurstTimer;
use saw_core::position::PositionMapper;
use saw_core::sample::Sample;
use saw_core::scene_file::{load_for_board, SceneFileError};
use saw_core::{Config, Controller};

mod common;
use common::LineModel;

const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};
const T16: BurstTimer = BurstTimer {
    clock_hz: 150_000_000,
    counter_bits: 16,
    max_burst_hz: 5_000,
};
const DEFAULT: &str = include_str!("../../scenes/default.toml");
const LINES: &str = include_str!("../../scenes/lines.toml");
const RANDOM: &str = include_str!("../../scenes/random.toml");
const GRATING: &str = include_str!("../../scenes/grating.toml");
const MATERIAL: &str = include_str!("../../scenes/material.toml");
const SAMPLE_US: u32 = 100;

/// The caps a scene file states, in the units the README and the scene files give: duty in %
/// (kept to 0.1 %, the reader's resolution), on-time in ms; 50 % and 50 ms when not stated.
/// Returns (duty cap ‰, on-time cap µs).
fn caps_as_written(text: &str) -> (u64, u64) {
    let doc: toml::Table = text.parse().expect("accepted scene files are TOML");
    let get = |key: &str, default: f64| {
        doc.get("limits")
            .and_then(|l| l.get(key))
            .map(|v| match v {
                toml::Value::Float(x) => *x,
                toml::Value::Integer(i) => *i as f64,
                other => panic!("limits.{key} = {other}"),
            })
            .unwrap_or(default)
    };
    let duty_permille = (get("max_duty_percent", 50.0) * 10.0).round() as u64;
    let on_us = (get("max_on_time_ms", 50.0) * 1000.0).round() as u64;
    (duty_permille, on_us)
}

/// Checks the line against the caps as written: every pulse's on-time, and the on-time in
/// every duty window (common::check_caps).
fn check_caps(
    line: &LineModel,
    duty_permille: u64,
    on_us: u64,
    what: &str,
) -> Result<(), TestCaseError> {
    prop_assert_eq!(line.protocol_errors, 0, "{}: Update while stopped", what);
    let max_on = on_us * line.clock_hz / 1_000_000;
    let window = line.clocks(common::stated_window_us(duty_permille, on_us));
    if let Err(e) = common::check_caps(&line.on, duty_permille, max_on, window) {
        return Err(TestCaseError::fail(format!("{what}: {e}")));
    }
    Ok(())
}

/// Feeds `samples` (time µs, code) to a controller holding `cfg`, models the line from its
/// actions, and checks the caps as written in `text`, and that the line is low from every sample
/// at a rail (the README's rule: within 1 % of either end of the 16-bit code) or reported faulty
/// until the next sample.
fn run_and_check(
    cfg: &Config,
    text: &str,
    timer: BurstTimer,
    samples: impl Iterator<Item = (u64, u16)>,
    what: &str,
) -> Result<(), TestCaseError> {
    let mut c = Controller::new(timer, SAMPLE_US).unwrap();
    c.load(cfg).unwrap();
    let margin = cfg.calibration.rail_margin_code;
    let mut line = LineModel::new(&timer);
    let mut faulted: Vec<(u64, u64)> = Vec::new();
    let mut last = 0;
    for (t, code) in samples {
        if let Some((_, end)) = faulted.last_mut() {
            if *end == u64::MAX {
                *end = line.clocks(t);
            }
        }
        let out = c.on_sample(Sample {
            code,
            t_us: t as u32,
        });
        if let Some(a) = out.action {
            line.apply(t, a);
        }
        let at_rail = code <= margin || code as u32 >= 65_535 - margin as u32;
        if at_rail {
            prop_assert!(
                out.fault.is_some(),
                "{}: code {} not taken for a rail",
                what,
                code
            );
        }
        if at_rail || out.fault.is_some() {
            faulted.push((line.clocks(t), u64::MAX));
        }
        last = t;
    }
    let end = line.clocks(last + SAMPLE_US as u64);
    line.advance(end);
    if let Some((_, e)) = faulted.last_mut() {
        if *e == u64::MAX {
            *e = end;
        }
    }
    for &(a, b) in &faulted {
        prop_assert!(
            !line.high_within(a, b),
            "{}: line high in a faulted sample period {}..{} clocks",
            what,
            a,
            b
        );
    }
    let (duty, on_us) = caps_as_written(text);
    check_caps(&line, duty, on_us, what)
}

/// A finger sweeping back and forth across the substrate at `speed_mm_s` from `start` (a
/// fraction of the length), `n` samples, with the samples in `blips` at a rail.
fn sweep(cfg: &Config, speed_mm_s: f64, start: f64, n: u64, blips: &[u16]) -> Vec<(u64, u16)> {
    let m = PositionMapper::new(cfg.calibration).unwrap();
    let len = m.length_um() as f64;
    let (lo, hi) = (0.01 * len, 0.99 * len);
    let span = hi - lo;
    (0..n)
        .map(|k| {
            let t = k * SAMPLE_US as u64;
            let d = start * span + speed_mm_s * 1000.0 * t as f64 * 1e-6;
            let phase = d.rem_euclid(2.0 * span);
            let x = lo
                + if phase < span {
                    phase
                } else {
                    2.0 * span - phase
                };
            let code = if blips.contains(&(k as u16)) {
                if k % 2 == 0 {
                    0
                } else {
                    65_535
                }
            } else {
                m.code_at_um(x as f32).round() as u16
            };
            (t, code)
        })
        .collect()
}

/// Schema names a refused file's error may name (`region[i].` prefixes and indices stripped).
const FIELDS: &[&str] = &[
    "(file)",
    "substrate",
    "length_mm",
    "code_at_start",
    "code_at_end",
    "rail_margin_code",
    "limits",
    "max_duty_percent",
    "max_on_time_ms",
    "stale_after_ms",
    "drive",
    "hysteresis_mm",
    "region",
    "kind",
    "until_mm",
    "f_b_hz",
    "duty_percent",
    "wavelength_mm",
    "ridge_mm",
    "groove_mm",
    "min_speed_mm_s",
    "amplitude_percent",
    "render",
    "rearm_mm",
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
    "spread_percent",
    "amplitude_spread_percent",
    "seed",
    "lines",
    "positions_mm",
    "pulse_ms",
    "envelope",
];

/// A refusal as the user reads it: one located sentence naming a field.
fn check_refusal(text: &str, e: &SceneFileError) -> Result<(), TestCaseError> {
    let lines: Vec<&str> = text.split('\n').collect();
    prop_assert!(e.line >= 1 && e.line <= lines.len(), "{}", e);
    prop_assert!(
        // The reader counts columns in bytes.
        e.column >= 1 && e.column <= lines[e.line - 1].len() + 1,
        "{}: column past the line",
        e
    );
    prop_assert!(!e.message.trim().is_empty(), "{}: no message", e);
    prop_assert!(!e.field.trim().is_empty(), "{}: no field", e);
    prop_assert_eq!(
        e.to_string(),
        format!(
            "{}:{}:{}: `{}`: {}",
            e.file, e.line, e.column, e.field, e.message
        )
    );
    let in_schema = e.field.split('.').all(|part| {
        let name = part.split('[').next().unwrap_or(part);
        FIELDS.contains(&name)
    });
    if text.parse::<toml::Table>().is_ok() {
        // TOML that reads: the field is one of the scene's, or a key the user wrote on the line
        // named (an unknown field, a value of the wrong type), under its table's name.
        let key = e.field.rsplit('.').next().unwrap_or(&e.field);
        let on_line = lines[e.line - 1].contains(key);
        prop_assert!(
            in_schema || on_line,
            "{}: `{}` is no scene field",
            e,
            e.field
        );
    } else {
        // Not TOML: the reader can only quote the line it stopped at.
        let on_line = lines[e.line - 1].contains(e.field.as_str());
        prop_assert!(on_line || e.field == "(file)", "{}", e);
    }
    Ok(())
}

/// A shipped file with one byte range replaced by fuzz.
fn mutated() -> impl Strategy<Value = String> {
    (
        prop::sample::select(vec![DEFAULT, LINES, RANDOM, GRATING, MATERIAL]),
        any::<prop::sample::Index>(),
        "[ -~\n]{0,12}",
    )
        .prop_map(|(base, at, junk)| {
            let i = at.index(base.len());
            let i = (0..=i)
                .rev()
                .find(|&k| base.is_char_boundary(k))
                .unwrap_or(0);
            format!("{}{}{}", &base[..i], junk, &base[i..])
        })
}

/// SplitMix64: the scene generator's dice, seeded by proptest.
struct Dice(u64);

impl Dice {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn log(&mut self, lo: f64, hi: f64) -> f64 {
        lo * (hi / lo).powf(self.unit())
    }
    fn pick(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
}

/// A range-checked value the generator wrote: its path, line and range.
struct Written {
    path: String,
    line: usize,
    lo: f64,
    hi: f64,
}

/// The generated file's lines, and the range-checked values among them.
#[derive(Default)]
struct Gen {
    out: Vec<String>,
    written: Vec<Written>,
}

impl Gen {
    fn push(&mut self, line: String) {
        self.out.push(line);
    }

    /// `key = v`, remembered as `path` with the reader's range `lo ..= hi`.
    fn put(&mut self, path: &str, key: &str, v: f64, lo: f64, hi: f64) {
        self.out.push(format!("{key} = {v:?}"));
        self.written.push(Written {
            path: path.to_string(),
            line: self.out.len(),
            lo,
            hi,
        });
    }
}

/// A scene file in the documented ranges, every kind and option drawn, and the range-checked
/// values it holds (to put one of them out of range).
fn generated(d: &mut Dice) -> (Vec<String>, Vec<Written>) {
    let mut g = Gen::default();
    g.push(format!(
        "drive = \"{}\"",
        ["standing", "progressive"][d.pick(2)]
    ));
    let hyst = (d.range(0.0, 1.0) * 1000.0).round() / 1000.0;
    g.put("hysteresis_mm", "hysteresis_mm", hyst, 0.0, 5.0);
    let length = 63.0;
    let cap = if d.chance(0.8) {
        (d.range(0.1, 100.0) * 10.0).round() / 10.0
    } else {
        50.0
    };
    let on_ms = (d.log(0.05, 200.0) * 1000.0).round() / 1000.0;
    if d.chance(0.9) {
        g.push("[limits]".to_string());
        g.put(
            "limits.max_duty_percent",
            "max_duty_percent",
            cap,
            0.1,
            100.0,
        );
        g.put(
            "limits.max_on_time_ms",
            "max_on_time_ms",
            on_ms,
            0.001,
            1000.0,
        );
        let stale = d.range(0.2, 20.0);
        g.put(
            "limits.stale_after_ms",
            "stale_after_ms",
            stale,
            0.2,
            1000.0,
        );
    }
    let (cap, on_ms) = if g.out.iter().any(|l| l == "[limits]") {
        (cap, on_ms)
    } else {
        (50.0, 50.0)
    };
    let n = 1 + d.pick(8);
    let width = length / n as f64;
    for i in 0..n {
        g.push(String::new());
        g.push("[[region]]".to_string());
        let f = |name: &str| format!("region[{i}].{name}");
        // Up to the cap (the reader takes 0.1 ..= 100; above the cap the load refuses it).
        let max_duty = cap;
        let kind = d.pick(6);
        g.push(format!(
            "kind = \"{}\"",
            ["off", "constant", "grating", "grating", "material", "random"][kind]
        ));
        if i + 1 < n {
            let until = ((i as f64 + 1.0 + d.range(-0.2, 0.2)) * width * 1000.0).round() / 1000.0;
            g.put(&f("until_mm"), "until_mm", until, 0.0, length);
        }
        let duty = |d: &mut Dice| (d.range(0.1, max_duty) * 10.0).round() / 10.0;
        match kind {
            1 => {
                let hz = d.log(0.5, 2_000.0);
                g.put(&f("f_b_hz"), "f_b_hz", hz, 0.001, 1e6);
                if d.chance(0.8) {
                    let v = duty(d);
                    g.put(&f("duty_percent"), "duty_percent", v, 0.1, 100.0);
                }
            }
            2 | 3 => {
                let lambda = (d.log(0.2, 10.0) * 1000.0).round() / 1000.0;
                if d.chance(0.7) {
                    g.put(&f("wavelength_mm"), "wavelength_mm", lambda, 0.001, length);
                } else {
                    let ridge = (lambda * d.range(0.1, 0.9) * 1000.0).round() / 1000.0;
                    g.put(&f("ridge_mm"), "ridge_mm", ridge, 0.0, length);
                    let groove = ((lambda - ridge) * 1000.0).round() / 1000.0;
                    g.put(&f("groove_mm"), "groove_mm", groove, 0.0, length);
                }
                if kind == 3 {
                    g.push("render = \"velocity\"".to_string());
                } else if d.chance(0.5) {
                    g.push("render = \"position\"".to_string());
                }
                if d.chance(0.6) {
                    let v = duty(d);
                    g.put(&f("duty_percent"), "duty_percent", v, 0.1, 100.0);
                }
                if d.chance(0.5) {
                    let v = d.range(0.0, 40.0);
                    g.put(&f("min_speed_mm_s"), "min_speed_mm_s", v, 0.0, 1000.0);
                }
                if d.chance(0.5) {
                    let v = d.range(0.1, 100.0);
                    g.put(&f("amplitude_percent"), "amplitude_percent", v, 0.1, 100.0);
                }
            }
            4 => {
                if d.chance(0.7) {
                    let v = d.range(0.0, 1.5);
                    g.put(&f("delta_mu"), "delta_mu", v, 0.0, 100.0);
                } else {
                    for l in [
                        "e_object_pa = 2.0e9",
                        "nu_object = 0.35",
                        "e_skin_pa = 1.0e6",
                        "nu_skin = 0.49",
                        "sigma_um = 10",
                        "beta_um = 80",
                        "shear_strength_diff_pa = 3.0e3",
                    ] {
                        g.push(l.to_string());
                    }
                }
                if d.chance(0.6) {
                    let v = d.log(0.05, 5.0);
                    g.put(&f("normal_force_n"), "normal_force_n", v, 1e-3, 100.0);
                }
                if d.chance(0.6) {
                    let v = d.log(0.01, 10.0);
                    g.put(&f("mass_g"), "mass_g", v, 1e-3, 1e4);
                }
                if d.chance(0.6) {
                    let v = d.log(10.0, 1e5);
                    g.put(&f("stiffness_n_per_m"), "stiffness_n_per_m", v, 1e-3, 1e7);
                }
                if d.chance(0.6) {
                    let v = duty(d);
                    g.put(&f("duty_percent"), "duty_percent", v, 0.1, 100.0);
                }
            }
            5 => {
                // Both ends of the spread must be renderable: at 1 Hz − 95 % a 16-bit timer's
                // prescaled tick outlasts a 50 µs on-time cap, and the load rightly refuses it.
                let hz = d.log(5.0, 1_500.0);
                g.put(&f("f_b_hz"), "f_b_hz", hz, 0.001, 1e6);
                if d.chance(0.7) {
                    let v = d.range(0.0, 50.0);
                    g.put(&f("spread_percent"), "spread_percent", v, 0.0, 100.0);
                }
                if d.chance(0.3) {
                    let v = d.range(0.0, 100.0);
                    let key = "amplitude_spread_percent";
                    g.put(&f(key), key, v, 0.0, 100.0);
                }
                if d.chance(0.5) {
                    let v = d.range(0.1, 100.0);
                    g.put(&f("amplitude_percent"), "amplitude_percent", v, 0.1, 100.0);
                }
                if d.chance(0.6) {
                    let v = duty(d);
                    g.put(&f("duty_percent"), "duty_percent", v, 0.1, 100.0);
                }
                if d.chance(0.5) {
                    g.push(format!("seed = {}", d.next() >> 1));
                }
            }
            _ => {}
        }
    }
    if d.chance(0.5) {
        g.push(String::new());
        g.push("[lines]".to_string());
        let k = 1 + d.pick(16);
        let pos: Vec<String> = (0..k)
            .map(|j| {
                format!(
                    "{:.3}",
                    (j as f64 + d.range(0.2, 0.8)) * (length / k as f64)
                )
            })
            .collect();
        g.push(format!("positions_mm = [{}]", pos.join(", ")));
        let p = (d.range(0.01, 1.0) * on_ms * 1000.0).round().max(1.0) / 1000.0;
        g.put("lines.pulse_ms", "pulse_ms", p, 0.001, 1000.0);
        g.push(format!(
            "envelope = \"{}\"",
            ["triangle", "rectangle"][d.pick(2)]
        ));
        if d.chance(0.5) {
            let v = d.range(0.1, 100.0);
            g.put(
                "lines.amplitude_percent",
                "amplitude_percent",
                v,
                0.1,
                100.0,
            );
        }
        if d.chance(0.5) {
            let v = d.range(0.0, 2.0);
            g.put("lines.rearm_mm", "rearm_mm", v, 0.0, 5.0);
        }
    }
    (g.out, g.written)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// Any text: refused with a located sentence naming a field, or accepted and then every
    /// pulse keeps the caps the file states.
    #[test]
    fn any_text_reads_or_is_located(
        text in prop_oneof![mutated(), "[ -~\n]{0,200}"],
        speed in 1.0f64..400.0,
        start in 0.0f64..1.0,
        blips in prop::collection::vec(0u16..1500, 0..4),
    ) {
        match load_for_board("fuzz.toml", &text, TIMER, SAMPLE_US) {
            Ok(cfg) => {
                let s = sweep(&cfg, speed, start, 1500, &blips);
                run_and_check(&cfg, &text, TIMER, s.into_iter(), "accepted text")?;
            }
            Err(e) => check_refusal(&text, &e)?,
        }
    }

    /// Generated scenes: in range they load and keep the caps they state; with one value put
    /// out of range (below, above, nan or inf) they are refused at that field and line.
    #[test]
    fn generated_scenes_load_or_name_the_bad_field(
        seed in any::<u64>(),
        corrupt in any::<Option<(prop::sample::Index, u8)>>(),
        speed in 1.0f64..400.0,
        start in 0.0f64..1.0,
        blips in prop::collection::vec(0u16..2000, 0..4),
        t16 in any::<bool>(),
    ) {
        let timer = if t16 { T16 } else { TIMER };
        let (mut lines, written) = generated(&mut Dice(seed));
        let bad = corrupt.map(|(i, how)| {
            let w = &written[i.index(written.len())];
            let v = match how % 4 {
                0 if w.lo > 0.0 => format!("{:?}", w.lo / 2.0),
                0 => "-0.5".to_string(),
                1 => format!("{:?}", w.hi * 2.0 + 1.0),
                2 => "nan".to_string(),
                _ => "inf".to_string(),
            };
            let key = lines[w.line - 1].split(" = ").next().unwrap().to_string();
            lines[w.line - 1] = format!("{key} = {v}");
            w
        });
        let text = lines.join("\n") + "\n";
        let r = load_for_board("gen.toml", &text, timer, SAMPLE_US);
        match (bad, r) {
            (None, Ok(cfg)) => {
                let s = sweep(&cfg, speed, start, 2000, &blips);
                run_and_check(&cfg, &text, timer, s.into_iter(), "generated scene")?;
            }
            (None, Err(e)) => prop_assert!(false, "in-range scene refused: {}\n{}", e, text),
            (Some(w), Ok(_)) => {
                prop_assert!(false, "{} out of range accepted:\n{}", w.path, text)
            }
            (Some(w), Err(e)) => {
                check_refusal(&text, &e)?;
                prop_assert_eq!(
                    (e.field.as_str(), e.line),
                    (w.path.as_str(), w.line),
                    "{}\n{}",
                    e,
                    text
                );
            }
        }
    }

    /// Adversarial sample streams (any code, any spacing) on the shipped scenes: the line keeps
    /// the caps each file states, and is low on every sample at a rail.
    #[test]
    fn any_sample_stream_keeps_the_caps(
        scene in prop::sample::select(vec![DEFAULT, LINES, RANDOM, GRATING, MATERIAL]),
        codes in prop::collection::vec(any::<u16>(), 1..400),
        steps in prop::collection::vec(0u32..400, 1..400),
    ) {
        let cfg = load_for_board("scene.toml", scene, TIMER, SAMPLE_US).unwrap();
        let mut t = 0u64;
        let samples: Vec<(u64, u16)> = codes
            .iter()
            .enumerate()
            .map(|(i, &code)| {
                t += steps[i % steps.len()] as u64;
                (t, code)
            })
            .collect();
        run_and_check(&cfg, scene, TIMER, samples.into_iter(), "sample stream")?;
    }
}
