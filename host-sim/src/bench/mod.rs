//! `host-sim bench`: the velocity estimators measured against each other.
//!
//! One command, reproducible from its seed: every scenario is generated once from the seed by
//! the rheostat/ADC model ([`crate::adc`]) over a trajectory ([`crate::trajectory`]) and replayed
//! to every method ([`methods::all`]), so all methods see the very same noise. Per method:
//! velocity RMS and worst error (reference motion, 2 LSB, 10 kHz), the lag measured under
//! acceleration at 20 mm/s, reversals, outliers and dropped samples, spurious grating bursts at
//! rest (3 LSB, 10 s), sweeps over speed, noise and sample rate, and the cost per sample counted
//! by callgrind ([`cost`]). Writes `bench-results.md` and `charts/estimators-*.png` under the
//! output directory (the repository's `docs/`).

pub mod charts;
pub mod cost;
pub mod measure;
pub mod methods;
pub mod renderers;
pub mod scenario;

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use measure::{bursts, errors, pool, replay, Errors};
use methods::{Method, DEFAULT, FOAW_CANDIDATES};
use saw_core::texture::GratingRender;
use scenario::{reference_spec, Obs, Spec};

/// Bench options.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// Seed of every scenario.
    pub seed: u64,
    /// Where `bench-results.md` and `charts/` go.
    pub out_dir: PathBuf,
    /// Worker threads.
    pub threads: usize,
    /// Skip the callgrind cost runs.
    pub skip_cost: bool,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            seed: 2026,
            out_dir: PathBuf::from("docs"),
            threads: 2,
            skip_cost: false,
        }
    }
}

/// Speeds of the speed sweep, mm/s.
pub const SPEEDS_MM_S: [f64; 9] = [1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 300.0];
/// Noise levels of the noise sweep, 12-bit LSB RMS per conversion.
pub const NOISES_LSB: [f64; 5] = [0.0, 1.0, 2.0, 3.0, 4.0];
/// Sample rates of the rate sweep, Hz.
pub const RATES_HZ: [u32; 4] = [1_000, 5_000, 10_000, 20_000];
/// Grating period for the burst count, µm.
pub const LAMBDA_UM: f64 = 1_000.0;
/// The core grating's start threshold, µm/s (stops below half).
pub const GRATING_START_UM_S: f64 = 5_000.0;
/// A raised start threshold evaluated alongside (the report's proposal for target 3).
pub const GRATING_START_HIGH_UM_S: f64 = 15_000.0;

/// Everything measured for one method.
#[derive(Clone, Debug, Default)]
pub struct MethodResult {
    /// Method name.
    pub name: String,
    /// Declared group delay at constant speed (the trait's figure), µs.
    pub declared_delay_us: u32,
    /// Reference motion, 2 LSB, 10 kHz.
    pub mixed: Errors,
    /// Lag measured under 0.5 m/s² through 15–25 mm/s, µs.
    pub delay: Errors,
    /// Constant 20 mm/s, 2 LSB.
    pub steady20: Errors,
    /// Triangle with instant reversals.
    pub reversals: Errors,
    /// Reference motion with outliers and dropped samples.
    pub outliers: Errors,
    /// Spurious bursts at rest over 10 s, 3 LSB: raw velocity synthesis, and with the core
    /// grating's threshold.
    pub bursts_raw: u64,
    /// See `bursts_raw`.
    pub bursts_gated: u64,
    /// As `bursts_gated` with the start threshold at [`GRATING_START_HIGH_UM_S`].
    pub bursts_gated_high: u64,
    /// RMS |v| at rest, 3 LSB, µm/s.
    pub rest_rms_um_s: f64,
    /// Largest |v| at rest, 3 LSB, µm/s: the smallest start threshold that keeps a grating
    /// silent there.
    pub rest_max_um_s: f64,
    /// (speed mm/s, RMS µm/s).
    pub by_speed: Vec<(f64, f64)>,
    /// (noise LSB, RMS µm/s).
    pub by_noise: Vec<(f64, f64)>,
    /// (rate Hz, RMS µm/s).
    pub by_rate: Vec<(f64, f64)>,
    /// Instructions per sample (callgrind), if measured.
    pub cost_ir: Option<f64>,
    /// The core's grating renderers driven by this estimator in the closed loop, on the mixed
    /// motion with a λ = 1 mm grating: position phase (the estimator sizes the pulses) and
    /// velocity synthesis (the estimator sets f_b, hence where the bursts fall).
    pub grating_phase: Option<renderers::RenderStats>,
    /// See `grating_phase`.
    pub grating_synth: Option<renderers::RenderStats>,
}

/// Scenario identifiers.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Key {
    Mixed(u64),
    Delay(u64),
    Reversal(u64),
    Outliers(u64),
    Rest,
    Speed(usize, u64),
    Noise(usize),
    Rate(usize),
}

fn specs(seed: u64) -> Vec<(Key, Spec)> {
    let mut v = Vec::new();
    for i in 0..4 {
        let mut s = reference_spec(seed + i);
        s.seed = seed.wrapping_mul(31).wrapping_add(100 + i);
        v.push((Key::Mixed(i), s));
    }
    for i in 0..40 {
        let (t, d) = scenario::delay_probe();
        let mut s = Spec::new(t, d, 2.0, 10_000);
        s.seed = seed.wrapping_mul(31).wrapping_add(200 + i);
        v.push((Key::Delay(i), s));
    }
    for i in 0..2 {
        let (t, d) = scenario::reversals();
        let mut s = Spec::new(t, d, 2.0, 10_000);
        s.seed = seed.wrapping_mul(31).wrapping_add(300 + i);
        v.push((Key::Reversal(i), s));
    }
    for i in 0..2 {
        let mut s = reference_spec(0);
        s.seed = seed.wrapping_mul(31).wrapping_add(400 + i);
        s.outlier_prob = 1e-3;
        s.drop_prob = 2e-3;
        v.push((Key::Outliers(i), s));
    }
    {
        let mut s = Spec::new(scenario::rest(), 10.0, 3.0, 10_000);
        s.seed = seed.wrapping_mul(31).wrapping_add(500);
        s.warmup_s = 0.0;
        v.push((Key::Rest, s));
    }
    for (k, &mm_s) in SPEEDS_MM_S.iter().enumerate() {
        for i in 0..2 {
            let (t, d) = scenario::constant(mm_s * 1_000.0);
            let mut s = Spec::new(t, d, 2.0, 10_000);
            s.seed = seed.wrapping_mul(31).wrapping_add(600 + 10 * k as u64 + i);
            v.push((Key::Speed(k, i), s));
        }
    }
    for (k, &lsb) in NOISES_LSB.iter().enumerate() {
        let mut s = reference_spec(0);
        s.noise_lsb = lsb;
        s.seed = seed.wrapping_mul(31).wrapping_add(700 + k as u64);
        v.push((Key::Noise(k), s));
    }
    for (k, &hz) in RATES_HZ.iter().enumerate() {
        let mut s = reference_spec(0);
        s.rate_hz = hz;
        s.seed = seed.wrapping_mul(31).wrapping_add(800 + k as u64);
        v.push((Key::Rate(k), s));
    }
    v
}

/// Runs `f(i)` for i in 0..n on `threads` threads, results in order.
pub fn par_map<T: Send>(n: usize, threads: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = AtomicUsize::new(0);
    let out: Mutex<Vec<Option<T>>> = Mutex::new((0..n).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..threads.max(1) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                if i >= n {
                    break;
                }
                let r = f(i);
                out.lock().unwrap()[i] = Some(r);
            });
        }
    });
    out.into_inner()
        .unwrap()
        .into_iter()
        .map(|o| o.expect("every job ran"))
        .collect()
}

/// The declared delay at a steady speed: after a noiseless ramp of 2 µm per sample.
fn declared_delay(m: &Method) -> u32 {
    let mut e = (m.build)(100);
    for i in 0..300u32 {
        e.update(10_000 + 2 * i as i32, i * 100);
    }
    e.group_delay_us()
}

fn measure_method(m: &Method, streams: &BTreeMap<Key, (Spec, Vec<Obs>)>) -> MethodResult {
    let mut r = MethodResult {
        name: m.name.to_string(),
        declared_delay_us: declared_delay(m),
        ..MethodResult::default()
    };
    let mut mixed = Vec::new();
    let mut delay = Vec::new();
    let mut rev = Vec::new();
    let mut outl = Vec::new();
    let mut speed: BTreeMap<usize, Vec<Errors>> = BTreeMap::new();
    for (key, (spec, stream)) in streams {
        let out = replay(m, stream, spec.period_us());
        let e = errors(stream, &out);
        match key {
            Key::Mixed(_) => mixed.push(e),
            Key::Delay(_) => delay.push(e),
            Key::Reversal(_) => rev.push(e),
            Key::Outliers(_) => outl.push(e),
            Key::Rest => {
                let (raw, gated) = bursts(&out, spec.period_us(), LAMBDA_UM, GRATING_START_UM_S);
                r.bursts_raw = raw;
                r.bursts_gated = gated;
                r.bursts_gated_high =
                    bursts(&out, spec.period_us(), LAMBDA_UM, GRATING_START_HIGH_UM_S).1;
                r.rest_rms_um_s = e.rms_um_s;
                r.rest_max_um_s = e.max_abs_um_s;
            }
            Key::Speed(k, _) => speed.entry(*k).or_default().push(e),
            Key::Noise(k) => r.by_noise.push((NOISES_LSB[*k], e.rms_um_s)),
            Key::Rate(k) => r.by_rate.push((RATES_HZ[*k] as f64, e.rms_um_s)),
        }
    }
    r.mixed = pool(&mixed);
    r.delay = pool(&delay);
    r.reversals = pool(&rev);
    r.outliers = pool(&outl);
    for (k, parts) in speed {
        let p = pool(&parts);
        r.by_speed.push((SPEEDS_MM_S[k], p.rms_um_s));
        if SPEEDS_MM_S[k] == 20.0 {
            r.steady20 = p;
        }
    }
    r
}

/// Runs the whole bench and writes the report; returns the per-method results.
pub fn run(opts: &BenchOptions) -> Result<Vec<MethodResult>, String> {
    let all = methods::all();
    if let Ok(name) = std::env::var(cost::COST_ENV) {
        let m = all
            .iter()
            .find(|m| m.name == name)
            .ok_or_else(|| format!("unknown method {name}"))?;
        let seed = std::env::var("SAW_BENCH_COST_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(opts.seed);
        cost::run_kernel(m, seed);
        return Ok(Vec::new());
    }
    let specs = specs(opts.seed);
    eprintln!(
        "bench: generating {} scenario streams (seed {})",
        specs.len(),
        opts.seed
    );
    let generated = par_map(specs.len(), opts.threads, |i| {
        let (key, spec) = &specs[i];
        let mut stream = spec.generate();
        if let Key::Delay(_) = key {
            // Score only the accelerating stretch through 15–25 mm/s.
            for o in &mut stream {
                o.scored = (15_000.0..=25_000.0).contains(&o.v_true) && o.a_true > 0.0;
            }
        }
        (key.clone(), (spec.clone(), stream))
    });
    let streams: BTreeMap<Key, (Spec, Vec<Obs>)> = generated.into_iter().collect();
    eprintln!("bench: {} methods", all.len());
    let mut results = par_map(all.len(), opts.threads, |i| {
        let mut r = measure_method(&all[i], &streams);
        let (mixed, d) = scenario::mixed();
        let period_us = crate::sim::sample_period_us(&saw_boards::NUCLEO_F446RE);
        let grating = |render| {
            renderers::core_run(
                render,
                "mixed".into(),
                mixed.clone(),
                d,
                2.0,
                opts.seed,
                Some(methods::Dyn((all[i].build)(period_us))),
            )
        };
        r.grating_phase = Some(grating(GratingRender::PositionPhase));
        r.grating_synth = Some(grating(GratingRender::VelocitySynthesis));
        r
    });
    if opts.skip_cost {
        eprintln!("bench: cost runs skipped");
    } else if cost::valgrind_available() {
        eprintln!("bench: callgrind cost runs");
        let work = std::env::temp_dir().join(format!("saw-bench-{}", std::process::id()));
        std::fs::create_dir_all(&work).map_err(|e| e.to_string())?;
        let costs = par_map(all.len(), opts.threads, |i| {
            cost::measure(&all[i], opts.seed, &work)
        });
        let _ = std::fs::remove_dir_all(&work);
        for (r, c) in results.iter_mut().zip(costs) {
            r.cost_ir = Some(c?);
        }
    } else {
        eprintln!("bench: valgrind not found, cost not measured");
    }
    write_report(opts, &all, &results)?;
    Ok(results)
}

fn mm(um_s: f64) -> String {
    format!("{:.2}", um_s / 1_000.0)
}

fn ms(us: f64) -> String {
    format!("{:.2}", us / 1_000.0)
}

/// Linear interpolation of `curve` (x ascending) at `x`, None outside.
fn interpolate(curve: &[(f64, f64)], x: f64) -> Option<f64> {
    curve.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        (x >= x0 && x <= x1 && x1 > x0).then(|| y0 + (y1 - y0) * (x - x0) / (x1 - x0))
    })
}

/// Draws `pts` (RMS error against `x_label`) as a scatter with its Pareto front into `path` and
/// lists the front's methods in `w` as `- {what}: …`.
fn pareto_chart(
    w: &mut String,
    path: &Path,
    title: &str,
    x_label: &str,
    pts: &[charts::Point],
    what: &str,
) -> Result<(), String> {
    charts::scatter(path, title, x_label, "RMS error, mm/s (log)", pts)?;
    let front: Vec<String> = charts::pareto(pts)
        .into_iter()
        .map(|i| pts[i].name.clone())
        .collect();
    let _ = writeln!(w, "- {what}: {}", front.join(", "));
    Ok(())
}

fn write_report(
    opts: &BenchOptions,
    all: &[Method],
    results: &[MethodResult],
) -> Result<(), String> {
    let charts_dir = opts.out_dir.join("charts");
    std::fs::create_dir_all(&charts_dir).map_err(|e| e.to_string())?;
    let by_name = |n: &str| results.iter().find(|r| r.name == n);
    let fam = |n: &str| all.iter().find(|m| m.name == n).map(|m| m.family);
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(w, "# Velocity estimator bench results\n");
    let _ = writeln!(
        w,
        "Generated by `cargo run --release -p host-sim --bin host-sim -- bench --seed {} --out docs` (do not edit by hand; \
         see `docs/estimators.md` for the reading). All figures are deterministic for the seed.\n",
        opts.seed
    );
    let _ = writeln!(
        w,
        "Conditions: 63 mm rheostat, default calibration, 16 × 12-bit conversions per sample \
         (σ_x ≈ 4 µm per LSB of per-conversion noise), seeded Gaussian ADC noise (`host_sim::adc`).\n\
         - **mixed**: rest 0.1 s, slow sine (±5 mm, 1.5 s, peak 21 mm/s), fast sine (±9 mm, \
         0.19 s: peak 300 mm/s and 10 m/s²) ×5; 2 LSB, 10 kHz, 4 seeds.\n\
         - **lag @20**: mean (v_true − v̂)/a while a 0.5 m/s² ramp passes 15–25 mm/s; 2 LSB, 40 seeds \
         (the group delay as seen; the *declared* one is the trait's `group_delay_us` at a steady speed).\n\
         - **20 mm/s**: constant speed, 2 LSB (pure noise figure).\n\
         - **reversals**: triangle 10↔40 mm at 100 mm/s (instant reversals), 2 LSB.\n\
         - **outl+drop**: *mixed* with single-sample outliers of ±2 mm (p = 10⁻³) and dropped \
         samples (p = 2·10⁻³).\n\
         - **bursts**: rest, 3 LSB, 10 s, λ = 1 mm grating by velocity synthesis (a burst per wrap \
         of ∫|V|/λ): raw, and *gated* by the core grating's 5 mm/s start / 2.5 mm/s stop threshold \
         (each switch-on counts one burst, since the burst timer starts every period with its on-time). \
         *gated 15*: the same with the start threshold raised to 15 mm/s (stop at 7.5). \
         *rest max* = largest |v̂| at rest = the smallest start threshold that keeps the grating silent.\n\
         - **cost**: x86-64 instructions per `update`, callgrind `Ir` over 20 000 samples of \
         *mixed* (see `host_sim::bench::cost`); deterministic for one build, but inlining differs \
         between builds (the smallest methods moved by up to ±40 Ir between two builds).\n"
    );
    let _ = writeln!(
        w,
        "| method | declared delay ms | lag @20 ms | RMS mixed mm/s | worst mixed mm/s | RMS 20 mm/s | \
         RMS reversals | worst reversals | RMS outl+drop | worst outl+drop | bursts raw | bursts gated | bursts gated 15 | \
         rest RMS mm/s | rest max mm/s | cost Ir/sample |"
    );
    let _ = writeln!(
        w,
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for r in results {
        let name = if r.name == DEFAULT {
            format!("**{}** (default)", r.name)
        } else {
            r.name.clone()
        };
        let _ = writeln!(
            w,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            name,
            ms(r.declared_delay_us as f64),
            ms(r.delay.lag_us),
            mm(r.mixed.rms_um_s),
            mm(r.mixed.worst_um_s),
            mm(r.steady20.rms_um_s),
            mm(r.reversals.rms_um_s),
            mm(r.reversals.worst_um_s),
            mm(r.outliers.rms_um_s),
            mm(r.outliers.worst_um_s),
            r.bursts_raw,
            r.bursts_gated,
            r.bursts_gated_high,
            mm(r.rest_rms_um_s),
            mm(r.rest_max_um_s),
            r.cost_ir.map_or("—".to_string(), |c| format!("{c:.0}")),
        );
    }
    // Sweeps.
    let sweep = |w: &mut String,
                 title: &str,
                 unit: &str,
                 get: &dyn Fn(&MethodResult) -> &Vec<(f64, f64)>| {
        let _ = writeln!(w, "\n## RMS error (mm/s) against {title}\n");
        let xs: Vec<f64> = get(&results[0]).iter().map(|p| p.0).collect();
        let _ = write!(w, "| method |");
        for x in &xs {
            let _ = write!(w, " {x} {unit} |");
        }
        let _ = writeln!(w);
        let _ = writeln!(w, "|---|{}", "---:|".repeat(xs.len()));
        for r in results {
            let _ = write!(w, "| {} |", r.name);
            for p in get(r) {
                let _ = write!(w, " {} |", mm(p.1));
            }
            let _ = writeln!(w);
        }
    };
    sweep(w, "speed (constant speed, 2 LSB, 10 kHz)", "mm/s", &|r| {
        &r.by_speed
    });
    sweep(w, "ADC noise (mixed, 10 kHz)", "LSB", &|r| &r.by_noise);
    sweep(
        w,
        "sample rate (mixed, 2 LSB; windows and gains kept in samples)",
        "Hz",
        &|r| &r.by_rate,
    );

    // Targets.
    let rendered = renderers::run(opts.seed);
    let _ = writeln!(w, "\n## Targets (2 LSB, 10 kHz)\n");
    let foaw_ref = FOAW_CANDIDATES
        .iter()
        .filter_map(|n| by_name(n))
        .min_by(|a, b| a.mixed.rms_um_s.total_cmp(&b.mixed.rms_um_s));
    if let (Some(d), Some(f)) = (by_name(DEFAULT), foaw_ref) {
        let foaw_name = f.name.as_str();
        let _ = writeln!(
            w,
            "FOAW reference: {foaw_name}, the best-fit FOAW with n_max = 32 and the lowest RMS on \
             *mixed* among bands {}.\n",
            FOAW_CANDIDATES.join(", ")
        );
        let lsq_curve = |get: &dyn Fn(&MethodResult) -> f64| {
            let mut c: Vec<(f64, f64)> = results
                .iter()
                .filter(|r| fam(&r.name) == Some(methods::Family::Lsq))
                .map(|r| (r.delay.lag_us, get(r)))
                .collect();
            c.sort_by(|a, b| a.0.total_cmp(&b.0));
            c
        };
        let at_f_mixed = interpolate(&lsq_curve(&|r| r.mixed.rms_um_s), f.delay.lag_us);
        let at_f_steady = interpolate(&lsq_curve(&|r| r.steady20.rms_um_s), f.delay.lag_us);
        let _ = writeln!(
            w,
            "1. **Default ({DEFAULT}) vs FOAW best-fit ({foaw_name})** — target: ≥ 2× lower \
             RMS at equal delay, or equal RMS at ≤ 1/4 of the cost.\n   \
             - {DEFAULT}: lag {} ms, RMS mixed {} mm/s, RMS at 20 mm/s {} mm/s, cost {} Ir.\n   \
             - {foaw_name}: lag {} ms, RMS mixed {} mm/s, RMS at 20 mm/s {} mm/s, cost {} Ir.\n   \
             - LSQ family interpolated at FOAW's lag ({} ms): RMS mixed {} mm/s (ratio FOAW/LSQ {}), \
             RMS at 20 mm/s {} mm/s (ratio {}).\n   \
             - Cost ratio {DEFAULT}/FOAW: {}.",
            ms(d.delay.lag_us),
            mm(d.mixed.rms_um_s),
            mm(d.steady20.rms_um_s),
            d.cost_ir.map_or("—".into(), |c| format!("{c:.0}")),
            ms(f.delay.lag_us),
            mm(f.mixed.rms_um_s),
            mm(f.steady20.rms_um_s),
            f.cost_ir.map_or("—".into(), |c| format!("{c:.0}")),
            ms(f.delay.lag_us),
            at_f_mixed.map_or("outside the LSQ range".into(), mm),
            at_f_mixed.map_or("—".into(), |v| format!("{:.2}", f.mixed.rms_um_s / v)),
            at_f_steady.map_or("outside the LSQ range".into(), mm),
            at_f_steady.map_or("—".into(), |v| format!("{:.2}", f.steady20.rms_um_s / v)),
            match (d.cost_ir, f.cost_ir) {
                (Some(a), Some(b)) => format!("{:.3}", a / b),
                _ => "—".into(),
            }
        );
        let _ = writeln!(
            w,
            "2. **Lag at 20 mm/s ≤ 2 ms**: {DEFAULT} {} ms → {}.",
            ms(d.delay.lag_us),
            if d.delay.lag_us <= 2_000.0 {
                "met"
            } else {
                "NOT met"
            }
        );
        // Placement, from the renderer runs (constant speeds 20–200 mm/s).
        for name in ["position phase", "velocity synthesis"] {
            let worst = rendered
                .iter()
                .filter(|r| r.renderer == name && r.case.parse::<f64>().is_ok())
                .map(|r| r.worst_err_um)
                .fold(0.0, f64::max);
            let _ = writeln!(
                w,
                "   **Grating bursts within λ/20 = {} µm of the ridges at 20–200 mm/s**: {name} \
                 worst {worst:.1} µm → {}.",
                renderers::RIDGE_UM / 20.0,
                if worst <= renderers::RIDGE_UM / 20.0 {
                    "met"
                } else {
                    "NOT met"
                }
            );
        }
        let _ = writeln!(
            w,
            "3. **Zero spurious bursts at rest (3 LSB, 10 s)**: {DEFAULT} raw {} / gated at 5 mm/s {} / \
             gated at 15 mm/s {} → {}.",
            d.bursts_raw,
            d.bursts_gated,
            d.bursts_gated_high,
            match (d.bursts_raw, d.bursts_gated, d.bursts_gated_high) {
                (0, _, _) => "met",
                (_, 0, _) => "met only with the core grating's 5 mm/s start threshold",
                (_, _, 0) => "met by velocity synthesis with its 15 mm/s start threshold; the \
                    default position-phase renderer needs no threshold (renderer table, rest row)",
                _ => "NOT met",
            }
        );
        let _ = writeln!(
            w,
            "\nMethods meeting target 2 and silent at rest once the start threshold is raised to \
             15 mm/s (no method with lag ≤ 2 ms is silent with the raw synthesis or at 5 mm/s):\n"
        );
        for r in results {
            if r.delay.lag_us > 0.0 && r.delay.lag_us <= 2_000.0 && r.bursts_gated_high == 0 {
                let _ = writeln!(
                    w,
                    "- {}: lag {} ms, RMS mixed {} mm/s, bursts raw {} / gated {} / gated 15 {}",
                    r.name,
                    ms(r.delay.lag_us),
                    mm(r.mixed.rms_um_s),
                    r.bursts_raw,
                    r.bursts_gated,
                    r.bursts_gated_high
                );
            }
        }
    }

    // Charts.
    let point = |r: &MethodResult, x: f64, y: f64| charts::Point {
        name: r.name.clone(),
        family: fam(&r.name).unwrap_or(methods::Family::Lsq),
        x,
        y,
    };
    let _ = writeln!(
        w,
        "\n## Grating renderers: burst placement against ridges (λ = 1 mm, 2 LSB, 10 kHz)\n\n\
         Placement error = true finger position at the burst's rising edge − the nearest ridge, µm, \
         signed along the motion (positive: late). Position phase and velocity synthesis are the \
         core's renderers in the closed-loop simulation (NUCLEO-F446RE, default estimator, gate, \
         timer model), as is the hybrid (position phase with the crossing predicted inside the \
         sample period, `render = \"hybrid\"`). On-time error: \
         RMS of (on − duty·λ/|V|)/(duty·λ/|V|) with the true speed. Skipped: ridge crossings the \
         core counted without a pulse.\n"
    );
    let _ = writeln!(
        w,
        "| renderer | motion (mm/s) | ridges crossed | bursts | skipped | mean error µm | RMS error µm | worst µm | on-time RMS error % |"
    );
    let _ = writeln!(w, "|---|---|---:|---:|---:|---:|---:|---:|---:|");
    let opt = |x: Option<f64>| x.map_or("–".to_string(), |x| format!("{x:.1}"));
    for r in &rendered {
        let _ = writeln!(
            w,
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {} |",
            r.renderer,
            r.case,
            r.ridges,
            r.bursts,
            r.skipped.map_or("–".to_string(), |s| s.to_string()),
            r.mean_err_um,
            r.rms_err_um,
            r.worst_err_um,
            opt(r.on_rms_pct)
        );
    }
    // Worst placement against λ for the three renderers, with the physical floor.
    let sweep = renderers::placement_sweep(opts.seed, 3);
    let (sigma_um, fitted_um, tick_um) = renderers::floor(opts.seed);
    let _ = writeln!(
        w,
        "\n### Worst placement against λ (0.1–4 mm), 20–200 mm/s, 3 noise seeds\n\n\
         A stroke there and back over 24 mm at each speed (turning half a period from the \
         ridges), 2 LSB. Steady: more than 6.7 ms after a turn (the hybrid's 64-sample line \
         refills after a reversal, and it is position phase until then). Physical floor: one sample's position σ = {sigma_um:.1} µm (ADC model); \
         3 σ of the hybrid's fitted position = {fitted_um:.1} µm; one timer tick of travel at \
         200 mm/s = {tick_um:.4} µm. Chart: `charts/renderers-placement-vs-wavelength.png`.\n"
    );
    let _ = writeln!(
        w,
        "| renderer | λ mm | speed mm/s | worst µm (steady) | RMS µm (steady) | worst µm within 6.7 ms of a turn | bursts / ridges | skipped | λ/20 µm |"
    );
    let _ = writeln!(w, "|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    for p in &sweep {
        let _ = writeln!(
            w,
            "| {} | {} | {} | {:.1} | {:.1} | {:.1} | {} / {} | {} | {:.0} |",
            p.renderer,
            p.wavelength_um as f64 / 1000.0,
            p.speed_mm_s,
            p.worst_um,
            p.rms_um,
            p.worst_turn_um,
            p.bursts,
            p.ridges,
            p.skipped,
            p.wavelength_um as f64 / 20.0
        );
    }
    let _ = writeln!(
        w,
        "\n### Grating placement per estimator (mixed motion, λ = 1 mm, closed loop)\n\n\
         Position phase places bursts by position, so the estimator only sizes the pulses \
         (on-time error against duty·λ/|V|); velocity synthesis takes its f_b, hence where its \
         bursts fall, from the estimator.\n"
    );
    let _ = writeln!(
        w,
        "| estimator | position phase RMS µm | worst µm | bursts / skipped | on-time RMS % | velocity synthesis RMS µm | worst µm | bursts |"
    );
    let _ = writeln!(w, "|---|---:|---:|---:|---:|---:|---:|---:|");
    for r in results {
        if let (Some(p), Some(v)) = (&r.grating_phase, &r.grating_synth) {
            let _ = writeln!(
                w,
                "| {} | {:.1} | {:.1} | {} / {} | {} | {:.1} | {:.1} | {} |",
                r.name,
                p.rms_err_um,
                p.worst_err_um,
                p.bursts,
                p.skipped.unwrap_or(0),
                opt(p.on_rms_pct),
                v.rms_err_um,
                v.worst_err_um,
                v.bursts
            );
        }
    }
    let _ = writeln!(w, "\n## Pareto fronts (lower is better on both axes)\n");
    for (file, title, y_of, what) in [
        (
            "estimators-error-vs-delay.png",
            "Velocity RMS error at 20 mm/s (noise, 2 LSB, 10 kHz) against lag at 20 mm/s — * = Pareto",
            (|r: &MethodResult| r.steady20.rms_um_s) as fn(&MethodResult) -> f64,
            "RMS at 20 mm/s against lag",
        ),
        (
            "estimators-mixed-error-vs-delay.png",
            "Velocity RMS error on the mixed motion (to 10 m/s², 2 LSB, 10 kHz) against lag — * = Pareto",
            (|r: &MethodResult| r.mixed.rms_um_s) as fn(&MethodResult) -> f64,
            "RMS mixed against lag",
        ),
    ] {
        let pts: Vec<_> = results
            .iter()
            .filter(|r| r.delay.lag_us > 0.0)
            .map(|r| point(r, r.delay.lag_us / 1_000.0, y_of(r) / 1_000.0))
            .collect();
        pareto_chart(
            w,
            &charts_dir.join(file),
            title,
            "lag at 20 mm/s, ms (log; methods with a negative mean lag left out)",
            &pts,
            what,
        )?;
    }
    if results.iter().all(|r| r.cost_ir.is_some()) {
        let cost_pts: Vec<_> = results
            .iter()
            .map(|r| point(r, r.cost_ir.unwrap(), r.mixed.rms_um_s / 1_000.0))
            .collect();
        pareto_chart(
            w,
            &charts_dir.join("estimators-error-vs-cost.png"),
            "Velocity RMS error (mixed, 2 LSB, 10 kHz) against cost — * = Pareto",
            "x86-64 instructions per sample (callgrind, log)",
            &cost_pts,
            "RMS mixed against cost",
        )?;
    }
    let pick = [
        "diff4",
        "lsq16",
        "lsq32",
        "lsq64",
        "foaw-end-d48-n32",
        "foaw-best-d24-n32",
        "foaw-best-d48-n32",
        "ab-p0.9",
        "abq16-p0.9",
        "std-L1e6",
        "std-L1e7",
        "med3+lsq32",
    ];
    let curves_of = |get: &dyn Fn(&MethodResult) -> Vec<(f64, f64)>| -> Vec<charts::Curve> {
        results
            .iter()
            .filter(|r| pick.contains(&r.name.as_str()))
            .map(|r| charts::Curve {
                name: r.name.clone(),
                family: fam(&r.name).unwrap_or(methods::Family::Lsq),
                points: get(r),
            })
            .collect()
    };
    charts::curves(
        &charts_dir.join("estimators-error-vs-speed.png"),
        "Velocity RMS error at constant speed (2 LSB, 10 kHz)",
        "speed, mm/s (log)",
        "RMS error, mm/s (log)",
        &curves_of(&|r| r.by_speed.iter().map(|p| (p.0, p.1 / 1e3)).collect()),
    )?;
    charts::curves(
        &charts_dir.join("estimators-error-vs-noise.png"),
        "Velocity RMS error on the mixed motion against ADC noise (10 kHz; 0 LSB plotted at 0.25)",
        "ADC noise per conversion, LSB RMS (log)",
        "RMS error, mm/s (log)",
        &curves_of(&|r| {
            r.by_noise
                .iter()
                .map(|p| (if p.0 == 0.0 { 0.25 } else { p.0 }, p.1 / 1e3))
                .collect()
        }),
    )?;
    // Renderers: worst placement against speed, with the λ/20 target as a line.
    let mut render_curves: Vec<charts::Curve> = [
        ("position phase", methods::Family::Lsq),
        ("velocity synthesis", methods::Family::Foaw),
        ("hybrid", methods::Family::Median),
    ]
    .into_iter()
    .map(|(name, family)| charts::Curve {
        name: name.to_string(),
        family,
        points: rendered
            .iter()
            .filter(|r| r.renderer == name)
            .filter_map(|r| Some((r.case.parse::<f64>().ok()?, r.worst_err_um.max(0.1))))
            .collect(),
    })
    .collect();
    render_curves.push(charts::Curve {
        name: "target: λ/20".to_string(),
        family: methods::Family::Difference,
        points: renderers::SPEEDS_MM_S
            .iter()
            .map(|&v| (v, renderers::RIDGE_UM / 20.0))
            .collect(),
    });
    charts::curves(
        &charts_dir.join("renderers-placement-vs-speed.png"),
        "Grating bursts: worst distance from the ridge against speed (λ = 1 mm, 2 LSB, 10 kHz)",
        "speed, mm/s (log)",
        "worst |placement error|, µm (log)",
        &render_curves,
    )?;
    // Worst placement against λ: the three renderers at 20 and 200 mm/s, the floor, λ/20.
    let families = [
        ("position phase", methods::Family::Lsq),
        ("velocity synthesis", methods::Family::Foaw),
        ("hybrid", methods::Family::Median),
    ];
    let mut wl_curves: Vec<charts::Curve> = Vec::new();
    for (name, family) in families {
        for mm_s in [20.0, 200.0] {
            wl_curves.push(charts::Curve {
                name: format!("{name}, {mm_s} mm/s"),
                family,
                points: sweep
                    .iter()
                    .filter(|p| p.renderer == name && p.speed_mm_s == mm_s)
                    .map(|p| (p.wavelength_um as f64 / 1000.0, p.worst_um.max(0.1)))
                    .collect(),
            });
        }
    }
    let lambdas = renderers::SWEEP_WAVELENGTHS_UM.map(|l| l as f64 / 1000.0);
    for (name, y) in [
        ("floor: 3 σ of the fitted position".to_string(), fitted_um),
        ("floor: one sample's σ".to_string(), sigma_um),
        (
            "position phase floor: one sample of travel at 200 mm/s".to_string(),
            20.0,
        ),
    ] {
        wl_curves.push(charts::Curve {
            name,
            family: methods::Family::Difference,
            points: lambdas.iter().map(|&l| (l, y)).collect(),
        });
    }
    wl_curves.push(charts::Curve {
        name: "target: λ/20".to_string(),
        family: methods::Family::Difference,
        points: lambdas.iter().map(|&l| (l, l * 1000.0 / 20.0)).collect(),
    });
    charts::curves(
        &charts_dir.join("renderers-placement-vs-wavelength.png"),
        "Grating bursts: worst distance from the ridge against λ, steady strokes (2 LSB, 10 kHz, 3 seeds)",
        "λ, mm (log)",
        "worst |placement error|, µm (log)",
        &wl_curves,
    )?;
    let _ = writeln!(
        w,
        "\nCharts: `charts/renderers-placement-vs-wavelength.png`, `charts/estimators-error-vs-delay.png`, `charts/estimators-mixed-error-vs-delay.png`, \
         `charts/estimators-error-vs-cost.png`, `charts/estimators-error-vs-speed.png`, \
         `charts/estimators-error-vs-noise.png`, `charts/renderers-placement-vs-speed.png`."
    );
    std::fs::write(opts.out_dir.join("bench-results.md"), md).map_err(|e| e.to_string())?;
    eprintln!(
        "bench: wrote {}",
        opts.out_dir.join("bench-results.md").display()
    );
    Ok(())
}

/// Worker threads of the bench.
const THREADS: crate::door::Whole = crate::door::Whole::new(1, 256);
/// Seed of the bench's scenarios.
const SEED: crate::door::Whole = crate::door::Whole::new(0, u64::MAX);

/// `host-sim bench [--seed N] [--out DIR] [--threads N] [--skip-cost]`.
#[derive(clap::Parser, Debug)]
#[command(
    name = "host-sim bench",
    bin_name = "host-sim bench",
    about = "Velocity estimators measured, charted and broken"
)]
struct BenchArgs {
    #[arg(long, default_value_t = 2026, allow_hyphen_values = true,
          help = SEED.help("Seed of every scenario"), value_parser = SEED.parser())]
    seed: u64,
    /// Output directory for bench-results.md and charts/ (default: out/bench; `--out docs`
    /// refreshes the committed results).
    #[arg(long, value_name = "DIR", value_parser = crate::door::out_dir)]
    out: Option<PathBuf>,
    #[arg(long, value_name = "N", default_value_t = 2, allow_hyphen_values = true,
          help = THREADS.help("Worker threads"), value_parser = THREADS.parser_usize())]
    threads: usize,
    /// Skip the callgrind cost runs.
    #[arg(long)]
    skip_cost: bool,
}

/// Runs the bench when the first argument is `bench`; None otherwise (the caller goes on with
/// its own command line).
pub fn run_from_env() -> Option<std::process::ExitCode> {
    let a: BenchArgs = crate::door::subcommand("bench")?;
    let opts = BenchOptions {
        seed: a.seed,
        out_dir: a.out.unwrap_or_else(default_out_dir),
        threads: a.threads,
        skip_cost: a.skip_cost,
    };
    match run(&opts) {
        Ok(_) => Some(std::process::ExitCode::SUCCESS),
        Err(e) => {
            eprintln!("bench: {e}");
            Some(std::process::ExitCode::FAILURE)
        }
    }
}

/// Where the report goes by default: `out/bench` (untracked); `--out docs` refreshes the
/// committed `docs/bench-results.md` and charts.
pub fn default_out_dir() -> PathBuf {
    PathBuf::from("out").join("bench")
}
