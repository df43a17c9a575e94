//! `cargo run --release -p host-sim`: simulates the default scene and prints a summary.

use std::process::ExitCode;
use std::time::Instant;

use host_sim::cli::{self, Args, Plan, Refusal};
use host_sim::{chart, metrics, report, sim};

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
    // `host-sim serve …`: a virtual board behind a pty, for `saw` (docs/link.md). It logs
    // what the firmware logs (boot scene, refusals) at info.
    if std::env::args().nth(1).as_deref() == Some("serve") {
        let _ = log::set_logger(&StderrLog);
        log::set_max_level(log::LevelFilter::Info);
    }
    if let Some(code) = host_sim::serve::run_from_env() {
        return code;
    }
    // `host-sim soak …`: the safety rules over random scenes, fingers and faults (docs/soak.md).
    if let Some(code) = host_sim::soak::run_from_env() {
        return code;
    }
    // `host-sim model …` and `host-sim tile-to-scene …`: physical models (docs/models.md).
    if let Some(code) = host_sim::models::cli::run_from_env() {
        return code;
    }
    let (args, matches) = match cli::parse_from(std::env::args_os()) {
        Ok(p) => p,
        Err(e) => e.exit(),
    };
    let _ = log::set_logger(&StderrLog);
    log::set_max_level(args.log);
    let plan = match cli::plan(&args, &matches) {
        Ok(p) => p,
        Err(Refusal::Door(e)) => {
            eprintln!("error: {e}\n\nFor more information, try '--help'.");
            return ExitCode::from(2);
        }
        Err(Refusal::Run(e)) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    match run(&args, plan) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run(args: &Args, plan: Plan) -> Result<ExitCode, Box<dyn std::error::Error>> {
    let started = Instant::now();
    let Plan { params, scenario } = plan;
    let r = sim::run(&params)?;
    let m = metrics::compute(&r);
    print!("{}", report::summary(&r, &m));
    let output = cli::chart_path(args);
    if let Some(dir) = output.parent() {
        if !dir.as_os_str().is_empty() {
            std::fs::create_dir_all(dir)?;
        }
    }
    let mut title = match &scenario {
        Some(sc) => format!("scenario: {}", sc.name),
        None => format!(
            "{} — {} — {} — noise {} LSB RMS",
            cli::scene_label(args),
            params.board.name,
            params.trajectory.describe(),
            params.adc.noise_lsb_rms
        ),
    };
    if m.off_travel.samples > 0 {
        title.push_str(&format!(
            " — finger off the travel in {:.0} % of the run",
            100.0 * m.off_travel.samples as f64 / m.samples.max(1) as f64
        ));
    }
    chart::write_png(&r, &output, &title)?;
    println!("chart: {}", output.display());
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
