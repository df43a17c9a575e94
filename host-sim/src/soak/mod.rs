//! `host-sim soak`: random scenes, fingers, sensor faults and scene events for as many samples
//! as asked, every sample and pulse checked online against the safety rules (`docs/soak.md`).
//!
//! The run is cut into episodes of [`EPISODE_SAMPLES`] (1 s), each drawn from (seed, episode
//! index) alone ([`episode::run_episode`]), so a violation at global sample `k` reproduces by
//! running its episode by itself (`--from` its first sample), and episodes spread over the
//! cores (rayon) in chunks, so memory stays constant in `--samples`. The checksum is a CRC-64
//! over the per-episode checksums in episode order: the same whatever the thread count.

pub mod check;
pub mod episode;
pub mod gen;
pub mod gen2d;
pub mod plane;

use std::process::ExitCode;
use std::time::Instant;

use clap::Parser;
use rayon::prelude::*;

pub use check::{Rule, Violation};
pub use episode::{run_episode, EpisodeReport, Plant, EPISODE_SAMPLES};

use crate::door::Whole;

/// The most samples one run takes: 10^12 (3.2 years of use at 10 kHz).
pub const MAX_SAMPLES: u64 = 1_000_000_000_000;
const SAMPLES: Whole = Whole::new(1, MAX_SAMPLES);
const FROM: Whole = Whole::new(0, MAX_SAMPLES);
const SEED: Whole = Whole::new(0, u64::MAX);
const THREADS: Whole = Whole::new(1, 256);
/// Episodes run in parallel per chunk: what stays in memory at once.
const CHUNK_EPISODES: u64 = 64;
/// Violations kept for printing (all are counted).
pub const KEPT: usize = 20;
/// One wrap of the core's µs clock: 2^32 µs.
const WRAP_US: u64 = 1 << 32;
/// The sample period of both boards (10 kHz), µs: global sample `k` is at `k · 100` µs.
const PERIOD_US: u64 = 100;

/// `host-sim soak`: the safety rules over random scenes, fingers and faults.
#[derive(Parser, Debug, Clone)]
#[command(
    name = "host-sim soak",
    about = "Soak the closed loop: random scenes (every texture kind, lines, both drive modes), \
             fingers (rest to 2 m/s strokes, 10 m/s² reversals, tremor), sensor faults and \
             mid-stroke reloads, boundary moves and refused scenes, every sample and pulse \
             checked against the caps, the fault rules and for runts (docs/soak.md). Exit code \
             1 on any violation."
)]
pub struct SoakArgs {
    #[arg(long, value_name = "N", allow_hyphen_values = true, default_value_t = 1_000_000, help = SAMPLES.help("Samples to run, 100 µs each (10^7 = 16.7 min of use)"), value_parser = SAMPLES.parser())]
    pub samples: u64,
    #[arg(long, value_name = "S", allow_hyphen_values = true, default_value_t = 1, help = SEED.help("Seed: the same seed gives the same scenes, faults and checksum"), value_parser = SEED.parser())]
    pub seed: u64,
    #[arg(long, value_name = "K", allow_hyphen_values = true, default_value_t = 0, help = format!("{}, a multiple of {EPISODE_SAMPLES} (an episode's first sample): reruns part of a soak, as a violation's line says", FROM.help("First global sample to run")), value_parser = from_parser)]
    pub from: u64,
    #[arg(long, value_name = "T", allow_hyphen_values = true, help = format!("{} [default: all cores]", THREADS.help("Worker threads")), value_parser = THREADS.parser_usize())]
    pub threads: Option<usize>,
    /// Print one JSON object instead of the summary.
    #[arg(long)]
    pub json: bool,
    /// Soak the 2D plane instead: random 2D scenes, 2D fingers with lift-offs and landings,
    /// touch faults, through the touch sensor and `Controller2d` (docs/soak.md, "The plane").
    #[arg(long)]
    pub plane: bool,
    /// A defect planted in the harness, to see the checks catch it (tests use it).
    #[arg(long, value_enum, default_value_t = Plant::None, hide = true)]
    pub plant: Plant,
}

/// `--from`: a whole number in range that starts an episode.
fn from_parser(s: &str) -> Result<u64, String> {
    let v = FROM.check(s)?;
    if v % EPISODE_SAMPLES != 0 {
        return Err(format!(
            "must be a multiple of {EPISODE_SAMPLES} (episodes start there; {} starts the one \
             holding it)",
            v - v % EPISODE_SAMPLES
        ));
    }
    Ok(v)
}

/// What a soak runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SoakOptions {
    /// Seed.
    pub seed: u64,
    /// First global sample (a multiple of [`EPISODE_SAMPLES`]).
    pub from: u64,
    /// Samples to run.
    pub samples: u64,
    /// Worker threads (None: rayon's default, all cores).
    pub threads: Option<usize>,
    /// A defect planted in the harness.
    pub plant: Plant,
    /// The 2D plane's soak (`--plane`) instead of the 1D one.
    pub plane: bool,
}

/// A violation with the command that reproduces it.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Found {
    /// The violation (its `sample` is the global index).
    #[serde(flatten)]
    pub violation: Violation,
    /// Its episode.
    pub episode: u64,
    /// `host-sim soak …` running its episode by itself.
    pub reproduce: String,
}

/// What a soak did and found.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Summary {
    /// Seed.
    pub seed: u64,
    /// First global sample.
    pub from: u64,
    /// Samples run.
    pub samples: u64,
    /// Episodes run.
    pub episodes: u64,
    /// Simulated time, s.
    pub simulated_s: f64,
    /// Wall time, s.
    pub wall_s: f64,
    /// Simulated over wall time.
    pub ratio: f64,
    /// Worker threads.
    pub threads: usize,
    /// Multiples of 2^32 µs inside the run: the core's clock wrapped this often.
    pub wraps: u64,
    /// Of those, the ones that fell inside an episode (the core ran across them).
    pub wraps_in_episode: u64,
    /// Pulses checked.
    pub pulses: u64,
    /// Fault windows injected, by kind (`open`, `short`, `stale`, `dropped`, `spike`, `drift`,
    /// `spike-train`).
    pub faults: std::collections::BTreeMap<&'static str, u64>,
    /// All fault windows.
    pub faults_total: u64,
    /// Sample periods the injected faults held off.
    pub off_samples: u64,
    /// Scenes reloaded mid-stroke.
    pub reloads: u64,
    /// Boundary moves.
    pub boundary_moves: u64,
    /// Refused loads.
    pub refusals: u64,
    /// Of those, scenes broken on purpose.
    pub broken: u64,
    /// Samples compared against the scene before a refusal.
    pub refusal_samples: u64,
    /// Violations, all rules.
    pub violations: u64,
    /// Violations by rule.
    pub by_rule: std::collections::BTreeMap<&'static str, u64>,
    /// The first [`KEPT`] violations, with their reproducing commands.
    pub found: Vec<Found>,
    /// CRC-64/XZ over the episodes' edge checksums in order, hex.
    pub checksum: String,
    /// The harness's planted defect (`none` for a real soak).
    pub plant: Plant,
    /// The 2D plane's soak (`--plane`): samples are touch frames.
    pub plane: bool,
    /// `--plane`: edge pulses fired.
    pub edge_pulses: u64,
    /// `--plane`: edge crossings the core skipped.
    pub edges_skipped: u64,
    /// `--plane`: oriented-grating ridge pulses.
    pub ridge_pulses: u64,
    /// `--plane`: a rendering finger lifted.
    pub lifts: u64,
    /// `--plane`: the finger's pieces by kind.
    pub moves: std::collections::BTreeMap<&'static str, u64>,
}

/// The command that reruns by itself the episode of `seed` holding global sample `sample`, its
/// first `samples` samples (as many as the soak ran of it: a violation can be judged a few
/// samples after the one it names, at a pulse's fall or the next rise).
pub fn reproduce(seed: u64, sample: u64, samples: u64, plant: Plant, plane: bool) -> String {
    let from = sample - sample % EPISODE_SAMPLES;
    let plant = match plant {
        Plant::None => String::new(),
        p => format!(
            " --plant {}",
            clap::ValueEnum::to_possible_value(&p)
                .map(|v| v.get_name().to_string())
                .unwrap_or_default()
        ),
    };
    let plane = if plane { " --plane" } else { "" };
    format!("host-sim soak{plane} --seed {seed} --from {from} --samples {samples}{plant}")
}

/// Multiples of 2^32 µs in `(from_us, to_us]`.
fn wraps_between(from_us: u64, to_us: u64) -> u64 {
    to_us / WRAP_US - from_us / WRAP_US
}

/// Runs a soak.
pub fn run(opts: &SoakOptions) -> Summary {
    let started = Instant::now();
    let first = opts.from / EPISODE_SAMPLES;
    let end = opts.from.saturating_add(opts.samples);
    let last = end.div_ceil(EPISODE_SAMPLES);
    let pool = opts
        .threads
        .and_then(|n| rayon::ThreadPoolBuilder::new().num_threads(n).build().ok());
    let threads = pool
        .as_ref()
        .map_or_else(rayon::current_num_threads, |p| p.current_num_threads());
    let mut s = Summary {
        seed: opts.seed,
        from: opts.from,
        samples: 0,
        episodes: 0,
        simulated_s: 0.0,
        wall_s: 0.0,
        ratio: 0.0,
        threads,
        // The plane's episodes each run on their board's frame period: its wraps are counted
        // per episode.
        wraps: if opts.plane {
            0
        } else {
            wraps_between(
                opts.from.saturating_mul(PERIOD_US),
                end.saturating_mul(PERIOD_US),
            )
        },
        wraps_in_episode: 0,
        pulses: 0,
        faults: fault_names(opts.plane).iter().map(|k| (*k, 0)).collect(),
        faults_total: 0,
        off_samples: 0,
        reloads: 0,
        boundary_moves: 0,
        refusals: 0,
        broken: 0,
        refusal_samples: 0,
        violations: 0,
        by_rule: Rule::ALL.iter().map(|r| (r.name(), 0)).collect(),
        found: Vec::new(),
        checksum: String::new(),
        plant: opts.plant,
        plane: opts.plane,
        edge_pulses: 0,
        edges_skipped: 0,
        ridge_pulses: 0,
        lifts: 0,
        moves: if opts.plane {
            gen2d::MOVES.iter().map(|k| (*k, 0)).collect()
        } else {
            Default::default()
        },
    };
    let mut combined = episode::CRC64.digest();
    let mut e = first;
    while e < last {
        let chunk_end = (e + CHUNK_EPISODES).min(last);
        let job = || {
            (e..chunk_end)
                .into_par_iter()
                .map(|ep| {
                    let start = ep * EPISODE_SAMPLES;
                    let n = end.min(start + EPISODE_SAMPLES) - start;
                    if opts.plane {
                        plane::run_episode2d(opts.seed, ep, n, opts.plant)
                    } else {
                        run_episode(opts.seed, ep, n, opts.plant)
                    }
                })
                .collect::<Vec<_>>()
        };
        let reports = match &pool {
            Some(p) => p.install(job),
            None => job(),
        };
        for r in reports {
            add(&mut s, &r, opts);
            combined.update(&r.checksum.to_le_bytes());
        }
        e = chunk_end;
    }
    s.checksum = format!("{:016x}", combined.finalize());
    if opts.plane {
        s.wraps = s.wraps_in_episode;
    } else {
        s.simulated_s = s.samples as f64 * PERIOD_US as f64 * 1e-6;
    }
    s.wall_s = started.elapsed().as_secs_f64();
    s.ratio = s.simulated_s / s.wall_s.max(1e-9);
    s
}

fn add(s: &mut Summary, r: &EpisodeReport, opts: &SoakOptions) {
    s.samples += r.samples;
    s.episodes += 1;
    s.wraps_in_episode += u64::from(r.wrapped);
    if opts.plane {
        s.simulated_s += r.samples as f64 * r.frame_us as f64 * 1e-6;
        s.edge_pulses += r.edge_pulses;
        s.edges_skipped += r.edges_skipped;
        s.ridge_pulses += r.ridge_pulses;
        s.lifts += r.lifts;
        for (k, n) in gen2d::MOVES.iter().zip(r.moves) {
            *s.moves.entry(k).or_default() += n;
        }
    }
    s.pulses += r.pulses;
    for (k, n) in fault_names(opts.plane).iter().zip(r.faults) {
        *s.faults.entry(k).or_default() += n;
        s.faults_total += n;
    }
    s.off_samples += r.off_samples;
    s.reloads += r.reloads;
    s.boundary_moves += r.boundary_moves;
    s.refusals += r.refusals;
    s.broken += r.broken;
    s.refusal_samples += r.refusal_samples;
    s.violations += r.violations;
    for (rule, n) in Rule::ALL.iter().zip(r.by_rule) {
        *s.by_rule.entry(rule.name()).or_default() += n;
    }
    for v in &r.kept {
        if s.found.len() < KEPT {
            s.found.push(Found {
                violation: v.clone(),
                episode: r.episode,
                reproduce: reproduce(opts.seed, v.sample, r.samples, opts.plant, opts.plane),
            });
        }
    }
}

/// The fault kinds' names: the 1D soak's or the plane's.
fn fault_names(plane: bool) -> &'static [&'static str; 7] {
    if plane {
        &gen2d::FAULTS_2D
    } else {
        &gen::SOAK_FAULTS
    }
}

/// The summary as a person reads it.
pub fn render(s: &Summary) -> String {
    let mut out = String::new();
    let h = s.simulated_s / 3600.0;
    out.push_str(&format!(
        "soak{}: seed {}, samples {}..{} ({} episodes of {EPISODE_SAMPLES}), {} threads{}\n",
        if s.plane {
            " --plane (2D, a sample is a touch frame)"
        } else {
            ""
        },
        s.seed,
        s.from,
        s.from + s.samples,
        s.episodes,
        s.threads,
        if s.plant == Plant::None {
            String::new()
        } else {
            format!(", planted defect {:?}", s.plant)
        }
    ));
    out.push_str(&format!(
        "simulated {:.1} s ({h:.2} h) in {:.1} s wall: {:.0}× real time\n",
        s.simulated_s, s.wall_s, s.ratio
    ));
    out.push_str(&format!(
        "µs clock wraps crossed: {} ({} inside an episode; the core's u32 µs wraps every 71.6 min)\n",
        s.wraps, s.wraps_in_episode
    ));
    out.push_str(&format!("pulses checked: {}\n", s.pulses));
    if s.plane {
        let moves: Vec<String> = s.moves.iter().map(|(k, n)| format!("{k} {n}")).collect();
        out.push_str(&format!(
            "finger: {}; {} lifts while rendering\nedges: {} pulses ({} crossings skipped), {} ridge pulses\n",
            moves.join(", "),
            s.lifts,
            s.edge_pulses,
            s.edges_skipped,
            s.ridge_pulses
        ));
    }
    let kinds: Vec<String> = s.faults.iter().map(|(k, n)| format!("{k} {n}")).collect();
    out.push_str(&format!(
        "faults injected: {} ({}); {} sample periods held off\n",
        s.faults_total,
        kinds.join(", "),
        s.off_samples
    ));
    out.push_str(&format!(
        "scene events: {} reloads, {} boundary moves, {} refusals ({} broken on purpose; {} samples compared with the scene before)\n",
        s.reloads, s.boundary_moves, s.refusals, s.broken, s.refusal_samples
    ));
    for f in &s.found {
        out.push_str(&format!(
            "VIOLATION {} at sample {} (seed {}, episode {}): {}\n  reproduce: {}\n",
            f.violation.rule.name(),
            f.violation.sample,
            s.seed,
            f.episode,
            f.violation.detail,
            f.reproduce
        ));
    }
    let rules: Vec<String> = s
        .by_rule
        .iter()
        .filter(|(_, n)| **n > 0)
        .map(|(k, n)| format!("{k}: {n}"))
        .collect();
    out.push_str(&format!(
        "violations: {}{}\n",
        s.violations,
        if rules.is_empty() {
            String::new()
        } else {
            format!(" ({})", rules.join(", "))
        }
    ));
    out.push_str(&format!("checksum: crc64 {}\n", s.checksum));
    out
}

/// `host-sim soak …` from the process's arguments; None for any other command.
pub fn run_from_env() -> Option<ExitCode> {
    let args: Vec<std::ffi::OsString> = std::env::args_os().skip(1).collect();
    let (cmd, rest) = args.split_first()?;
    if cmd != "soak" {
        return None;
    }
    let argv =
        std::iter::once(std::ffi::OsString::from("host-sim soak")).chain(rest.iter().cloned());
    let a = match SoakArgs::try_parse_from(argv) {
        Ok(a) => a,
        Err(e) => e.exit(),
    };
    let s = run(&SoakOptions {
        seed: a.seed,
        from: a.from,
        samples: a.samples,
        threads: a.threads,
        plant: a.plant,
        plane: a.plane,
    });
    if a.json {
        match serde_json::to_string(&s) {
            Ok(j) => println!("{j}"),
            Err(e) => {
                eprintln!("error: the summary did not serialise: {e}");
                return Some(ExitCode::FAILURE);
            }
        }
    } else {
        print!("{}", render(&s));
    }
    Some(if s.violations == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}
