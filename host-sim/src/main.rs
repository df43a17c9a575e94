//! `cargo run --release -p host-sim`: simulates the default scene and prints a summary.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Parser, ValueEnum};
use host_sim::scenario::Scenario;
use host_sim::sim::{self, SimParams};
use host_sim::trajectory::Trajectory;
use host_sim::{chart, metrics, report};

#[derive(Clone, Copy, Debug, ValueEnum)]
enum Kind {
    /// Triangle back and forth between --from and --to.
    BackAndForth,
    /// Sine back and forth between --from and --to (peak speed = --speed).
    Sine,
    /// At rest at --from.
    Rest,
    /// Constant speed from --from towards --to (and beyond).
    Constant,
    /// From --from to --to and back.
    Reversal,
    /// From rest at --from, accelerating at --accel up to --speed.
    Ramp,
}

/// Host simulation of the SAW tactile display: trajectory → rheostat/ADC → saw-core → burst timer.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Trajectory kind.
    #[arg(long, value_enum, default_value_t = Kind::BackAndForth)]
    trajectory: Kind,
    /// Finger speed, mm/s.
    #[arg(long, default_value_t = 60.0)]
    speed: f64,
    /// Start (or rest) position, mm.
    #[arg(long, default_value_t = 1.5)]
    from: f64,
    /// Far turning point, mm.
    #[arg(long, default_value_t = 61.5)]
    to: f64,
    /// Acceleration for --trajectory ramp, m/s².
    #[arg(long, default_value_t = 2.0)]
    accel: f64,
    /// ADC noise per conversion, 12-bit LSB RMS.
    #[arg(long, default_value_t = 2.0)]
    noise: f64,
    /// ADC offset per conversion, 12-bit LSB.
    #[arg(long, default_value_t = 0.0)]
    offset: f64,
    /// Simulated time, s.
    #[arg(long, default_value_t = 3.0)]
    duration: f64,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Board: nucleo-f446re or nucleo-g474re.
    #[arg(long, default_value = "nucleo-f446re")]
    board: String,
    /// Disable timer preload (shows the runts preload prevents).
    #[arg(long)]
    no_preload: bool,
    /// Scene file (TOML, see scenes/); default: the built-in default scene.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Run a scenario file instead (its expectations are checked too).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Chart path.
    #[arg(long, short, default_value = "out/sim-default.png")]
    output: PathBuf,
    /// Log level of the core's log lines (error, warn, info, debug, trace, off).
    #[arg(long, default_value = "warn", value_parser = parse_level)]
    log: log::LevelFilter,
}

fn parse_level(s: &str) -> Result<log::LevelFilter, String> {
    s.parse().map_err(|_| format!("unknown log level {s:?}"))
}

struct StderrLog;

impl log::Log for StderrLog {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::max_level()
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) {
            eprintln!("[{:5} {}] {}", r.level(), r.target(), r.args());
        }
    }
    fn flush(&self) {}
}

fn main() -> ExitCode {
    // `host-sim bench …`: the velocity estimators measured (docs/bench-results.md).
    if let Some(code) = host_sim::bench::run_from_env() {
        return code;
    }
    // `host-sim model …` and `host-sim tile-to-scene …`: physical models (docs/models.md).
    if let Some(code) = host_sim::models::cli::run_from_env() {
        return code;
    }
    let args = Args::parse();
    let _ = log::set_logger(&StderrLog);
    log::set_max_level(args.log);
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args) -> Result<ExitCode, Box<dyn std::error::Error>> {
    let started = Instant::now();
    let (params, scenario) = match &args.scenario {
        Some(path) => {
            let sc = Scenario::from_file(path)?;
            (sc.params()?, Some(sc))
        }
        None => {
            let board = saw_boards::by_name(&args.board)
                .ok_or_else(|| format!("unknown board {:?}", args.board))?;
            let (a, b, v) = (args.from * 1e3, args.to * 1e3, args.speed * 1e3);
            let trajectory = match args.trajectory {
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
                Kind::Rest => Trajectory::Rest { at_um: a },
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
                    accel_um_s2: args.accel * 1e6 * (b - a).signum(),
                    v_max_um_s: v,
                },
            };
            let mut p = SimParams::new(board, trajectory, args.duration)
                .with_noise(args.noise, args.seed)
                .with_offset(args.offset);
            p.preload = !args.no_preload;
            if let Some(path) = &args.scene {
                let text = std::fs::read_to_string(path)
                    .map_err(|e| format!("{}: {e}", path.display()))?;
                p.config = saw_core::scene_file::load_for_board(
                    &path.display().to_string(),
                    &text,
                    sim::burst_timer(board),
                    sim::sample_period_us(board),
                )?;
            }
            (p, None)
        }
    };
    let r = sim::run(&params)?;
    let m = metrics::compute(&r);
    print!("{}", report::summary(&r, &m));
    if let Some(dir) = args.output.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    let title = match &scenario {
        Some(sc) => format!("scenario: {}", sc.name),
        None => format!(
            "{} — {} — noise {} LSB RMS",
            params.board.name,
            params.trajectory.describe(),
            params.adc.noise_lsb_rms
        ),
    };
    chart::write_png(&r, &args.output, &title)?;
    println!("chart: {}", args.output.display());
    println!(
        "simulated {:.2} s in {:.2} s",
        params.duration_s,
        started.elapsed().as_secs_f64()
    );
    if let Some(sc) = scenario {
        let fails = sc.check(&r, &m);
        if fails.is_empty() {
            println!("scenario {:?}: all expectations met", sc.name);
        } else {
            for f in &fails {
                println!("FAIL: {f}");
            }
            return Ok(ExitCode::FAILURE);
        }
    }
    Ok(ExitCode::SUCCESS)
}
