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
    // `host-sim help [COMMAND]`: the other commands are dispatched by hand before clap, so
    // clap knows no `help` subcommand; this gives the same text as `--help`.
    let argv: Vec<String> = std::env::args().skip(1).collect();
    // A reader that stops early (`host-sim … | head`) ends the run as it ends `cat`, not with
    // a panic in `println!`: SIGPIPE back to its default, which Rust's runtime sets to ignore.
    // Not for `serve`, whose line may be a socket a host closes: it must see EPIPE and go on.
    if argv.first().map(String::as_str) != Some("serve") {
        // SAFETY: at the start of main, before any thread exists; SIG_DFL installs no handler.
        let _ = unsafe {
            nix::sys::signal::signal(
                nix::sys::signal::Signal::SIGPIPE,
                nix::sys::signal::SigHandler::SigDfl,
            )
        };
    }
    if argv.first().map(String::as_str) == Some("help") {
        return help(&argv[1..]);
    }
    // `host-sim check FILE…`: scene files read as the boards take them, nothing run.
    if let Some(code) = host_sim::check::run_from_env() {
        return code;
    }
    // `host-sim bench …`: the velocity estimators measured (docs/bench-results.md).
    if let Some(code) = host_sim::bench::run_from_env() {
        return code;
    }
    // `host-sim budget …`: lag against noise per ADC configuration (docs/conversion-budget.md).
    if let Some(code) = host_sim::budget::run_from_env() {
        return code;
    }
    // `host-sim touch-budget …`: the touch frame's phases against its period (docs/touch.md).
    if let Some(code) = host_sim::touch_budget::run_from_env() {
        return code;
    }
    // `host-sim guard …`: outlier guards' lag, noise and outlier error (issue #35).
    if let Some(code) = host_sim::guard::run_from_env() {
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
    let refused = |r: Refusal| {
        match &r {
            Refusal::Door(e) => eprintln!("error: {e}\n\nFor more information, try '--help'."),
            Refusal::Scene(e) => eprintln!("error: {e}"),
            Refusal::Run(e) => eprintln!("error: {e}"),
        }
        ExitCode::from(r.exit_code())
    };
    // A 4-wire scene, or a 2D trajectory on the demo screen (issue #36). Its scene check runs
    // the controller's compile, whose refusal log ("previous kept") is a live board's: the file's
    // refusal is the error line below, so the log is held to errors while the plan is made.
    log::set_max_level(args.log.min(log::LevelFilter::Error));
    let plan2d = host_sim::cli2d::plan(&args, &matches);
    log::set_max_level(args.log);
    match plan2d {
        Ok(Some(plan2d)) => {
            return match host_sim::cli2d::run(&args, &plan2d) {
                Ok(()) => ExitCode::SUCCESS,
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Ok(None) => {}
        Err(r) => return refused(r),
    }
    let plan = match cli::plan(&args, &matches) {
        Ok(p) => p,
        Err(r) => return refused(r),
    };
    match run(&args, plan) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `host-sim help` (the simulator's `--help`) or `host-sim help COMMAND` (that command's
/// `--help`, from the command itself, so the two never differ).
fn help(topic: &[String]) -> ExitCode {
    use clap::CommandFactory;
    let names: Vec<&str> = cli::COMMANDS.iter().map(|c| c.0).collect();
    match topic {
        [] => {
            print!("{}", cli::Args::command().render_long_help());
            ExitCode::SUCCESS
        }
        [cmd] if cmd == "help" => help(&[]),
        [cmd] if names.contains(&cmd.as_str()) => {
            let status = std::env::current_exe().and_then(|exe| {
                std::process::Command::new(exe)
                    .args([cmd, "--help"])
                    .status()
            });
            match status {
                Ok(s) if s.success() => ExitCode::SUCCESS,
                Ok(_) => ExitCode::FAILURE,
                Err(e) => {
                    eprintln!("error: cannot run host-sim {cmd} --help: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        [cmd] => {
            eprintln!(
                "error: unknown command '{cmd}': host-sim's commands are {}\n\nFor more \
                 information, try 'host-sim --help'.",
                names.join(", ")
            );
            ExitCode::from(2)
        }
        more => {
            eprintln!(
                "error: host-sim help takes one command name, not '{}'\n\nFor more \
                 information, try 'host-sim --help'.",
                more.join(" ")
            );
            ExitCode::from(2)
        }
    }
}

/// Samples the bare core loop draws for the speed line (3.3 s of the run's trajectory, three
/// legs of the default triangle; its slices run them in turn, from the fresh controller again
/// after the last): 0.26 MB, drawn before the run, so the resident memory the run reports
/// holds them.
const BARE_CORE_SAMPLES: u64 = 32_768;
/// Fewest slices the bare core loop's figure is the mean of: a run too short to have them
/// between its chunks, and a scenario run (which has none), run the rest after it.
const BARE_MIN_SLICES: usize = 32;

fn run(args: &Args, plan: Plan) -> Result<ExitCode, Box<dyn std::error::Error>> {
    let Plan { params, scenario } = plan;
    // The bare core loop the speed line compares with, its input drawn before the run's time
    // starts; a plain run times it in slices between its chunks (`sim::BareCore`).
    let mut bare = sim::BareCore::new(&params, BARE_CORE_SAMPLES)?;
    let started = Instant::now();
    let mut memory: Vec<(f64, u64)> = Vec::new();
    // A scenario's expectations look at the whole trace; a plain run keeps none (constant
    // memory whatever its duration) and computes its figures and chart as it goes.
    let mut busy_s = Vec::new();
    let (header, m, data, recorded) = match &scenario {
        Some(_) => {
            let r = sim::run(&params)?;
            let m = metrics::compute(&r);
            let data = chart::ChartData::of(&r);
            (r.header(), m, data, Some(r))
        }
        None => {
            // Resident memory at simulated 10 s, 100 s, 1000 s, … and the end: flat, since
            // nothing grows with the duration.
            let period_s = sim::sample_period_us(params.board) as f64 * 1e-6;
            let n = sim::samples_in(&params);
            let mut next_mark = (10.0 / period_s) as u64;
            // The index of the next sample to mark (a mark or the last): one comparison a
            // sample.
            let mut due = next_mark.min(n).saturating_sub(1);
            let threads = sim::stream_threads();
            let st = sim::stream_timed(&params, true, threads, Some(&mut bare), |k| {
                if k == due {
                    if let Some(b) = sim::resident_bytes() {
                        memory.push(((k + 1) as f64 * period_s, b));
                    }
                    if k + 1 == next_mark {
                        next_mark = next_mark.saturating_mul(10);
                    }
                    due = next_mark.min(n).saturating_sub(1);
                }
            })?;
            let data = st.chart.ok_or("the streamed run kept no chart")?;
            busy_s = st.busy_s;
            (st.header, st.metrics, data, None)
        }
    };
    // The bare loop's slices ran inside the plain run: not the closed loop's time.
    let sim_s = started.elapsed().as_secs_f64() - bare.spent().1;
    print!("{}", report::summary(&header, &m));
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
    chart::write_png(&data, &m, &output, &title)?;
    println!("chart: {}", output.display());
    let in_run = bare.slices();
    bare.top_up(BARE_MIN_SLICES);
    // The bare loop's CPU time per sample: the mean of its slices, spread over the run as the
    // closed loop's CPU time is (`sim::BareCore`); the quartiles show how much the machine
    // moved it.
    let untimed = "the bare core loop could not be timed";
    let bare_ns = |q| bare.ns_per_sample_at(q).ok_or(untimed);
    let (bare_lo, bare_hi) = (bare_ns(0.25)?, bare_ns(0.75)?);
    let bare_mean = bare.ns_per_sample().ok_or(untimed)?;
    let bare_s = bare_mean * 1e-9;
    let per_sample = sim_s / m.samples.max(1) as f64;
    let period_s = header.sample_period_us as f64 * 1e-6;
    let slices = match in_run {
        0 => format!(
            "{} slices of {} samples after the run",
            bare.slices(),
            sim::BARE_SLICE
        ),
        n if n == bare.slices() => format!(
            "{n} slices of {} samples between the loop's chunks",
            sim::BARE_SLICE
        ),
        n => format!(
            "{} slices of {} samples, {n} between the loop's chunks",
            bare.slices(),
            sim::BARE_SLICE
        ),
    };
    println!(
        "simulated {:.2} s in {:.3} s: {:.0}× real time ({:.0} ns per sample: ADC model, core, \
         timer model, metrics{}); the bare core loop alone runs at {:.0}× ({:.1} ns per sample \
         in CPU time, the mean of {slices}, quartiles {bare_lo:.1}–{bare_hi:.1} ns), so the \
         closed loop costs {:.1}× the core; with the chart written, {:.2} s in all",
        params.duration_s,
        sim_s,
        params.duration_s / sim_s,
        per_sample * 1e9,
        if recorded.is_some() {
            ", whole trace kept".to_string()
        } else {
            match sim::stream_threads() {
                1 => ", chart recording".to_string(),
                n => format!(", chart recording; pipelined on {n} threads"),
            }
        },
        period_s / bare_s,
        bare_mean,
        per_sample / bare_s,
        started.elapsed().as_secs_f64()
    );
    if busy_s.len() > 1 {
        // On a machine busy with other work the threads wait for a CPU: their own time is
        // what an idle machine's wall time would be near.
        let ns: Vec<String> = busy_s
            .iter()
            .map(|b| format!("{:.1}", b / m.samples.max(1) as f64 * 1e9))
            .collect();
        let most = busy_s.iter().copied().fold(0.0, f64::max) / m.samples.max(1) as f64;
        println!(
            "the loop's threads ran {} ns per sample (CPU time; the loop and the feeder): the \
             busier {:.2}× the core",
            ns.join(" and "),
            most / bare_s
        );
    }
    if memory.len() > 1 {
        let marks: Vec<String> = memory
            .iter()
            .map(|(t, b)| format!("{:.1} MB at {t:.0} s", *b as f64 / 1e6))
            .collect();
        println!("resident memory: {}", marks.join(", "));
    }
    if let (Some(sc), Some(r)) = (scenario, recorded) {
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
