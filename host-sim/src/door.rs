//! Values checked at the door: the clap value parsers of every numeric flag of the `host-sim`
//! binary (the simulator, `model …`, `tile-to-scene`, `bench`), each with its unit and range, and
//! the help text that states them.
//!
//! A refused value never reaches a model: clap prints `error: invalid value 'V' for '--flag
//! <UNIT>': <rule>` on one line and exits with code 2. The rule is one of
//! - `must be from LO to HI UNIT` (out of range),
//! - `must be a finite number from LO to HI UNIT` (NaN, inf),
//! - `not a number; must be from LO to HI UNIT` (anything `f64` does not parse),
//! - `must be a whole number from LO to HI` (integer flags).

use std::path::PathBuf;

/// The numbers a real-valued flag accepts: finite and within `lo..=hi`, in `unit` (empty for a
/// dimensionless ratio).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    /// Smallest value accepted.
    pub lo: f64,
    /// Largest value accepted.
    pub hi: f64,
    /// Unit as the help and the errors print it ("mm/s", "LSB RMS", "" for a ratio).
    pub unit: &'static str,
}

/// `x` as a person writes it in a range: `0.1`, `1000`, `-0.99`, `1e12`, `1e-16`.
pub fn fmt_num(x: f64) -> String {
    let a = x.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

impl Range {
    /// `lo..=hi` in `unit`.
    pub const fn new(lo: f64, hi: f64, unit: &'static str) -> Self {
        Self { lo, hi, unit }
    }

    /// `from 0.1 to 1000 mm/s`.
    pub fn span(&self) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", self.unit)
        };
        format!("from {} to {}{unit}", fmt_num(self.lo), fmt_num(self.hi))
    }

    /// The help line of a flag: `Finger speed, mm/s (0.1 to 1000)`, or `Friction coefficient
    /// (0 to 10)` for a ratio.
    pub fn help(&self, what: &str) -> String {
        let unit = if self.unit.is_empty() {
            String::new()
        } else {
            format!(", {}", self.unit)
        };
        format!(
            "{what}{unit} ({} to {})",
            fmt_num(self.lo),
            fmt_num(self.hi)
        )
    }

    /// `s` as a number of this range, or the rule it breaks.
    pub fn check(&self, s: &str) -> Result<f64, String> {
        let Ok(v) = s.trim().parse::<f64>() else {
            return Err(format!("not a number; must be {}", self.span()));
        };
        if !v.is_finite() {
            return Err(format!("must be a finite number {}", self.span()));
        }
        if v < self.lo || v > self.hi {
            return Err(format!("must be {}", self.span()));
        }
        Ok(v)
    }

    /// The clap value parser of this range.
    pub fn parser(self) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
        move |s: &str| self.check(s)
    }
}

/// The whole numbers an integer flag accepts: `lo..=hi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Whole {
    /// Smallest value accepted.
    pub lo: u64,
    /// Largest value accepted.
    pub hi: u64,
}

impl Whole {
    /// `lo..=hi`.
    pub const fn new(lo: u64, hi: u64) -> Self {
        Self { lo, hi }
    }

    /// The help line of a flag: `Worker threads (1 to 64)`.
    pub fn help(&self, what: &str) -> String {
        format!("{what} ({} to {})", self.lo, self.hi)
    }

    /// `s` as a whole number of this range, or the rule it breaks.
    pub fn check(&self, s: &str) -> Result<u64, String> {
        match s.trim().parse::<u64>() {
            Ok(v) if (self.lo..=self.hi).contains(&v) => Ok(v),
            _ => Err(format!(
                "must be a whole number from {} to {}",
                self.lo, self.hi
            )),
        }
    }

    /// The clap value parser of this range (u64).
    pub fn parser(self) -> impl Fn(&str) -> Result<u64, String> + Clone + Send + Sync + 'static {
        move |s: &str| self.check(s)
    }

    /// The clap value parser of this range (usize; `hi` must fit).
    pub fn parser_usize(
        self,
    ) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync + 'static {
        move |s: &str| self.check(s).map(|v| v as usize)
    }
}

/// Clap value parser of a chart path: the charts are PNG files (plotters' bitmap backend picks
/// the format from the extension), so anything not ending in `.png` is refused before the run.
pub fn png_path(s: &str) -> Result<PathBuf, String> {
    let p = PathBuf::from(s);
    let is_png = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if is_png && p.file_stem().is_some_and(|f| !f.is_empty()) {
        Ok(p)
    } else {
        Err("the chart is a PNG file: the path must end in .png".into())
    }
}

/// Clap value parser of an output directory: anything but an existing file (created if absent).
pub fn out_dir(s: &str) -> Result<PathBuf, String> {
    let p = PathBuf::from(s);
    if s.is_empty() {
        return Err("the output directory must be named".into());
    }
    if p.exists() && !p.is_dir() {
        return Err(
            "a file is there, not a directory: name a directory (created if missing)".into(),
        );
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_print_as_written() {
        assert_eq!(fmt_num(0.1), "0.1");
        assert_eq!(fmt_num(1000.0), "1000");
        assert_eq!(fmt_num(-0.99), "-0.99");
        assert_eq!(fmt_num(0.0), "0");
        assert_eq!(fmt_num(1e12), "1e12");
        assert_eq!(fmt_num(1e-16), "1e-16");
        assert_eq!(fmt_num(999_999.0), "999999");
    }

    #[test]
    fn a_range_refuses_with_its_rule() {
        let r = Range::new(0.1, 1000.0, "mm/s");
        assert_eq!(r.help("Finger speed"), "Finger speed, mm/s (0.1 to 1000)");
        assert_eq!(r.check("60"), Ok(60.0));
        assert_eq!(r.check("0.1"), Ok(0.1));
        assert_eq!(r.check("1000"), Ok(1000.0));
        for (input, want) in [
            ("-10", "must be from 0.1 to 1000 mm/s"),
            ("1000.001", "must be from 0.1 to 1000 mm/s"),
            ("NaN", "must be a finite number from 0.1 to 1000 mm/s"),
            ("-inf", "must be a finite number from 0.1 to 1000 mm/s"),
            ("ten", "not a number; must be from 0.1 to 1000 mm/s"),
        ] {
            assert_eq!(r.check(input).unwrap_err(), want, "{input}");
        }
        let ratio = Range::new(0.0, 10.0, "");
        assert_eq!(
            ratio.help("Friction coefficient"),
            "Friction coefficient (0 to 10)"
        );
        assert_eq!(ratio.check("11").unwrap_err(), "must be from 0 to 10");
    }

    #[test]
    fn whole_numbers_refuse_fractions_and_signs() {
        let w = Whole::new(1, 64);
        assert_eq!(w.check("2"), Ok(2));
        for bad in ["0", "65", "-1", "1.5", "nan", ""] {
            assert_eq!(
                w.check(bad).unwrap_err(),
                "must be a whole number from 1 to 64",
                "{bad}"
            );
        }
        assert_eq!(
            Whole::new(0, u64::MAX).check("18446744073709551615"),
            Ok(u64::MAX)
        );
    }

    #[test]
    fn charts_are_png() {
        assert!(png_path("out/a.png").is_ok());
        assert!(png_path("out/A.PNG").is_ok());
        for bad in ["x.svg", "x.jpg", "out/", "out/x", ".png", "x.png.tmp"] {
            assert_eq!(
                png_path(bad).unwrap_err(),
                "the chart is a PNG file: the path must end in .png",
                "{bad}"
            );
        }
    }
}

/// Parses the command line as `A` when its first argument is `name` (a subcommand the main
/// command line hands over: `bench`, `budget`, `guard`), the program name kept for clap's
/// messages; None otherwise. A bad value exits with clap's one-line error, as the main line does.
pub fn subcommand<A: clap::Parser>(name: &str) -> Option<A> {
    let mut args = std::env::args_os();
    let bin = args.next()?;
    if args.next()? != name {
        return None;
    }
    Some(A::parse_from(std::iter::once(bin).chain(args)))
}

/// The seeds a sweep (`budget`, `guard`) measures each figure over: `--seed` (the base) and
/// `--seeds` (how many, 1 ..= 20), flattened into its arguments.
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct SweepSeeds {
    #[arg(long, default_value_t = 2026, allow_hyphen_values = true,
          help = SWEEP_SEED.help("Base seed"), value_parser = SWEEP_SEED.parser())]
    pub seed: u64,
    #[arg(long, default_value_t = 3, allow_hyphen_values = true,
          help = SWEEP_SEEDS.help("Seeds each figure is measured over"),
          value_parser = SWEEP_SEEDS.parser())]
    pub seeds: u64,
}

const SWEEP_SEED: Whole = Whole::new(0, u64::MAX);
const SWEEP_SEEDS: Whole = Whole::new(1, 20);

/// Creates `out_dir/charts` for a sweep's results (`budget`, `guard`); the error is the one line
/// naming `--out`, the path and the cause.
pub fn charts_dir(out_dir: &std::path::Path) -> Result<PathBuf, String> {
    let charts = out_dir.join("charts");
    std::fs::create_dir_all(&charts).map_err(|e| {
        format!(
            "--out {}: cannot create {}: {e}",
            out_dir.display(),
            charts.display()
        )
    })?;
    Ok(charts)
}
