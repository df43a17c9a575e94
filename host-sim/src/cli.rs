//! The simulator's command line (`host-sim [flags]`): its flags, each checked at the door
//! ([`crate::door`]), the combinations it refuses, and the run the flags describe.
//!
//! What is checked where:
//! - by clap, while parsing: every number (unit, range, NaN/inf), the board, the trajectory kind,
//!   the chart's extension;
//! - by [`plan`], before anything runs: flags that contradict each other or would be ignored
//!   (`--scenario` with run flags, `--accel` without a ramp, `--to`/`--speed` at rest, `--from` =
//!   `--to` for a motion), and `--from`/`--to` against the travel of the scene actually loaded.
//!
//! Both refuse with exit code 2 and one line: `error: invalid value 'V' for '--flag <UNIT>':
//! <rule>` or `error: <sentence>`.

use std::path::PathBuf;

use clap::builder::{PossibleValuesParser, TypedValueParser};
use clap::parser::ValueSource;
use clap::{ArgMatches, CommandFactory, FromArgMatches, Parser, ValueEnum};
use saw_boards::BoardDef;

use crate::door::{fmt_num, png_path, Range, Whole};
use crate::scenario::Scenario;
use crate::sim::{self, SimParams};
use crate::trajectory::Trajectory;

/// Finger speed (peak speed for the sine, top speed for the ramp).
pub const SPEED: Range = Range::new(0.1, 1000.0, "mm/s");
/// Acceleration of the ramp.
pub const ACCEL: Range = Range::new(0.01, 100.0, "m/s²");
/// ADC noise per conversion: up to 100 LSB RMS (2.4 % of full scale on every conversion).
pub const NOISE: Range = Range::new(0.0, 100.0, "LSB RMS");
/// ADC offset per conversion: at most the 12-bit span either way.
pub const OFFSET: Range = Range::new(-4095.0, 4095.0, "LSB");
/// Simulated time: ten minutes at 10 kHz is 6 million trace points (about 0.7 GB).
/// Simulated time of a plain run, s: up to a day, since a plain run keeps no trace (memory flat
/// in the duration, docs/streaming.md).
pub const DURATION: Range = Range::new(0.01, 86_400.0, "s");
/// Simulated time of a scenario, s: its expectations look at the whole trace, which it keeps
/// (about 100 B per sample).
pub const SCENARIO_DURATION: Range = Range::new(0.01, 600.0, "s");
/// Noise seed.
pub const SEED: Whole = Whole::new(0, u64::MAX);
/// The default run's time when the motion has no end of its own, s.
pub const DEFAULT_DURATION_S: f64 = 3.0;
/// Default distance of `--from` and `--to` from the ends of the travel, mm.
pub const END_MARGIN_MM: f64 = 1.5;

/// Trajectory kinds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Kind {
    /// Triangle back and forth between --from and --to.
    BackAndForth,
    /// Sine back and forth between --from and --to (peak speed = --speed).
    Sine,
    /// At rest at --from.
    Rest,
    /// Constant speed from --from towards --to (and beyond if --duration outlasts the trip).
    Constant,
    /// From --from to --to and back (and beyond --from if --duration outlasts the trip).
    Reversal,
    /// From rest at --from, accelerating at --accel up to --speed towards --to (and beyond if
    /// --duration outlasts the trip).
    Ramp,
    /// 2D: a straight stroke from --from-xy to --to-xy, then rest.
    Line,
    /// 2D: round a circle of --radius about --center-xy.
    Circle,
    /// 2D: a spiral about --center-xy from --r0 out to --radius in --turns turns.
    Spiral,
    /// 2D: a raster of --rows rows over the rectangle from --from-xy to --to-xy.
    Raster,
    /// 2D: straight lines between the timed points of --path FILE (CSV t_s,x_mm,y_mm).
    Path,
}

impl Kind {
    /// A finger path on a 2D screen (run by [`crate::cli2d`], refused with a 1D scene).
    pub fn is_2d(self) -> bool {
        matches!(
            self,
            Kind::Line | Kind::Circle | Kind::Spiral | Kind::Raster | Kind::Path
        )
    }

    /// The name the command line uses (`back-and-forth`).
    pub fn name(self) -> String {
        self.to_possible_value()
            .map(|v| v.get_name().to_string())
            .unwrap_or_default()
    }
}

/// The travel of the default scene, mm.
fn default_travel_mm() -> f64 {
    saw_core::default_config().calibration.length_um as f64 / 1e3
}

fn position_help(what: &str, default: &str) -> String {
    format!(
        "{what}, mm (0 to the end of the travel: {} for the default scene) [default: {default}]",
        fmt_num(default_travel_mm())
    )
}

/// A position: any finite number at the door; [`plan`] checks it against the scene's travel.
fn finite_mm(s: &str) -> Result<f64, String> {
    let rule = format!(
        "from 0 to the end of the travel, {} mm for the default scene",
        fmt_num(default_travel_mm())
    );
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("must be a finite number {rule}")),
        Err(_) => Err(format!("not a number; must be {rule}")),
    }
}

pub fn board_parser() -> impl TypedValueParser<Value = &'static BoardDef> {
    PossibleValuesParser::new(saw_boards::ALL.iter().map(|b| b.name)).map(|name| {
        saw_boards::by_name(&name).unwrap_or(&saw_boards::NUCLEO_F446RE) // listed above
    })
}

fn parse_level(s: &str) -> Result<log::LevelFilter, String> {
    s.parse().map_err(|_| format!("unknown log level {s:?}"))
}

/// The binary's other commands, each dispatched before the simulator's flags are parsed
/// (`main.rs`), with what each does: `--help` lists them, `host-sim help COMMAND` shows one's
/// help.
pub const COMMANDS: [(&str, &str); 9] = [
    (
        "check",
        "scene files (1D or 2D) read as each board takes them, nothing run",
    ),
    (
        "serve",
        "a virtual board behind a pseudo-terminal, for saw and its panel (docs/link.md)",
    ),
    (
        "soak",
        "the safety rules over random scenes, fingers and faults (docs/soak.md)",
    ),
    ("model", "physical models of the display (docs/models.md)"),
    (
        "tile-to-scene",
        "a grooved tile as a scene file's grating region",
    ),
    (
        "bench",
        "the velocity estimators measured and charted (docs/bench-results.md)",
    ),
    (
        "budget",
        "lag against noise per ADC configuration (docs/conversion-budget.md)",
    ),
    (
        "guard",
        "outlier guards: lag against outlier error (docs/conversion-budget.md)",
    ),
    (
        "touch-budget",
        "the touch frame's phases against its period, per board (docs/touch.md)",
    ),
];

/// The commands' list `--help` ends with: one line each.
pub fn commands_help() -> String {
    let mut s = String::from(
        "Commands (each one's flags, units and ranges: host-sim help COMMAND, or host-sim \
         COMMAND --help):\n",
    );
    for (name, what) in COMMANDS {
        s.push_str(&format!("  {name:<14} {what}\n"));
    }
    s.push_str("  help           this help, or a command's: host-sim help serve");
    s
}

/// Host simulation of the SAW tactile display: trajectory → rheostat/ADC → saw-core → burst timer.
#[derive(Parser, Debug, Clone)]
#[command(name = "host-sim", version, after_help = commands_help())]
pub struct Args {
    /// Trajectory kind.
    #[arg(long, value_enum, default_value_t = Kind::BackAndForth)]
    pub trajectory: Kind,
    #[arg(long, value_name = "MM_S", default_value_t = 60.0, allow_hyphen_values = true,
          help = SPEED.help("Finger speed (peak for sine, top for ramp)"), value_parser = SPEED.parser())]
    pub speed: f64,
    #[arg(long, value_name = "MM", allow_hyphen_values = true,
          help = position_help("Start (or rest) position", "1.5"), value_parser = finite_mm)]
    pub from: Option<f64>,
    #[arg(long, value_name = "MM", allow_hyphen_values = true,
          help = position_help("Far turning point (the direction for constant and ramp)",
                               "the end of the travel minus 1.5"),
          value_parser = finite_mm)]
    pub to: Option<f64>,
    #[arg(long, value_name = "M_S2", default_value_t = 2.0, allow_hyphen_values = true,
          help = ACCEL.help("Acceleration of --trajectory ramp"), value_parser = ACCEL.parser())]
    pub accel: f64,
    #[arg(long, value_name = "LSB_RMS", default_value_t = 2.0, allow_hyphen_values = true,
          help = NOISE.help("ADC noise per conversion (12-bit)"), value_parser = NOISE.parser())]
    pub noise: f64,
    #[arg(long, value_name = "LSB", default_value_t = 0.0, allow_hyphen_values = true,
          help = OFFSET.help("ADC offset per conversion (12-bit)"), value_parser = OFFSET.parser())]
    pub offset: f64,
    #[arg(long, value_name = "S", allow_hyphen_values = true,
          help = format!("{} [default: 3; constant and ramp: until the finger reaches --to; \
                          reversal: until it is back at --from; a 2D path: to its end; a 2D run is \
                          at most {} s]", DURATION.help("Simulated time"),
                          crate::cli2d::DURATION_2D.hi),
          value_parser = DURATION.parser())]
    pub duration: Option<f64>,
    #[arg(long, value_name = "SEED", default_value_t = 1, allow_hyphen_values = true,
          help = SEED.help("Noise seed"), value_parser = SEED.parser())]
    pub seed: u64,
    /// Board: its timers, its acquisition and its velocity window (F446: 16 conversions a
    /// sample, 32 samples; G474: 32 conversions, 26 samples).
    #[arg(long, default_value = saw_boards::NUCLEO_F446RE.name, value_parser = board_parser())]
    pub board: &'static BoardDef,
    /// Disable timer preload (ARPE, OCxPE = 0): a new ARR/CCR acts at once, so a 16-bit timer
    /// makes runts and a 32-bit one whose counter has passed a shortened ARR stalls until the
    /// counter wraps (47.7 s at 90 MHz); the summary reports malformed pulses and stalls.
    #[arg(long)]
    pub no_preload: bool,
    /// Draw every ADC conversion's noise (16 Gaussian draws per sample) instead of the sum's
    /// tabulated exact distribution (one draw): the reference the fast path is measured
    /// against, several times slower (docs/streaming.md).
    #[arg(long)]
    pub per_conversion: bool,
    /// Scene file (TOML, see scenes/); default: the built-in default scene.
    #[arg(long, value_name = "FILE")]
    pub scene: Option<PathBuf>,
    /// Run a scenario file instead (its expectations are checked too); it sets the board,
    /// trajectory, noise, seed and duration, so none of those flags go with it.
    #[arg(long, value_name = "FILE")]
    pub scenario: Option<PathBuf>,
    /// Chart path (PNG) [default: out/sim-<scene>.png, named after the scene file (out/sim-default.png
    /// for the built-in scene) or the scenario (out/scenario-<name>.png); a 2D run's
    /// out/sim2d-<scene>.png (out/sim2d-demo.png)].
    #[arg(long, short, value_name = "PNG", value_parser = png_path)]
    pub output: Option<PathBuf>,
    /// Log level of the core's log lines (error, warn, info, debug, trace, off).
    #[arg(long, default_value = "warn", value_parser = parse_level)]
    pub log: log::LevelFilter,
    /// The 2D run's flags (a 4-wire scene, issue #36).
    #[command(flatten)]
    pub two_d: crate::cli2d::Flags2d,
}

/// Parses a command line (`argv[0]` first); clap's error on a refused value.
pub fn parse_from<I, T>(argv: I) -> Result<(Args, ArgMatches), clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let m = Args::command().try_get_matches_from(argv)?;
    let a = Args::from_arg_matches(&m)?;
    Ok((a, m))
}

/// A finger motion as the flags give it, defaults filled in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Kind.
    pub kind: Kind,
    /// `--from`, mm.
    pub from_mm: f64,
    /// `--to`, mm.
    pub to_mm: f64,
    /// `--speed`, mm/s.
    pub speed_mm_s: f64,
    /// `--accel`, m/s².
    pub accel_m_s2: f64,
}

impl Motion {
    /// The trajectory (µm) of this motion.
    pub fn trajectory(&self) -> Trajectory {
        let (a, b, v) = (self.from_mm * 1e3, self.to_mm * 1e3, self.speed_mm_s * 1e3);
        match self.kind {
            Kind::BackAndForth => Trajectory::Triangle {
                a_um: a,
                b_um: b,
                speed_um_s: v,
            },
            Kind::Sine => Trajectory::Sine {
                a_um: a,
                b_um: b,
                period_s: std::f64::consts::PI * (b - a).abs() / v,
            },
            // 2D kinds never get here: `plan` refuses them with a 1D scene.
            Kind::Rest | Kind::Line | Kind::Circle | Kind::Spiral | Kind::Raster | Kind::Path => {
                Trajectory::Rest { at_um: a }
            }
            Kind::Constant => Trajectory::Constant {
                from_um: a,
                speed_um_s: v * (b - a).signum(),
            },
            Kind::Reversal => Trajectory::Reversal {
                from_um: a,
                turn_um: b,
                speed_um_s: v,
            },
            Kind::Ramp => Trajectory::Ramp {
                from_um: a,
                v0_um_s: 0.0,
                accel_um_s2: self.accel_m_s2 * 1e6 * (b - a).signum(),
                v_max_um_s: v,
            },
        }
    }

    /// How long the motion lasts on its own, s: constant and ramp until the finger reaches
    /// `--to`, reversal until it is back at `--from`; `None` for the periodic kinds and rest.
    pub fn trip_s(&self) -> Option<f64> {
        let d = (self.to_mm - self.from_mm).abs();
        let v = self.speed_mm_s;
        match self.kind {
            Kind::BackAndForth | Kind::Sine | Kind::Rest => None,
            Kind::Line | Kind::Circle | Kind::Spiral | Kind::Raster | Kind::Path => None,
            Kind::Constant => Some(d / v),
            Kind::Reversal => Some(2.0 * d / v),
            Kind::Ramp => {
                let a = self.accel_m_s2 * 1e3; // mm/s²
                let d_acc = v * v / (2.0 * a);
                Some(if d <= d_acc {
                    (2.0 * d / a).sqrt()
                } else {
                    v / a + (d - d_acc) / v
                })
            }
        }
    }

    /// The run's time when `--duration` is not given: the trip (at least [`DURATION`]'s
    /// smallest), or [`DEFAULT_DURATION_S`].
    pub fn default_duration_s(&self) -> f64 {
        self.trip_s()
            .map_or(DEFAULT_DURATION_S, |t| t.clamp(DURATION.lo, DURATION.hi))
    }
}

/// Why the flags do not make a run.
#[derive(Debug)]
pub enum Refusal {
    /// A value or a combination refused at the door (exit code 2); the sentence after `error: `.
    Door(String),
    /// The `--scene` file refused, by the reader's rules or the board's (exit code 2, as `saw
    /// push` and `host-sim serve` refuse a scene file, docs/scenes.md): `file:line:col: `field`:
    /// sentence`, at the value at fault.
    Scene(saw_core::scene_file::SceneFileError),
    /// A file the flags name could not be used: unreadable, or a scenario that cannot run (exit
    /// code 1).
    Run(Box<dyn std::error::Error>),
}

impl Refusal {
    /// The exit code: 2 for a flag or a scene file refused, 1 for a file that cannot be used.
    pub fn exit_code(&self) -> u8 {
        match self {
            Refusal::Door(_) | Refusal::Scene(_) => 2,
            Refusal::Run(_) => 1,
        }
    }

    fn value(flag: &str, m: &ArgMatches, id: &str, rule: String) -> Self {
        Refusal::Door(format!(
            "invalid value '{}' for '{flag}': {rule}",
            raw(m, id).unwrap_or_default()
        ))
    }
}

/// What the user typed for flag `id` (None when it came from a default).
pub(crate) fn raw(m: &ArgMatches, id: &str) -> Option<String> {
    if m.value_source(id) != Some(ValueSource::CommandLine) {
        return None;
    }
    m.get_raw(id)
        .and_then(|mut v| v.next_back())
        .map(|v| v.to_string_lossy().into_owned())
}

/// `--flag V` as typed (`--flag` alone for a switch), for the sentences of refused combinations;
/// None when the flag was not given.
pub(crate) fn given(m: &ArgMatches, id: &str) -> Option<String> {
    let flag = format!("--{}", id.replace('_', "-"));
    let v = raw(m, id)?;
    Some(if SWITCHES.contains(&id) {
        flag
    } else {
        format!("{flag} {v}")
    })
}

/// The flags without a value.
const SWITCHES: [&str; 3] = ["no_preload", "per_conversion", "json"];

/// A run the flags describe: its parameters, and the scenario it checks (if `--scenario`).
#[derive(Debug)]
pub struct Plan {
    /// What to simulate.
    pub params: SimParams,
    /// The scenario file's expectations.
    pub scenario: Option<Scenario>,
}

/// The chart's path: `-o` as given, else named after what runs, so a run of one scene never
/// overwrites another's chart: `out/sim-<scene file stem>.png`, `out/sim-default.png` for the
/// built-in scene, `out/scenario-<file stem>.png` for a scenario.
pub fn chart_path(args: &Args) -> PathBuf {
    if let Some(p) = &args.output {
        return p.clone();
    }
    let stem = |p: &PathBuf| {
        p.file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    PathBuf::from("out").join(match (&args.scenario, &args.scene) {
        (Some(sc), _) => format!("scenario-{}.png", stem(sc)),
        (None, Some(scene)) => format!("sim-{}.png", stem(scene)),
        (None, None) => "sim-default.png".to_string(),
    })
}

/// The name a chart title gives the scene: the file's stem, or "default scene".
pub fn scene_label(args: &Args) -> String {
    match &args.scene {
        Some(p) => format!(
            "scene {}",
            p.file_stem()
                .map(|s| s.to_string_lossy())
                .unwrap_or_default()
        ),
        None => "default scene".to_string(),
    }
}

/// The flags [`Args::scenario`] sets itself.
const SCENARIO_SETS: [&str; 13] = [
    "trajectory",
    "speed",
    "from",
    "to",
    "accel",
    "noise",
    "offset",
    "duration",
    "seed",
    "board",
    "no_preload",
    "per_conversion",
    "scene",
];

/// The run the flags describe, or why there is none.
pub fn plan(args: &Args, m: &ArgMatches) -> Result<Plan, Refusal> {
    // A 2D kind or flag has no 1D meaning (main runs a 2D scene before coming here).
    crate::cli2d::refuse_in_1d(args, m)?;
    if let Some(path) = &args.scenario {
        let ignored: Vec<String> = SCENARIO_SETS.iter().filter_map(|id| given(m, id)).collect();
        if !ignored.is_empty() {
            return Err(Refusal::Door(format!(
                "--scenario takes the board, trajectory, noise, seed, duration and scene from \
                 its file; {} would be ignored: give one or the other",
                ignored.join(", ")
            )));
        }
        let sc = Scenario::from_file(path)
            .map_err(|e| Refusal::Run(format!("{}: {e}", path.display()).into()))?;
        let params = sc
            .params()
            .map_err(|e| Refusal::Run(format!("{}: {e}", path.display()).into()))?;
        if !(SCENARIO_DURATION.lo..=SCENARIO_DURATION.hi).contains(&params.duration_s) {
            return Err(Refusal::Run(
                format!(
                    "{}: the scenario lasts {} s; it must last {} (a scenario keeps its whole \
                     trace)",
                    path.display(),
                    params.duration_s,
                    SCENARIO_DURATION.span()
                )
                .into(),
            ));
        }
        return Ok(Plan {
            params,
            scenario: Some(sc),
        });
    }
    let kind = args.trajectory;
    if args.trajectory != Kind::Ramp {
        if let Some(a) = given(m, "accel") {
            return Err(Refusal::Door(format!(
                "{a} is the acceleration of --trajectory ramp; --trajectory {} would ignore it",
                kind.name()
            )));
        }
    }
    if kind == Kind::Rest {
        let ignored: Vec<String> = ["to", "speed"]
            .iter()
            .filter_map(|id| given(m, id))
            .collect();
        if !ignored.is_empty() {
            return Err(Refusal::Door(format!(
                "--trajectory rest stays at --from; {} would be ignored",
                ignored.join(", ")
            )));
        }
    }
    let board = args.board;
    let (config, scene_name) = match &args.scene {
        None => (saw_core::default_config(), "the default scene".to_string()),
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| Refusal::Run(format!("--scene {}: {e}", path.display()).into()))?;
            let config = saw_core::scene_file::load_for_board(
                &path.display().to_string(),
                &text,
                sim::burst_timer(board),
                sim::sample_period_us(board),
            )
            .map_err(Refusal::Scene)?;
            (config, path.display().to_string())
        }
    };
    let travel_mm = config.calibration.length_um as f64 / 1e3;
    let margin = END_MARGIN_MM.min(travel_mm / 4.0);
    let motion = Motion {
        kind,
        from_mm: args.from.unwrap_or(margin),
        to_mm: args.to.unwrap_or(travel_mm - margin),
        speed_mm_s: args.speed,
        accel_m_s2: args.accel,
    };
    for (id, flag, v) in [
        ("from", "--from <MM>", motion.from_mm),
        ("to", "--to <MM>", motion.to_mm),
    ] {
        if !(0.0..=travel_mm).contains(&v) {
            let rule = format!(
                "must be from 0 to {} mm, the travel of {scene_name}",
                fmt_num(travel_mm)
            );
            return Err(Refusal::value(flag, m, id, rule));
        }
    }
    if kind != Kind::Rest && motion.from_mm == motion.to_mm {
        let show = |id: &str, v: f64| match raw(m, id) {
            Some(r) => format!("--{id} {r}"),
            None => format!("--{id} {} (its default)", fmt_num(v)),
        };
        return Err(Refusal::Door(format!(
            "{} and {} are the same point; --trajectory {} moves between them, so they must differ",
            show("from", motion.from_mm),
            show("to", motion.to_mm),
            kind.name()
        )));
    }
    let duration_s = args.duration.unwrap_or_else(|| motion.default_duration_s());
    let mut params = SimParams::new(board, motion.trajectory(), duration_s)
        .with_config(config)
        .with_noise(args.noise, args.seed)
        .with_offset(args.offset);
    params.preload = !args.no_preload;
    params.adc.per_conversion = args.per_conversion;
    Ok(Plan {
        params,
        scenario: None,
    })
}
