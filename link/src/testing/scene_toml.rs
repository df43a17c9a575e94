//! Structure-aware scene files for the `scene_struct` fuzz target: the fuzzer's bytes read as
//! choices (`arbitrary::Unstructured`) that build a scene's tables and keys, written as TOML
//! text for the reader. Every texture kind with its keys, `[lines]` with any number of
//! positions, `[limits]`, `[substrate]`, `drive` and `hysteresis_mm`; values mostly in range but
//! often odd decimals, range edges, just outside, non-finite or huge; keys sometimes missing or
//! foreign.
//!
//! Why: the byte-level mutator of the `scene_file` target rarely turns a valid file into another
//! valid one with a new shape (an array grown by a valid element, a value with a third decimal),
//! so code reached only by such files stayed unfound (docs/fuzzing.md, the planted panics).
//! Here one mutated byte is one changed decision: a count, a key present or not, a value.

use std::fmt::Write;
use std::string::String;

use arbitrary::{Result, Unstructured};
use saw_core::position::DEFAULT_LENGTH_UM;

/// What a key holds, with the range the reader accepts (so most draws are in it).
#[derive(Clone, Copy)]
enum Val {
    /// A number of the key's unit, accepted within `lo ..= hi`.
    Num(f64, f64),
    /// A whole number (`seed`, ADC codes), drawn within `lo ..= hi` unless odd (ADC codes of
    /// the 65 520 full scale where any draw is a valid calibration: the ends a quarter of full
    /// scale apart or more, outside the rail bands).
    Int(u64, u64),
    /// One of these strings (the last, drawn only when a decision goes the odd way, is one the
    /// reader refuses).
    Str(&'static [&'static str]),
}

use Val::{Int, Num, Str};

/// A key and what it holds.
type Key = (&'static str, Val);

const DUTY: Key = ("duty_percent", Num(0.1, 40.0));
const SPEED: Key = ("min_speed_mm_s", Num(0.0, 1000.0));
const AMPLITUDE: Key = ("amplitude_percent", Num(0.1, 100.0));
/// f_b up to the test board's 2 kHz limit (the reader takes up to 1 MHz; the board refuses).
const F_B: Key = ("f_b_hz", Num(0.001, 2000.0));

/// The region kinds and their keys, as the reader's `spec.rs` lists them. Some ranges are drawn
/// narrower than the reader's so that most draws also pass what is checked later: a grating's
/// lengths are bounded by the substrate (63 mm by default) and must leave room for its rearm,
/// and the eq. 12 parameters must give μs − μc ≤ 100.
const KINDS: &[(&str, &[Key])] = &[
    ("off", &[]),
    ("constant", &[F_B, DUTY]),
    (
        "grating",
        &[
            ("wavelength_mm", Num(0.001, 20.0)),
            ("ridge_mm", Num(0.0, 10.0)),
            ("groove_mm", Num(0.0, 10.0)),
            DUTY,
            SPEED,
            AMPLITUDE,
            ("render", Str(&["position", "velocity", "hybrid", "phase"])),
            ("rearm_mm", Num(0.0, 0.5)),
        ],
    ),
    (
        "material",
        &[
            ("delta_mu", Num(0.0, 100.0)),
            ("e_object_pa", Num(1e5, 1e11)),
            ("nu_object", Num(0.0, 0.5)),
            ("e_skin_pa", Num(1e4, 1e7)),
            ("nu_skin", Num(0.0, 0.5)),
            ("sigma_um", Num(1.0, 100.0)),
            ("beta_um", Num(1.0, 100.0)),
            ("shear_strength_diff_pa", Num(0.0, 1e4)),
            ("normal_force_n", Num(1e-3, 100.0)),
            ("mass_g", Num(1e-3, 1e4)),
            ("stiffness_n_per_m", Num(1e-3, 1e7)),
            DUTY,
            SPEED,
        ],
    ),
    (
        "random",
        &[
            F_B,
            ("spread_percent", Num(0.0, 25.0)),
            AMPLITUDE,
            ("amplitude_spread_percent", Num(0.0, 0.0)),
            DUTY,
            ("seed", Int(0, u64::MAX)),
        ],
    ),
];

const SUBSTRATE: &[Key] = &[
    ("length_mm", Num(1.0, 1000.0)),
    ("code_at_start", Int(700, 16_000)),
    ("code_at_end", Int(40_000, 64_800)),
    ("rail_margin_code", Int(1, 650)),
];

const LIMITS: &[Key] = &[
    ("max_duty_percent", Num(0.1, 100.0)),
    ("max_level_percent", Num(0.1, 100.0)),
    ("max_on_time_ms", Num(0.001, 1000.0)),
    ("stale_after_ms", Num(0.2, 1000.0)),
];

/// `[lines]` besides `positions_mm`.
const LINES: &[Key] = &[
    ("pulse_ms", Num(0.001, 1000.0)),
    ("envelope", Str(&["triangle", "rectangle", "square"])),
    ("amplitude_percent", Num(0.1, 100.0)),
    ("rearm_mm", Num(0.0, 5.0)),
];

/// Values no range should let through, or that stress number reading (TOML spellings the
/// reader must take or refuse with a sentence).
const ODD: &[&str] = &[
    "0",
    "-0.0",
    "-1",
    "1e-9",
    "0.0005",
    "0.0015",
    "1e300",
    "-1e300",
    "inf",
    "-inf",
    "nan",
    "4294967.295",
    "4294967.296",
    "1e6",
    "9223372036854775807",
    "18446744073709551616",
    "1_000",
    "0.1e1",
    "+5",
    "5e-324",
    "2.5E-3",
    "0x10",
    "true",
    "\"5\"",
    "[]",
];

/// The scene file the bytes choose. Never fails: bytes that run out read as the first choice
/// of each decision (which gives a short, valid scene).
pub fn scene_toml(data: &[u8]) -> String {
    let mut u = Unstructured::new(data);
    let mut out = String::new();
    // How often a decision goes the odd way (a value out of range, a key missing or foreign), in
    // 64ths: never for 3 inputs in 8, so that those are valid scenes that reach the controller;
    // up to 1 in 4 for the rest. A scene makes dozens of decisions, so a fixed rate high enough
    // to test refusals would leave few files that get past the first one.
    let odd = [0, 0, 0, 1, 2, 4, 8, 16][u.int_in_range(0..=7).unwrap_or(0)];
    let mut g = Gen {
        u,
        odd,
        out: &mut out,
    };
    // Unstructured errs only when a draw cannot be made; what was written so far is still a
    // scene file to read.
    let _ = g.scene();
    out
}

/// A scene being written from the fuzzer's choices.
struct Gen<'a, 'o> {
    u: Unstructured<'a>,
    /// How often [`Gen::odd`] is true, in 64ths.
    odd: u8,
    out: &'o mut String,
}

impl Gen<'_, '_> {
    /// Whether this decision goes the odd way. False when the bytes have run out (the draw
    /// reads 0), so a short input is a plain scene.
    fn odd(&mut self) -> Result<bool> {
        Ok(self.u.int_in_range(0u8..=63)? >= 64 - self.odd)
    }

    fn line(&mut self, text: core::fmt::Arguments<'_>) {
        let _ = self.out.write_fmt(text);
        self.out.push('\n');
    }

    fn scene(&mut self) -> Result<()> {
        // Top-level keys first: TOML puts them before any table.
        if self.odd()? {
            self.line(format_args!("drive = \"sideways\""));
        } else {
            match self.u.int_in_range(0u8..=2)? {
                0 => {}
                1 => self.line(format_args!("drive = \"standing\"")),
                _ => self.line(format_args!("drive = \"progressive\"")),
            }
        }
        if self.u.arbitrary()? {
            // The reader takes up to 5 mm, but regions must be wider than twice it: drawn
            // within 1 mm (odd draws go past 5).
            let h = self.num(0.0, 1.0)?;
            self.line(format_args!("hysteresis_mm = {h}"));
        }
        let mut length_mm = DEFAULT_LENGTH_UM as f64 / 1000.0;
        if self.u.arbitrary()? {
            self.line(format_args!("\n[substrate]"));
            let mut written = std::vec::Vec::new();
            self.keys(SUBSTRATE, |_| Some(true), &mut written)?;
            // The bound for positions and boundaries below.
            if let Some(l) = written
                .iter()
                .find(|(k, _)| *k == "length_mm")
                .and_then(|(_, v)| v.parse::<f64>().ok())
                .filter(|l| l.is_finite() && *l > 0.0)
            {
                length_mm = l;
            }
        }
        if self.u.arbitrary()? {
            self.line(format_args!("\n[limits]"));
            self.keys(LIMITS, |_| None, &mut std::vec::Vec::new())?;
        }
        let lines_last: bool = self.u.arbitrary()?;
        if !lines_last {
            self.lines(length_mm)?;
        }
        // 1 to 8 regions, the most a scene holds; odd: none or 9.
        let n = match (self.odd()?, self.u.int_in_range(1u8..=8)?) {
            (true, n) if n % 2 == 0 => 0,
            (true, _) => 9,
            (false, n) => n,
        };
        let mut until = 0.0;
        for i in 0..n {
            self.region(i, n, length_mm, &mut until)?;
        }
        if lines_last {
            self.lines(length_mm)?;
        }
        Ok(())
    }

    /// One `[[region]]` of `n`; `until` is where the one before ended.
    fn region(&mut self, i: u8, n: u8, length_mm: f64, until: &mut f64) -> Result<()> {
        self.line(format_args!("\n[[region]]"));
        let (kind, kind_keys) = *self.u.choose(KINDS)?;
        let kind = if self.odd()? { "velvet" } else { kind };
        self.line(format_args!("kind = \"{kind}\""));
        // Every region but the last needs `until_mm`, the last must not have it.
        let last = i + 1 == n;
        if last == self.odd()? {
            // Increasing within the substrate, unless odd: anywhere in it.
            *until = if self.odd()? {
                self.num(0.0, length_mm)?.parse().unwrap_or(0.0)
            } else {
                let step = (length_mm - *until) / f64::from(n - i);
                let width: f64 = self.num(0.0, step.max(0.001) * 1.5)?.parse().unwrap_or(0.0);
                *until + width
            };
            let places = self.u.int_in_range(0..=4)?;
            self.line(format_args!("until_mm = {}", decimal(*until, places)));
        }
        // The keys the kind needs, without the ones it refuses beside them (a grating's
        // wavelength or ridge + groove; a material's delta_mu or eq. 12); odd: any mix.
        let coherent = !self.odd()?;
        let other_way: bool = self.u.arbitrary()?;
        self.keys(
            kind_keys,
            |name| coherent.then(|| needs(kind, other_way, name)).flatten(),
            &mut std::vec::Vec::new(),
        )
    }

    /// `[lines]` (half the time): 0 to 16 positions (odd: 17 or 18, more than the reader
    /// holds), increasing within the substrate (odd: anywhere, any order).
    fn lines(&mut self, length_mm: f64) -> Result<()> {
        if !self.u.arbitrary::<bool>()? {
            return Ok(());
        }
        self.line(format_args!("\n[lines]"));
        // The reader requires the positions: odd, none.
        if !self.odd()? {
            let n = self.u.int_in_range(0u8..=16)? + if self.odd()? { 2 } else { 0 };
            let sorted = !self.odd()?;
            let mut at = 0.0;
            let mut v = std::vec::Vec::new();
            for _ in 0..n {
                if sorted {
                    let gap = length_mm / (f64::from(n) + 1.0);
                    at += self.num(0.0, gap)?.parse::<f64>().unwrap_or(1.0);
                    v.push(decimal(at, self.u.int_in_range(0..=4)?));
                } else {
                    v.push(self.num(0.0, length_mm)?);
                }
            }
            self.line(format_args!("positions_mm = [{}]", v.join(", ")));
        }
        self.keys(LINES, |_| None, &mut std::vec::Vec::new())
    }

    /// Each key written or not, as `want` says: `Some(true)` unless odd, `Some(false)` only if
    /// odd, `None` half the time; and, odd, a key the table does not take (another table's, or
    /// none's). The keys written and their values are added to `written`.
    fn keys(
        &mut self,
        keys: &[Key],
        want: impl Fn(&str) -> Option<bool>,
        written: &mut std::vec::Vec<(&'static str, String)>,
    ) -> Result<()> {
        for &(name, val) in keys {
            let present = match want(name) {
                Some(true) => !self.odd()?,
                Some(false) => self.odd()?,
                None => self.u.arbitrary()?,
            };
            if present {
                let v = self.value(val)?;
                self.line(format_args!("{name} = {v}"));
                written.push((name, v));
            }
        }
        if self.odd()? {
            let all: std::vec::Vec<Key> = KINDS
                .iter()
                .flat_map(|(_, k)| k.iter().copied())
                .chain(LIMITS.iter().copied())
                .chain([("colour", Str(&["red"]))])
                .collect();
            let (name, val) = *self.u.choose(&all)?;
            let v = self.value(val)?;
            self.line(format_args!("{name} = {v}"));
        }
        Ok(())
    }

    /// A value for a key, as TOML text.
    fn value(&mut self, val: Val) -> Result<String> {
        Ok(match val {
            Num(lo, hi) => self.num(lo, hi)?,
            Int(lo, hi) => {
                if self.odd()? {
                    (*self
                        .u
                        .choose(&["-1", "65536", "18446744073709551616", "1.5"])?)
                    .into()
                } else {
                    self.u.int_in_range(lo..=hi)?.to_string()
                }
            }
            Str(choices) => {
                let (valid, refused) = choices.split_at(choices.len() - 1);
                let s = if self.odd()? {
                    refused[0]
                } else {
                    self.u.choose(valid)?
                };
                std::format!("\"{s}\"")
            }
        })
    }

    /// A number for a key accepted within `lo ..= hi`, as TOML text: within the range with 0
    /// to 4 decimals (a third decimal is a µm), or a bound written to 3 decimals; odd: a step
    /// past a bound, an integer, an exponent, an odd spelling or any f64 at all.
    fn num(&mut self, lo: f64, hi: f64) -> Result<String> {
        let places = self.u.int_in_range(0..=4)?;
        let frac = f64::from(self.u.arbitrary::<u32>()?) / f64::from(u32::MAX);
        // Ranges over many decades (a modulus from 1 Pa to 10 TPa) log-uniform, else most
        // draws would sit in the top decade.
        let x = if lo > 0.0 && hi / lo >= 1e3 {
            lo * (hi / lo).powf(frac)
        } else {
            lo + (hi - lo) * frac
        };
        if !self.odd()? {
            let bound = |b: f64| decimal(b, places.max(3));
            return Ok(match self.u.int_in_range(0u8..=9)? {
                8 => bound(lo),
                9 => bound(hi),
                _ => {
                    // Rounding to few places can take a draw out of the range (0.0004 Hz to
                    // "0"): the bound it passed, then.
                    let v = decimal(x, places);
                    match v.parse::<f64>() {
                        Ok(r) if r < lo => bound(lo),
                        Ok(r) if r > hi => bound(hi),
                        _ => v,
                    }
                }
            });
        }
        let step = 10f64.powi(-(places as i32));
        Ok(match self.u.int_in_range(0u8..=5)? {
            0 => decimal(lo - step, places),
            1 => decimal(hi + step, places),
            2 => std::format!("{}", x.round() as i64),
            3 => std::format!("{x:e}"),
            4 => self.u.choose(ODD)?.to_string(),
            _ => {
                let y = self.u.arbitrary::<f64>()?;
                // Rust's NaN spelling is not TOML's.
                if y.is_nan() {
                    "nan".into()
                } else {
                    std::format!("{y:?}")
                }
            }
        })
    }
}

/// Whether a region of `kind` needs `name` (`Some(true)`), refuses it beside the keys it
/// needs (`Some(false)`), or takes it or not (`None`). `other_way` picks a grating's ridge +
/// groove over its wavelength, a material's eq. 12 parameters over its delta_mu.
fn needs(kind: &str, other_way: bool, name: &str) -> Option<bool> {
    const EQ12: &[&str] = &[
        "e_object_pa",
        "nu_object",
        "e_skin_pa",
        "nu_skin",
        "sigma_um",
        "beta_um",
        "shear_strength_diff_pa",
    ];
    match (kind, name) {
        ("constant" | "random", "f_b_hz") => Some(true),
        ("grating", "wavelength_mm") => Some(!other_way),
        ("grating", "ridge_mm" | "groove_mm") => Some(other_way),
        ("material", "delta_mu") => Some(!other_way),
        ("material", n) if EQ12.contains(&n) => Some(other_way),
        _ => None,
    }
}

/// `x` with exactly `places` decimals; at 0 places a TOML integer (`5`), which the reader takes
/// for a number too.
fn decimal(x: f64, places: usize) -> String {
    if !x.is_finite() {
        return std::format!("{x:?}").replace("NaN", "nan");
    }
    std::format!("{x:.places$}")
}

#[cfg(test)]
mod tests {
    use super::scene_toml;
    use saw_core::scene_file::load_for_board;
    use saw_core::texture::Texture;

    /// Random bytes (a fixed xorshift stream) build scenes the reader accepts often enough to
    /// reach past it, with every texture kind, and with the shapes the byte-level mutator
    /// missed: 6 or more lines, and a hysteresis of 1 µm in 5 (docs/fuzzing.md).
    #[test]
    fn random_choices_reach_accepted_scenes_of_every_shape() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let (mut accepted, mut six_lines, mut odd_hysteresis) = (0, 0, 0);
        let mut kinds = [false; 5];
        const N: usize = 2000;
        for _ in 0..N {
            let bytes: std::vec::Vec<u8> = (0..400)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    state as u8
                })
                .collect();
            let text = scene_toml(&bytes);
            let Ok(cfg) = load_for_board("s.toml", &text, crate::testing::TIMER, 100) else {
                continue;
            };
            accepted += 1;
            six_lines += usize::from(cfg.scene.lines.positions_um.len() >= 6);
            odd_hysteresis += usize::from(cfg.scene.hysteresis_um % 5 == 1);
            for t in &cfg.scene.textures {
                kinds[match t {
                    Texture::Off => 0,
                    Texture::Constant(_) => 1,
                    Texture::Grating(_) => 2,
                    Texture::Material(_) => 3,
                    Texture::Random(_) => 4,
                    other => panic!("a kind scene_toml's KINDS lacks: {other:?}"),
                }] = true;
            }
        }
        eprintln!("{accepted} of {N} accepted, {six_lines} with 6+ lines, {odd_hysteresis} with 1 µm in 5");
        // Measured: 264 accepted, 30 with 6+ lines, 5 with 1 µm in 5.
        assert!(accepted >= N / 20, "{accepted} of {N} accepted");
        assert_eq!(kinds, [true; 5], "kinds accepted");
        assert!(
            six_lines >= 5 && odd_hysteresis >= 1,
            "{six_lines} {odd_hysteresis}"
        );
    }
}
