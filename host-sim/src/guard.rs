//! `host-sim guard`: outlier guards cheaper than the median (issue #35) — lag, velocity noise
//! and worst error under single-sample outliers of `LsqSlope<K>` bare, behind the median-of-3
//! and behind each guard, on the acquisitions of the conversion budget that reach the noise
//! bound (`docs/conversion-budget.md`, "Outlier guards").
//!
//! Lag and noise are the budget's own figures ([`budget::streams`], [`budget::measure`]). The
//! outlier figure is the estimator bench's (`docs/estimators.md`): the worst |v̂ − v| over two
//! streams of the mixed motion (to 300 mm/s and 10 m/s²) per seed, with single-sample outliers
//! of ±2 mm (p = 10⁻³) and lost samples (p = 2·10⁻³), here through the budget's ADC model
//! of the acquisition. Writes `guard-frontier-results.md` and `charts/guard-frontier.png`
//! under the output directory.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::position::Calibration;
use saw_core::velocity::{InnovationGate, LsqSlope, Median3, StepClamp};

use crate::bench::measure::{errors, pool, replay, Errors};
use crate::bench::methods::{BoxedEstimator, Family, Method};
use crate::bench::scenario::{self, Input, Obs};
use crate::budget::{self, Silicon, TARGET_LAG_MS, TARGET_NOISE_MM_S};
use crate::door::{Range, Whole};

/// The bound on the worst error under single-sample outliers, mm/s (today's 22 with
/// the median, plus a little).
pub const TARGET_OUTLIER_MM_S: f64 = 25.0;
/// The innovation gate: largest distance from the prediction a sample may have and pass, µm
/// (≥ 10 σ of the noisiest acquisition's position, ~8 µm at 16 conversions; a prediction off
/// by a 1 m/s speed error is 100 µm).
pub const GATE_UM: u32 = 100;
/// The innovation gate: samples held in a row before a jump is taken (two outliers in a row
/// are held too).
pub const GATE_MAX_HELD: u8 = 2;
/// The step clamp's speed limits, µm/s: 1 m/s and 0.5 m/s (the mixed motion peaks at 0.3).
pub const CLAMP_FAST_UM_S: u32 = 1_000_000;
/// See [`CLAMP_FAST_UM_S`].
pub const CLAMP_SLOW_UM_S: u32 = 500_000;
/// Outlier probability, size and lost-sample probability: the bench's.
pub const OUTLIER_PROB: f64 = 1e-3;
/// See [`OUTLIER_PROB`], µm: the default of `--outlier-um`.
pub const OUTLIER_UM: f64 = 2_000.0;
/// See [`OUTLIER_PROB`].
pub const DROP_PROB: f64 = 2e-3;
/// Output rate of every acquisition here, Hz.
pub const RATE_HZ: u32 = 10_000;
/// Floor and corner: the budget's assumed ones.
pub const FLOOR_LSB: f64 = 0.05;
/// See [`FLOOR_LSB`], Hz.
pub const FLOOR_CORNER_HZ: f64 = 2_000.0;
/// Outlier streams per seed (as the bench).
const OUTLIER_STREAMS: u64 = 2;

/// The guards compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Guard {
    /// The bare slope.
    Bare,
    /// `Median3`.
    Median,
    /// `InnovationGate` at [`GATE_UM`], [`GATE_MAX_HELD`].
    Gate,
    /// `StepClamp` at [`CLAMP_FAST_UM_S`].
    ClampFast,
    /// `StepClamp` at [`CLAMP_SLOW_UM_S`].
    ClampSlow,
}

impl Guard {
    /// Every guard, in table order.
    pub const ALL: [Guard; 5] = [
        Guard::Bare,
        Guard::Median,
        Guard::Gate,
        Guard::ClampFast,
        Guard::ClampSlow,
    ];
    /// Name in tables and the chart.
    pub fn name(self) -> &'static str {
        match self {
            Guard::Bare => "bare LsqSlope",
            Guard::Median => "Median3",
            Guard::Gate => "InnovationGate 100 µm, 2 held",
            Guard::ClampFast => "StepClamp 1 m/s",
            Guard::ClampSlow => "StepClamp 0.5 m/s",
        }
    }
}

/// One acquisition: a board's ADC mode and conversions per 10 kHz sample.
#[derive(Clone, Debug)]
pub struct Acquisition {
    /// Short name.
    pub name: &'static str,
    /// The board's silicon (the budget's).
    pub silicon: fn() -> Silicon,
    /// The budget's mode name.
    pub mode: &'static str,
    /// Conversions per sample.
    pub conversions: u32,
}

/// The acquisitions measured: each board's default, the F446's `dual-adc` image and the two
/// 1.28 Msps dual points of the budget.
pub fn acquisitions() -> Vec<Acquisition> {
    vec![
        Acquisition {
            name: "F446 default: 1 ADC, 56 cycles, ×16",
            silicon: budget::f446,
            mode: "single smp56",
            conversions: 16,
        },
        Acquisition {
            name: "F446 dual-adc image: 2 ADCs, 15 cycles, ×2×16",
            silicon: budget::f446,
            mode: "dual smp15",
            conversions: 32,
        },
        Acquisition {
            name: "F446 dual 1.28 Msps: 2 ADCs, 15 cycles, ×128",
            silicon: budget::f446,
            mode: "dual smp15",
            conversions: 128,
        },
        Acquisition {
            name: "G474 default: 1 ADC, 47.5 cycles, ×32",
            silicon: budget::g474,
            mode: "single smp47.5",
            conversions: 32,
        },
        Acquisition {
            name: "G474 dual 1.28 Msps: 2 ADCs, 24.5 cycles, ×128",
            silicon: budget::g474,
            mode: "dual smp24.5",
            conversions: 128,
        },
    ]
}

macro_rules! guarded {
    ($k:literal) => {
        [
            (
                Guard::Bare,
                Method {
                    name: concat!("lsq", $k),
                    family: Family::Lsq,
                    build: |p: u32| -> BoxedEstimator { Box::new(LsqSlope::<$k>::new(p).unwrap()) },
                },
            ),
            (
                Guard::Median,
                Method {
                    name: concat!("med3+lsq", $k),
                    family: Family::Median,
                    build: |p: u32| -> BoxedEstimator {
                        Box::new(Median3::new(LsqSlope::<$k>::new(p).unwrap(), p))
                    },
                },
            ),
            (
                Guard::Gate,
                Method {
                    name: concat!("gate+lsq", $k),
                    family: Family::Lsq,
                    build: |p: u32| -> BoxedEstimator {
                        Box::new(InnovationGate::new(
                            LsqSlope::<$k>::new(p).unwrap(),
                            p,
                            GATE_UM,
                            GATE_MAX_HELD,
                        ))
                    },
                },
            ),
            (
                Guard::ClampFast,
                Method {
                    name: concat!("clamp1+lsq", $k),
                    family: Family::Lsq,
                    build: |p: u32| -> BoxedEstimator {
                        Box::new(StepClamp::new(
                            LsqSlope::<$k>::new(p).unwrap(),
                            p,
                            CLAMP_FAST_UM_S,
                        ))
                    },
                },
            ),
            (
                Guard::ClampSlow,
                Method {
                    name: concat!("clamp05+lsq", $k),
                    family: Family::Lsq,
                    build: |p: u32| -> BoxedEstimator {
                        Box::new(StepClamp::new(
                            LsqSlope::<$k>::new(p).unwrap(),
                            p,
                            CLAMP_SLOW_UM_S,
                        ))
                    },
                },
            ),
        ]
    };
}

/// Every estimator measured: (window K, guard, method).
pub fn estimators() -> Vec<(usize, Guard, Method)> {
    let mut v = Vec::new();
    for (k, set) in [
        (12, guarded!(12)),
        (14, guarded!(14)),
        (15, guarded!(15)),
        (16, guarded!(16)),
        (20, guarded!(20)),
        (24, guarded!(24)),
        (26, guarded!(26)),
        (28, guarded!(28)),
        (30, guarded!(30)),
        (32, guarded!(32)),
        (40, guarded!(40)),
    ] {
        for (g, m) in set {
            v.push((k, g, m));
        }
    }
    v
}

/// The bench's outlier and lost-sample draws on a clean stream (its `Spec::generate` draws,
/// seeded the same way): a lost sample drops its slot; an outlier moves the position by
/// ±`outlier_um`, kept on the substrate (the bench keeps its code off the rails).
pub fn add_outliers(stream: &mut [Obs], seed: u64, outlier_um: f64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5A5A_0F0F_1234_8765);
    let length = Calibration::default().length_um as f64;
    for o in stream {
        let Input::Position(x) = o.input else {
            continue;
        };
        if rng.random::<f64>() < DROP_PROB {
            o.input = Input::Dropped;
        } else if rng.random::<f64>() < OUTLIER_PROB {
            let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
            o.input = Input::Position((x as f64 + sign * outlier_um).clamp(0.0, length) as i32);
        }
    }
}

/// One seed's outlier streams of an acquisition: the mixed motion with outliers and drops.
pub fn outlier_streams(acq: &Acquisition, seed: u64, outlier_um: f64) -> Vec<Vec<Obs>> {
    let si = (acq.silicon)();
    let mode = mode_of(&si, acq);
    let (t, d) = scenario::mixed();
    (0..OUTLIER_STREAMS)
        .map(|i| {
            let s = seed.wrapping_mul(31).wrapping_add(400 + i);
            let p = budget::adc_params(&si, mode, acq.conversions, FLOOR_LSB, FLOOR_CORNER_HZ, s);
            let mut stream = budget::generate(&t, d, RATE_HZ, p);
            add_outliers(&mut stream, s, outlier_um);
            stream
        })
        .collect()
}

fn mode_of<'a>(si: &'a Silicon, acq: &Acquisition) -> &'a budget::AdcMode {
    si.modes
        .iter()
        .find(|m| m.name == acq.mode)
        .expect("the acquisition's mode is one of the budget's")
}

/// The budget options the lag and noise streams are made with.
fn budget_options(seed: u64) -> budget::BudgetOptions {
    budget::BudgetOptions {
        seed,
        seeds: 1,
        floor_lsb: FLOOR_LSB,
        floor_corner_hz: FLOOR_CORNER_HZ,
        out_dir: PathBuf::new(),
        threads: 1,
        boards: Vec::new(),
    }
}

/// One seed's figures of one estimator: lag µs, noise µm/s RMS, worst error under outliers µm/s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SeedFigures {
    /// Lag at 20 mm/s, µs.
    pub lag_us: f64,
    /// Velocity noise at 20 mm/s, µm/s RMS.
    pub noise_um_s: f64,
    /// Worst |v̂ − v| on the outlier streams, µm/s.
    pub outlier_worst_um_s: f64,
}

/// Measures `methods` on one acquisition for one seed (every method sees the same streams),
/// the outliers ±`outlier_um`.
pub fn measure_seed(
    acq: &Acquisition,
    seed: u64,
    outlier_um: f64,
    methods: &[&Method],
) -> Vec<SeedFigures> {
    let si = (acq.silicon)();
    let mode = mode_of(&si, acq);
    let (delay, steady) = budget::streams(
        &si,
        mode,
        RATE_HZ,
        acq.conversions,
        &budget_options(seed),
        seed,
    );
    let outl = outlier_streams(acq, seed, outlier_um);
    let period = 1_000_000 / RATE_HZ;
    methods
        .iter()
        .map(|m| {
            let (lag_us, noise_um_s) = budget::measure(m, RATE_HZ, &delay, &steady);
            let o: Vec<Errors> = outl
                .iter()
                .map(|s| errors(s, &replay(m, s, period)))
                .collect();
            SeedFigures {
                lag_us,
                noise_um_s,
                outlier_worst_um_s: pool(&o).worst_um_s,
            }
        })
        .collect()
}

/// One candidate on one acquisition, over the seeds.
#[derive(Clone, Debug)]
pub struct GuardPoint {
    /// Acquisition name.
    pub acquisition: &'static str,
    /// The guard.
    pub guard: Guard,
    /// Window K.
    pub k: usize,
    /// Estimator name.
    pub estimator: &'static str,
    /// Lag pooled (mean over seeds), ms.
    pub lag_ms: f64,
    /// Design lag ([`budget::design_lag_us`]), ms.
    pub design_lag_ms: f64,
    /// Noise pooled (RMS over seeds), mm/s.
    pub noise_mm_s: f64,
    /// Worst error under outliers over every seed, mm/s.
    pub outlier_worst_mm_s: f64,
    /// Worst seed's lag, ms.
    pub worst_lag_ms: f64,
    /// Worst seed's noise, mm/s.
    pub worst_noise_mm_s: f64,
    /// Per seed.
    pub per_seed: Vec<SeedFigures>,
}

impl GuardPoint {
    /// The lag the chart shows and the target is checked on: the larger of the measured and
    /// the design one, ms (as the budget).
    pub fn shown_lag_ms(&self) -> f64 {
        self.lag_ms.max(self.design_lag_ms)
    }
    /// Pooled noise within the bound.
    pub fn at_noise_bound(&self) -> bool {
        self.noise_mm_s <= TARGET_NOISE_MM_S
    }
    /// Lag ≤ 0.8 ms (measured and design), noise ≤ 1.66 mm/s, outlier worst ≤ 25 mm/s.
    pub fn meets(&self) -> bool {
        self.at_noise_bound()
            && self.shown_lag_ms() <= TARGET_LAG_MS
            && self.outlier_worst_mm_s <= TARGET_OUTLIER_MM_S
    }
}

/// Options of `host-sim guard`.
#[derive(Clone, Debug)]
pub struct GuardOptions {
    /// Base seed.
    pub seed: u64,
    /// Seeds.
    pub seeds: u64,
    /// Output directory.
    pub out_dir: PathBuf,
    /// Worker threads.
    pub threads: usize,
    /// Outlier size, µm.
    pub outlier_um: f64,
}

/// Measures every estimator on every acquisition over the seeds.
pub fn sweep(opts: &GuardOptions) -> Vec<GuardPoint> {
    let acqs = acquisitions();
    let ests = estimators();
    let methods: Vec<&Method> = ests.iter().map(|(_, _, m)| m).collect();
    let jobs: Vec<(usize, u64)> = (0..acqs.len())
        .flat_map(|a| (0..opts.seeds).map(move |s| (a, opts.seed + s)))
        .collect();
    let measured = crate::bench::par_map(jobs.len(), opts.threads, |j| {
        let (a, seed) = jobs[j];
        let r = measure_seed(&acqs[a], seed, opts.outlier_um, &methods);
        eprintln!("guard: {} seed {seed} done", acqs[a].name);
        r
    });
    let mut out = Vec::new();
    for (a, acq) in acqs.iter().enumerate() {
        let si = (acq.silicon)();
        let window_us = acq.conversions as f64 * mode_of(&si, acq).step_s() * 1e6;
        let runs: Vec<&Vec<SeedFigures>> = jobs
            .iter()
            .zip(&measured)
            .filter(|((ja, _), _)| *ja == a)
            .map(|(_, r)| r)
            .collect();
        for (ei, (k, g, m)) in ests.iter().enumerate() {
            let per_seed: Vec<SeedFigures> = runs.iter().map(|r| r[ei]).collect();
            let n = per_seed.len() as f64;
            out.push(GuardPoint {
                acquisition: acq.name,
                guard: *g,
                k: *k,
                estimator: m.name,
                lag_ms: per_seed.iter().map(|s| s.lag_us).sum::<f64>() / n / 1e3,
                design_lag_ms: budget::design_lag_us(*k, *g == Guard::Median, RATE_HZ, window_us)
                    / 1e3,
                noise_mm_s: (per_seed.iter().map(|s| s.noise_um_s.powi(2)).sum::<f64>() / n).sqrt()
                    / 1e3,
                outlier_worst_mm_s: per_seed
                    .iter()
                    .map(|s| s.outlier_worst_um_s)
                    .fold(0.0, f64::max)
                    / 1e3,
                worst_lag_ms: per_seed.iter().map(|s| s.lag_us).fold(f64::MIN, f64::max) / 1e3,
                worst_noise_mm_s: per_seed
                    .iter()
                    .map(|s| s.noise_um_s)
                    .fold(f64::MIN, f64::max)
                    / 1e3,
                per_seed,
            });
        }
    }
    out
}

/// The frontier point of `guard` on `acquisition`: the lowest lag (the larger of measured and
/// design) at noise ≤ 1.66 mm/s and outlier worst ≤ 25 mm/s.
pub fn frontier<'a>(
    points: &'a [GuardPoint],
    acquisition: &str,
    guard: Guard,
) -> Option<&'a GuardPoint> {
    points
        .iter()
        .filter(|p| p.acquisition == acquisition && p.guard == guard)
        .filter(|p| p.at_noise_bound() && p.outlier_worst_mm_s <= TARGET_OUTLIER_MM_S)
        .min_by(|a, b| a.shown_lag_ms().total_cmp(&b.shown_lag_ms()))
}

const X_RANGE: (f64, f64) = (0.6, 2.2);
const Y_RANGE: (f64, f64) = (5.0, 1_000.0);

fn colour(g: Guard) -> RGBColor {
    match g {
        Guard::Bare => RGBColor(127, 127, 127),
        Guard::Median => RGBColor(31, 119, 180),
        Guard::Gate => RGBColor(44, 160, 44),
        Guard::ClampFast => RGBColor(255, 127, 14),
        Guard::ClampSlow => RGBColor(148, 103, 189),
    }
}

/// Draws `pts` with the marker of acquisition `ai` on `area`'s coordinates.
macro_rules! markers {
    ($area:expr, $ai:expr, $pts:expr, $c:expr) => {{
        let c = $c;
        match $ai % 5 {
            0 => $area
                .draw_series($pts.map(|p| Circle::new(p, 4, c.filled())))
                .map(|_| ()),
            1 => $area
                .draw_series($pts.map(|p| TriangleMarker::new(p, 6, c.filled())))
                .map(|_| ()),
            2 => $area
                .draw_series($pts.map(|p| Cross::new(p, 5, c.stroke_width(2))))
                .map(|_| ()),
            3 => $area
                .draw_series($pts.map(|p| Circle::new(p, 5, c.stroke_width(2))))
                .map(|_| ()),
            _ => $area
                .draw_series($pts.map(|p| {
                    EmptyElement::at(p) + Rectangle::new([(-4, -4), (4, 4)], c.stroke_width(2))
                }))
                .map(|_| ()),
        }
    }};
}

/// Lag against outlier worst error, one series per guard (a line per acquisition through its
/// windows), only points at the noise bound, with the target lines.
pub fn chart(path: &Path, points: &[GuardPoint], outlier_um: f64) -> Result<(), String> {
    let e = |e: &dyn std::fmt::Display| e.to_string();
    let root = BitMapBackend::new(path, (1400, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Outlier guards (issue #35): lag against worst error under ±{} µm outliers, at noise ≤ {TARGET_NOISE_MM_S} mm/s",
                outlier_um
            ),
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(X_RANGE.0..X_RANGE.1, (Y_RANGE.0..Y_RANGE.1).log_scale())
        .map_err(|x| e(&x))?;
    chart
        .configure_mesh()
        .x_desc("lag at 20 mm/s, ms (the larger of measured and design)")
        .y_desc("worst |v̂ − v| with outliers and lost samples, mm/s (log)")
        .draw()
        .map_err(|x| e(&x))?;
    let red = RGBColor(200, 30, 30);
    chart
        .draw_series(LineSeries::new(
            vec![(TARGET_LAG_MS, Y_RANGE.0), (TARGET_LAG_MS, Y_RANGE.1)],
            red.stroke_width(2),
        ))
        .map_err(|x| e(&x))?
        .label("targets: lag 0.8 ms, outlier worst 25 mm/s")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            vec![
                (X_RANGE.0, TARGET_OUTLIER_MM_S),
                (X_RANGE.1, TARGET_OUTLIER_MM_S),
            ],
            red.stroke_width(2),
        ))
        .map_err(|x| e(&x))?;
    let acqs = acquisitions();
    for g in Guard::ALL {
        let c = colour(g);
        let mut labelled = false;
        for (ai, acq) in acqs.iter().enumerate() {
            let mut xy: Vec<(f64, f64)> = points
                .iter()
                .filter(|p| p.guard == g && p.acquisition == acq.name && p.at_noise_bound())
                .map(|p| {
                    (
                        p.shown_lag_ms().clamp(X_RANGE.0, X_RANGE.1),
                        p.outlier_worst_mm_s.clamp(Y_RANGE.0, Y_RANGE.1),
                    )
                })
                .collect();
            if xy.is_empty() {
                continue;
            }
            xy.sort_by(|a, b| a.0.total_cmp(&b.0));
            let series = chart
                .draw_series(LineSeries::new(xy.clone(), c.stroke_width(1)))
                .map_err(|x| e(&x))?;
            if !labelled {
                labelled = true;
                series
                    .label(g.name())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, c.filled()));
            }
            markers!(chart, ai, xy.iter().copied(), c).map_err(|x| e(&x))?;
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|x| e(&x))?;
    // The acquisitions' markers, as text under the legend.
    for (ai, acq) in acqs.iter().enumerate() {
        let y = 640 + 22 * ai as i32;
        let p = (1010, y + 7);
        match ai % 5 {
            0 => root.draw(&Circle::new(p, 4, BLACK.filled())),
            1 => root.draw(&TriangleMarker::new(p, 6, BLACK.filled())),
            2 => root.draw(&Cross::new(p, 5, BLACK.stroke_width(2))),
            3 => root.draw(&Circle::new(p, 5, BLACK.stroke_width(2))),
            _ => root.draw(
                &(EmptyElement::at(p) + Rectangle::new([(-4, -4), (4, 4)], BLACK.stroke_width(2))),
            ),
        }
        .map_err(|x| e(&x))?;
        root.draw(&Text::new(
            acq.name,
            (1025, y),
            ("sans-serif", 14).into_font(),
        ))
        .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))
}

const HEADER: &str = "| acquisition | estimator | K | lag ms | design lag ms | noise mm/s | outlier worst mm/s | worst-seed lag | worst-seed noise | per-seed outlier worst | meets all three |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|";

fn row(w: &mut String, p: &GuardPoint) {
    let seeds: Vec<String> = p
        .per_seed
        .iter()
        .map(|s| format!("{:.1}", s.outlier_worst_um_s / 1e3))
        .collect();
    let _ = writeln!(
        w,
        "| {} | {} | {} | {:.3} | {:.3} | {:.2} | {:.1} | {:.3} | {:.2} | {} | {} |",
        p.acquisition,
        p.estimator,
        p.k,
        p.lag_ms,
        p.design_lag_ms,
        p.noise_mm_s,
        p.outlier_worst_mm_s,
        p.worst_lag_ms,
        p.worst_noise_mm_s,
        seeds.join(" / "),
        if p.meets() { "**yes**" } else { "no" },
    );
}

/// Runs the sweep, writes the table and the chart.
pub fn run(opts: &GuardOptions) -> Result<Vec<GuardPoint>, String> {
    let charts = crate::door::charts_dir(&opts.out_dir)?;
    let points = sweep(opts);
    chart(&charts.join("guard-frontier.png"), &points, opts.outlier_um)?;
    let mut md = String::new();
    let w = &mut md;
    let _ = writeln!(w, "# Outlier guards: results (issue #35)\n");
    let _ = writeln!(
        w,
        "Generated by `cargo run --release -p host-sim --bin host-sim -- guard --seed {} --seeds {} \
         --outlier-um {} --out {}` (do not edit by hand; `docs/conversion-budget.md`, \"Outlier guards\", explains \
         the candidates and the pick). 10 kHz output; the budget's ADC model (floor {FLOOR_LSB} LSB, \
         {FLOOR_CORNER_HZ} Hz corner, settling, conversion window). Lag and noise as the budget \
         measures them (pooled over the seeds); outlier worst: the largest |v̂ − v| over {OUTLIER_STREAMS} \
         streams per seed of the bench's mixed motion (to 300 mm/s, 10 m/s²) with ±{} µm \
         single-sample outliers (p = {OUTLIER_PROB}) and lost samples (p = {DROP_PROB}), worst of \
         every seed. Targets: lag ≤ {TARGET_LAG_MS} ms (measured and design), noise ≤ \
         {TARGET_NOISE_MM_S} mm/s, outlier worst ≤ {TARGET_OUTLIER_MM_S} mm/s. Chart: \
         `charts/guard-frontier.png`.\n",
        opts.seed,
        opts.seeds,
        opts.outlier_um,
        opts.out_dir.display(),
        opts.outlier_um,
    );
    let acqs = acquisitions();
    let _ = writeln!(
        w,
        "## Frontier\n\nPer acquisition and guard, the lowest lag at noise ≤ {TARGET_NOISE_MM_S} mm/s \
         and outlier worst ≤ {TARGET_OUTLIER_MM_S} mm/s (none: no window reaches both):\n\n{HEADER}"
    );
    for acq in &acqs {
        for g in Guard::ALL {
            match frontier(&points, acq.name, g) {
                Some(p) => row(w, p),
                None => {
                    let _ = writeln!(w, "| {} | {} | none | | | | | | | | |", acq.name, g.name());
                }
            }
        }
    }
    let _ = writeln!(w, "\n## Every point\n\n{HEADER}");
    for p in &points {
        row(w, p);
    }
    std::fs::write(opts.out_dir.join("guard-frontier-results.md"), md).map_err(|e| {
        format!(
            "--out {}: cannot write guard-frontier-results.md: {e}",
            opts.out_dir.display()
        )
    })?;
    Ok(points)
}

const THREADS: Whole = Whole::new(1, 256);
/// Outlier size flag range.
pub const OUTLIER_SIZE: Range = Range::new(1.0, 60_000.0, "µm");

/// `host-sim guard [--seed N] [--seeds N] [--outlier-um X] [--out DIR] [--threads N]`.
#[derive(clap::Parser, Debug)]
#[command(
    name = "host-sim guard",
    bin_name = "host-sim guard",
    about = "Outlier guards: lag, noise and worst error under outliers per guard and window (issue #35)"
)]
struct GuardArgs {
    #[command(flatten)]
    seeds: crate::door::SweepSeeds,
    /// Output directory for guard-frontier-results.md and charts/ (default: out/guard;
    /// `--out docs` refreshes the committed results).
    #[arg(long, value_name = "DIR", value_parser = crate::door::out_dir)]
    out: Option<PathBuf>,
    #[arg(long, value_name = "N", default_value_t = 2, allow_hyphen_values = true,
          help = THREADS.help("Worker threads"), value_parser = THREADS.parser_usize())]
    threads: usize,
    #[arg(long, value_name = "UM", default_value_t = OUTLIER_UM, allow_hyphen_values = true,
          help = OUTLIER_SIZE.help("Size of the single-sample outliers (the bench's: 2000)"),
          value_parser = OUTLIER_SIZE.parser())]
    outlier_um: f64,
}

/// Runs the guard sweep when the first argument is `guard`; None otherwise.
pub fn run_from_env() -> Option<std::process::ExitCode> {
    let a: GuardArgs = crate::door::subcommand("guard")?;
    let opts = GuardOptions {
        seed: a.seeds.seed,
        seeds: a.seeds.seeds,
        out_dir: a.out.unwrap_or_else(|| PathBuf::from("out").join("guard")),
        threads: a.threads,
        outlier_um: a.outlier_um,
    };
    match run(&opts) {
        Ok(points) => {
            for acq in acquisitions() {
                for g in Guard::ALL {
                    match frontier(&points, acq.name, g) {
                        Some(p) => println!(
                            "{} · {}: K {} lag {:.3} ms (design {:.3}), noise {:.2} mm/s, outlier worst {:.1} mm/s{}",
                            acq.name, g.name(), p.k, p.lag_ms, p.design_lag_ms, p.noise_mm_s,
                            p.outlier_worst_mm_s, if p.meets() { " — meets all three" } else { "" }
                        ),
                        None => println!("{} · {}: none: no window reaches both bounds", acq.name, g.name()),
                    }
                }
            }
            println!(
                "wrote {}",
                opts.out_dir.join("guard-frontier-results.md").display()
            );
            Some(std::process::ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("guard: {e}");
            Some(std::process::ExitCode::FAILURE)
        }
    }
}
