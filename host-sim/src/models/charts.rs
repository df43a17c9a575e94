//! The models' charts (`docs/charts/models-*.png`, drawn with plotters) and the tables of
//! docs/models.md, computed in-process from the model functions: `host-sim model charts`.
//!
//! The only external tool is valgrind, for the atan cost axis (callgrind instruction counts of
//! the `#[inline(never)]` bench loops of [`super::atan`], run on this same binary). Without it
//! the atan chart plots the errors per implementation instead and the cost columns print `—`.

use std::fmt::Write as _;
use std::ops::Add;
use std::path::{Path, PathBuf};
use std::process::Command;

use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::atan::{atan_curve, atan_errors, AtanCurvePoint, AtanError, AtanImpl, R_MAX};
use super::grooved::{GroovedInput, Solver};
use super::solvers::{solver_sweep, SolverStats, SWEEP_RTOL_EXPONENTS};
use super::stick_slip::{fig5_curve, Fig5Point, StickSlipParams};
use super::tile::{tile_rows, TileRow, OZ_G};

/// The four charts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Chart {
    /// f_ss against μs − μc (Nara et al. fig. 5).
    Fig5,
    /// θ solvers: iterations and evaluations against achieved accuracy.
    Solvers,
    /// Taylor & Lederman tile sets: A and D per set and force.
    Tiles,
    /// atan implementations: error against cost, error against R.
    Atan,
}

impl Chart {
    /// All four, in the order they are written.
    pub const ALL: [Chart; 4] = [Chart::Fig5, Chart::Solvers, Chart::Tiles, Chart::Atan];

    /// `--only` name.
    pub fn name(self) -> &'static str {
        match self {
            Chart::Fig5 => "fig5",
            Chart::Solvers => "solvers",
            Chart::Tiles => "tiles",
            Chart::Atan => "atan",
        }
    }

    /// Parses [`Chart::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == s)
    }

    /// PNG file name (the names docs/models.md links to).
    pub fn file_name(self) -> &'static str {
        match self {
            Chart::Fig5 => "models-stick-slip-fig5.png",
            Chart::Solvers => "models-theta-solvers.png",
            Chart::Tiles => "models-tiles.png",
            Chart::Atan => "models-atan.png",
        }
    }
}

/// Where the atan cost comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AtanCostSource {
    /// No cost: the chart plots errors per implementation (tests; `--no-cost`).
    Skip,
    /// Callgrind on `exe`, which must run `model atan-bench` (the host-sim binary). Skipped with
    /// a note when valgrind is not installed.
    Callgrind {
        /// The binary to count (normally this process's own executable).
        exe: PathBuf,
    },
}

/// Instruction counts of the atan bench loops (x86-64 of the counted build, not Cortex-M).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtanCost {
    /// Instructions per iteration of the empty loop, subtracted from the others.
    pub loop_instr: f64,
    /// Net instructions per atan call, in [`AtanImpl::ALL`] order.
    pub atan_instr: [f64; 3],
    /// Net instructions per f_ss sample (eq. 10 in f32) with that atan; the f64 reference has
    /// no per-sample bench.
    pub fss_instr: [Option<f64>; 3],
}

/// Points of the fig. 5 curve (401 values of Δμ, as the charts have always used).
pub const FIG5_POINTS: usize = 400;

/// Writes the charts (all, or `only`) into `out` and returns the tables and notes to print.
pub fn write_charts(
    out: &Path,
    only: Option<Chart>,
    cost_source: &AtanCostSource,
) -> Result<String, String> {
    std::fs::create_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut text = String::new();
    for chart in Chart::ALL {
        if only.is_some_and(|o| o != chart) {
            continue;
        }
        let path = out.join(chart.file_name());
        match chart {
            Chart::Fig5 => {
                let curve = fig5_curve(FIG5_POINTS)?;
                draw_fig5(&path, &curve)?;
                text.push_str(&fig5_table(&curve));
            }
            Chart::Solvers => {
                let sweep = solver_sweep();
                draw_solvers(&path, &sweep)?;
                text.push_str(&solvers_table(&sweep));
            }
            Chart::Tiles => draw_tiles(&path, &tile_rows()?)?,
            Chart::Atan => {
                let errors = AtanImpl::ALL.map(atan_errors);
                let cost = match cost_source {
                    AtanCostSource::Skip => {
                        text.push_str("note: atan cost not measured (--no-cost)\n");
                        None
                    }
                    AtanCostSource::Callgrind { exe } => {
                        let c = measure_atan_cost(exe)?;
                        if c.is_none() {
                            text.push_str(
                                "note: valgrind not found: atan cost not measured; the atan chart \
                                 plots errors per implementation instead of against cost\n",
                            );
                        } else if cfg!(debug_assertions) {
                            text.push_str(
                                "note: this is a debug build: its instruction counts are not the \
                                 release figures of docs/models.md (use --release)\n",
                            );
                        }
                        c
                    }
                };
                draw_atan(&path, &errors, cost.as_ref(), &atan_curve())?;
                text.push_str(&atan_table(&errors, cost.as_ref()));
            }
        }
        let _ = writeln!(text, "wrote {}", path.display());
    }
    Ok(text)
}

// ---------------------------------------------------------------- tables

/// The fig. 5 values quoted in docs/models.md: f_ss at the curve points nearest Δμ = 0.01, 0.1,
/// 1 and 10.
pub fn fig5_table(curve: &[Fig5Point]) -> String {
    let mut s = String::new();
    for target in [0.01, 0.1, 1.0, 10.0] {
        let Some(p) = curve.iter().min_by(|a, b| {
            (a.delta_mu - target)
                .abs()
                .total_cmp(&(b.delta_mu - target).abs())
        }) else {
            continue;
        };
        let _ = writeln!(
            s,
            "fig5: delta_mu = {}: f_ss = {} Hz",
            sig(p.delta_mu, 4),
            sig(p.f_ss_hz, 4)
        );
    }
    s
}

/// The solver table of docs/models.md (rtol = 1e-3, 1e-6 … 1e-15), Markdown.
pub fn solvers_table(sweep: &[SolverStats]) -> String {
    let mut s = String::from(
        "\n| solver | rtol | solved/cases | mean iter | max iter | mean evals (f + f') | max rel θ error |\n\
         |---|---|---|---|---|---|---|\n",
    );
    for st in sweep {
        // The exponent is recovered from rtol = 10⁻ⁿ so that the table shows `1e-3`, not
        // 10f64.powi(-3)'s last-digit noise.
        let n = (-st.rtol.log10()).round() as i32;
        if n % 3 != 0 {
            continue;
        }
        let _ = writeln!(
            s,
            "| {} | 1e-{n} | {}/{} | {:.2} | {} | {:.2} | {} |",
            st.solver.name(),
            st.solved,
            st.cases,
            st.mean_iterations,
            st.max_iterations,
            st.mean_evaluations,
            exp(st.max_rel_theta_error, 1)
        );
    }
    s
}

/// The atan table of docs/models.md, Markdown; cost columns `—` without a cost.
pub fn atan_table(errors: &[AtanError], cost: Option<&AtanCost>) -> String {
    let mut s = String::from(
        "\n| atan | max abs err (rad) | mean abs err (rad) | max rel f_ss err | mean rel f_ss err | x86-64 instr/call (net of loop) | f_ss per sample, instr |\n\
         |---|---|---|---|---|---|---|\n",
    );
    let dash = || "—".to_string();
    for e in errors {
        let i = AtanImpl::ALL.iter().position(|&x| x == e.imp).unwrap_or(0);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} |",
            e.imp.name(),
            exp(e.max_abs_rad, 2),
            exp(e.mean_abs_rad, 2),
            exp(e.max_rel_f_ss, 2),
            exp(e.mean_rel_f_ss, 2),
            cost.map_or_else(dash, |c| format!("{:.1}", c.atan_instr[i])),
            cost.and_then(|c| c.fss_instr[i])
                .map_or_else(dash, |x| format!("{x:.1}"))
        );
    }
    if let Some(c) = cost {
        let _ = writeln!(
            s,
            "(loop overhead {:.1} instr/iteration, subtracted)",
            c.loop_instr
        );
    }
    s
}

/// `x` to `digits` significant digits without trailing zeros (C's `%g` for moderate values).
fn sig(x: f64, digits: usize) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let mag = x.abs().log10().floor() as i32;
    if !(-4..digits as i32).contains(&mag) {
        return exp(x, digits.saturating_sub(1));
    }
    let decimals = (digits as i32 - 1 - mag).max(0) as usize;
    let s = format!("{x:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// `x` in scientific notation with a two-digit exponent (`3.3e-04`), as the docs' tables print.
fn exp(x: f64, decimals: usize) -> String {
    let s = format!("{x:.decimals$e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let e: i32 = e.parse().unwrap_or(0);
            format!("{m}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs())
        }
        None => s,
    }
}

// ---------------------------------------------------------------- atan cost (callgrind)

/// Bench loops (names of `model atan-bench --impl`) and the symbols callgrind collects in.
const BENCHES: [(&str, &str); 6] = [
    ("none", "bench_atan_none"),
    ("micromath", "bench_atan_micromath"),
    ("libm", "bench_atan_libm"),
    ("f64", "bench_atan_f64"),
    ("fss-micromath", "bench_fss_micromath"),
    ("fss-libm", "bench_fss_libm"),
];

/// Two run lengths, differenced so that everything outside the loop body (start-up, input
/// generation) cancels: instructions per iteration = (Ir(N2) − Ir(N1))/(N2 − N1).
const BENCH_N1: u64 = 10_000;
const BENCH_N2: u64 = 20_000;

/// Counts the bench loops of `exe` under callgrind; `Ok(None)` when valgrind is not installed.
pub fn measure_atan_cost(exe: &Path) -> Result<Option<AtanCost>, String> {
    let work = std::env::temp_dir().join(format!("saw-models-callgrind-{}", std::process::id()));
    std::fs::create_dir_all(&work).map_err(|e| format!("{}: {e}", work.display()))?;
    let result = (|| {
        let mut per_iteration = [0.0f64; BENCHES.len()];
        for (slot, (what, symbol)) in per_iteration.iter_mut().zip(BENCHES) {
            let Some(a) = callgrind_ir(exe, &work, what, BENCH_N1, symbol)? else {
                return Ok(None);
            };
            let Some(b) = callgrind_ir(exe, &work, what, BENCH_N2, symbol)? else {
                return Ok(None);
            };
            *slot = (b as f64 - a as f64) / (BENCH_N2 - BENCH_N1) as f64;
        }
        let lp = per_iteration[0];
        Ok(Some(AtanCost {
            loop_instr: lp,
            atan_instr: [
                per_iteration[1] - lp,
                per_iteration[2] - lp,
                per_iteration[3] - lp,
            ],
            fss_instr: [
                Some(per_iteration[4] - lp),
                Some(per_iteration[5] - lp),
                None,
            ],
        }))
    })();
    let _ = std::fs::remove_dir_all(&work);
    result
}

/// Instructions callgrind counts inside `symbol` for one `model atan-bench` run; `Ok(None)` when
/// valgrind cannot be started because it is not installed.
fn callgrind_ir(
    exe: &Path,
    work: &Path,
    what: &str,
    n: u64,
    symbol: &str,
) -> Result<Option<u64>, String> {
    let out_file = work.join(format!("cg-{what}-{n}.out"));
    let run = Command::new("valgrind")
        .arg("--tool=callgrind")
        .arg(format!("--callgrind-out-file={}", out_file.display()))
        .arg(format!("--toggle-collect=*{symbol}*"))
        .arg(exe)
        .args(["model", "atan-bench", "--impl", what, "--n", &n.to_string()])
        .output();
    let run = match run {
        Ok(r) => r,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("valgrind: {e}")),
    };
    if !run.status.success() {
        return Err(format!(
            "valgrind on {} model atan-bench --impl {what}: {}\n{}",
            exe.display(),
            run.status,
            String::from_utf8_lossy(&run.stderr)
        ));
    }
    let text =
        std::fs::read_to_string(&out_file).map_err(|e| format!("{}: {e}", out_file.display()))?;
    callgrind_total(&text)
        .map(Some)
        .ok_or_else(|| format!("{}: no summary/totals line", out_file.display()))
}

/// The event total of a callgrind output file (its `summary:` or `totals:` line; Ir first).
pub fn callgrind_total(text: &str) -> Option<u64> {
    text.lines().find_map(|l| {
        let rest = l
            .strip_prefix("summary:")
            .or_else(|| l.strip_prefix("totals:"))?;
        rest.split_whitespace().next()?.parse().ok()
    })
}

// ---------------------------------------------------------------- drawing helpers

/// matplotlib's first colours (tab10), so that series keep the colours the charts always had.
const TAB10: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

const FONT: &str = "sans-serif";

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// House style of every panel: faint grid at the labelled ticks only (no minor grid, as
/// host-sim's other charts: it adds nothing to read and makes the PNGs several times larger),
/// 15 px axis descriptions, 14 px tick labels.
fn house_style<'m, 'a, 'b, X: Ranged, Y: Ranged, DB: DrawingBackend>(
    m: &'m mut MeshStyle<'a, 'b, X, Y, DB>,
) -> &'m mut MeshStyle<'a, 'b, X, Y, DB> {
    m.axis_desc_style((FONT, 15))
        .label_style((FONT, 14))
        .bold_line_style(BLACK.mix(0.12))
        .light_line_style(WHITE.mix(0.0))
}

/// Legend box in the house style.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    c: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
    font_px: u32,
) -> Result<(), String> {
    c.configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.3))
        .label_font((FONT, font_px))
        .draw()
        .map_err(err)
}

/// Splits off a header of `lines.len()` centred title lines and returns the rest of `root`.
fn header<'a>(
    root: &DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>,
    lines: &[&str],
    font_px: u32,
) -> Result<DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>, String> {
    let line_px = font_px as i32 + 6;
    let (head, body) = root.split_vertically(line_px * lines.len() as i32 + 8);
    let centre = head.dim_in_pixel().0 as i32 / 2;
    let style = TextStyle::from((FONT, font_px).into_font()).pos(Pos::new(HPos::Center, VPos::Top));
    for (i, l) in lines.iter().enumerate() {
        head.draw(&Text::new(
            l.to_string(),
            (centre, 6 + line_px * i as i32),
            style.clone(),
        ))
        .map_err(err)?;
    }
    Ok(body)
}

/// Log-axis range over [lo, hi] with 5 % padding in log space, widened to whole decades when
/// fewer than two decades would be inside (plotters puts log ticks only on and between decades,
/// so a narrower axis would have no ticks at all).
fn log_range(lo: f64, hi: f64) -> std::ops::Range<f64> {
    let (a, b) = (lo.log10(), hi.log10());
    let pad = 0.05 * (b - a).max(0.1);
    let (mut a, mut b) = (a - pad, b + pad);
    if b.floor() - a.ceil() < 1.0 {
        (a, b) = (a.floor(), b.ceil());
    }
    10f64.powf(a)..10f64.powf(b)
}

/// Linear range over [lo, hi] with 5 % padding.
fn lin_range(lo: f64, hi: f64) -> std::ops::Range<f64> {
    let pad = 0.05 * (hi - lo).max(1e-12);
    lo - pad..hi + pad
}

/// (min, max) of the finite values.
fn min_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
}

/// Tick label of a log axis: powers of ten as 10ⁿ, 2, 3 and 5 times a power of ten as plain
/// numbers (as matplotlib labels a short log axis), other ticks unlabelled so that the labels
/// near the next decade do not run into it.
fn log_tick(v: &f64) -> String {
    let e = v.log10();
    if (e - e.round()).abs() < 1e-6 {
        return format!("10{}", superscript(e.round() as i32));
    }
    let mantissa = v / 10f64.powf(e.floor());
    if [2.0, 3.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-6) {
        sig(*v, 3)
    } else {
        String::new()
    }
}

fn superscript(n: i32) -> String {
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let mut s = String::new();
    if n < 0 {
        s.push('⁻');
    }
    for c in n.unsigned_abs().to_string().chars() {
        s.push(DIGITS[c.to_digit(10).unwrap_or(0) as usize]);
    }
    s
}

/// Marker shapes (matplotlib's "o", "s", "^").
#[derive(Clone, Copy, Debug)]
enum Shape {
    Circle,
    Square,
    Triangle,
}

/// How a series' points are marked.
#[derive(Clone, Copy, Debug)]
struct Marker {
    shape: Shape,
    /// Half-width (circle radius), px.
    size_px: i32,
    colour: RGBColor,
    /// Outline only (white inside).
    hollow: bool,
}

/// Draws one marker per point and, if `label` is given, labels the series with a legend entry
/// (`legend_line` drawn through the marker when given). A hollow marker is the filled one with
/// a white one inside (plotters' stroked circles are ragged and its triangles are always filled).
fn draw_markers<'a, DB: DrawingBackend + 'a, CT: CoordTranslate<From = (f64, f64)>>(
    c: &mut ChartContext<'a, DB, CT>,
    points: &[(f64, f64)],
    marker: Marker,
    label: Option<String>,
    legend_line: Option<ShapeStyle>,
) -> Result<(), String> {
    // Ring width 2 px; a triangle's edges move in by half the change of its circumradius.
    match marker.shape {
        Shape::Circle => marker_series(c, points, marker, label, legend_line, 2, |cx, s, st| {
            Circle::new((cx, 0), s, st)
        }),
        Shape::Square => marker_series(c, points, marker, label, legend_line, 2, |cx, s, st| {
            Rectangle::new([(cx - s, -s), (cx + s, s)], st)
        }),
        // A triangle's size is its circumradius: one pixel more to match the others' area.
        Shape::Triangle => marker_series(c, points, marker, label, legend_line, 4, |cx, s, st| {
            TriangleMarker::new((cx, 0), s + 1, st)
        }),
    }
}

/// [`draw_markers`] for one shape: `shape(x offset, half-width, style)` is the marker's element
/// (centred `x offset` px right of its point), drawn twice, the inner one `inset` px smaller.
/// Generic over the element because plotters' type-erased element (`DynElement`) cannot be
/// drawn on a backend that borrows its file path.
fn marker_series<'a, DB, CT, E>(
    c: &mut ChartContext<'a, DB, CT>,
    points: &[(f64, f64)],
    marker: Marker,
    label: Option<String>,
    legend_line: Option<ShapeStyle>,
    inset: i32,
    shape: impl Fn(i32, i32, ShapeStyle) -> E + Copy + 'a,
) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate<From = (f64, f64)>,
    E: Drawable<DB> + 'a,
    for<'b> &'b E: PointCollection<'b, (i32, i32)>,
{
    let outer = marker.colour.filled();
    let inner = if marker.hollow { WHITE.filled() } else { outer };
    let size_px = marker.size_px;
    let anno = c
        .draw_series(points.iter().map(|&p| {
            EmptyElement::at(p) + shape(0, size_px, outer) + shape(0, size_px - inset, inner)
        }))
        .map_err(err)?;
    if let Some(l) = label {
        // Legend entries are 24 px wide; the marker sits in the middle.
        let line = legend_line.unwrap_or_else(|| TRANSPARENT.stroke_width(0));
        let lpx = size_px.min(6);
        anno.label(l).legend(move |(x, y)| {
            // Spelled out: with `E`'s bounds in scope, `EmptyElement + PathElement` would be
            // inferred as `EmptyElement + E`.
            let path = PathElement::new(vec![(0, 0), (24, 0)], line);
            <EmptyElement<_, DB> as Add<PathElement<_>>>::add(EmptyElement::at((x, y)), path)
                + shape(12, lpx, outer)
                + shape(12, lpx - inset, inner)
        });
    }
    Ok(())
}

// ---------------------------------------------------------------- charts

/// Fig. 5: f_ss against μs − μc on log axes, with the large-R asymptote and the ω0/2π plateau.
pub fn draw_fig5(path: &Path, curve: &[Fig5Point]) -> Result<(), String> {
    let (Some(first), Some(last)) = (curve.first(), curve.last()) else {
        return Err("fig5: empty curve".into());
    };
    let f0_hz = first.f0_hz;
    let p = StickSlipParams::fig5(1.0);
    let root = BitMapBackend::new(path, (800, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let title = format!(
        "Nara et al. fig. 5: P = {} N, m = {} g, k = {} N/m, U = {} cm/s",
        sig(p.normal_force_n, 4),
        sig(p.mass_kg * 1e3, 4),
        sig(p.stiffness_n_per_m, 4),
        sig(p.speed_m_s * 1e2, 4)
    );
    // Matplotlib's limits: the curve's low end / 2 to twice the plateau.
    let (y_lo, y_hi) = (last.f_ss_hz * 0.5, f0_hz * 2.0);
    let (x_lo, x_hi) = min_max(curve.iter().map(|p| p.delta_mu));
    let mut c = ChartBuilder::on(&root)
        .caption(title, (FONT, 18))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(log_range(x_lo, x_hi).log_scale(), (y_lo..y_hi).log_scale())
        .map_err(err)?;
    house_style(
        c.configure_mesh()
            .x_desc("μs − μc")
            .y_desc("stick-slip frequency f_ss (Hz)")
            .x_label_formatter(&log_tick)
            .y_label_formatter(&log_tick),
    )
    .draw()
    .map_err(err)?;
    let f_style = TAB10[0].stroke_width(2);
    c.draw_series(LineSeries::new(
        curve.iter().map(|p| (p.delta_mu, p.f_ss_hz)),
        f_style,
    ))
    .map_err(err)?
    .label("f_ss (eq. 10, f64)")
    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], f_style));
    // The asymptote ∝ 1/Δμ leaves the top of the chart at small Δμ: start it where it crosses
    // y_hi so that the dashes are not drawn over the title.
    let asym: Vec<(f64, f64)> = {
        let k = last.asymptote_hz * last.delta_mu;
        let mut v = vec![(k / y_hi, y_hi)];
        v.extend(
            curve
                .iter()
                .filter(|p| p.asymptote_hz < y_hi)
                .map(|p| (p.delta_mu, p.asymptote_hz)),
        );
        v
    };
    let a_style = TAB10[1].stroke_width(2);
    c.draw_series(DashedLineSeries::new(asym, 8, 5, a_style))
        .map_err(err)?
        .label("large-R asymptote kU/(2ΔμP)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], a_style));
    let p_style = BLACK.mix(0.5).stroke_width(2);
    c.draw_series(DashedLineSeries::new(
        [(x_lo / 10.0, f0_hz), (x_hi * 10.0, f0_hz)],
        2,
        4,
        p_style,
    ))
    .map_err(err)?
    .label(format!("ω0/2π = {f0_hz:.1} Hz (Δμ → 0)"))
    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], p_style));
    legend(&mut c, SeriesLabelPosition::LowerLeft, 14)?;
    root.present().map_err(err)
}

/// Solver cost against achieved accuracy: two panels (iterations; evaluations of eq. 4 plus
/// derivative), accuracy growing to the right.
pub fn draw_solvers(path: &Path, sweep: &[SolverStats]) -> Result<(), String> {
    let cases = sweep.first().map_or(0, |s| s.cases);
    let root = BitMapBackend::new(path, (1210, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let (e_lo, e_hi) = (SWEEP_RTOL_EXPONENTS.start(), SWEEP_RTOL_EXPONENTS.end());
    let l1 = format!(
        "θ solvers on eq. 4: {cases} cases (paper tiles × 1,4,9,16 oz × k 0.008/0.08/0.8 × μ 0/0.5/2), rtol 1e-{e_lo}…1e-{e_hi}"
    );
    let l2 = "Newton (from π/4) fails on the cases whose pole θ* < π/4 (counted out of its means)";
    let body = header(&root, &[&l1, l2], 15)?;
    let panels = body.split_evenly((1, 2));
    // Accuracy as −log10(error) on a linear axis, so that better accuracy is to the right
    // (plotters has no reversed log axis). Exact results (error 0) sit at 1e-17.
    let acc = |s: &SolverStats| -s.max_rel_theta_error.max(1e-17).log10();
    let (x_lo, x_hi) = min_max(sweep.iter().map(acc));
    let x_tick = |x: &f64| {
        if (x - x.round()).abs() < 1e-6 {
            format!("10{}", superscript(-x.round() as i32))
        } else {
            String::new()
        }
    };
    type Metric = fn(&SolverStats) -> f64;
    let metrics: [(&str, Metric); 2] = [
        ("mean iterations", |s| s.mean_iterations),
        ("mean evaluations of eq. 4 + derivative", |s| {
            s.mean_evaluations
        }),
    ];
    let shapes = [Shape::Circle, Shape::Square, Shape::Triangle];
    for (panel, (y_desc, metric)) in panels.iter().zip(metrics) {
        let (_, y_hi) = min_max(sweep.iter().map(metric));
        let mut c = ChartBuilder::on(panel)
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(60)
            .build_cartesian_2d(lin_range(x_lo, x_hi), 0.0..y_hi * 1.05)
            .map_err(err)?;
        house_style(
            c.configure_mesh()
                .x_desc("achieved accuracy: max |θ − θ_ref|/θ_ref")
                .y_desc(y_desc)
                .x_labels(16)
                .x_label_formatter(&x_tick)
                .y_label_formatter(&|y: &f64| format!("{y:.0}")),
        )
        .draw()
        .map_err(err)?;
        for (i, solver) in Solver::ALL.into_iter().enumerate() {
            let colour = TAB10[i];
            let shape = shapes[i];
            let pts: Vec<(f64, f64)> = sweep
                .iter()
                .filter(|s| s.solver == solver)
                .map(|s| (acc(s), metric(s)))
                .collect();
            c.draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                .map_err(err)?;
            let m = Marker {
                shape,
                size_px: 5,
                colour,
                hollow: false,
            };
            draw_markers(
                &mut c,
                &pts,
                m,
                Some(solver.name().to_string()),
                Some(colour.stroke_width(2)),
            )?;
        }
        legend(&mut c, SeriesLabelPosition::UpperLeft, 14)?;
    }
    root.present().map_err(err)
}

/// Tile sets: A (top row) and D (bottom row) against the varied width, one column per set, one
/// line per force; the amplitude ‰ of the grating region labels A at the lowest and highest
/// force.
pub fn draw_tiles(path: &Path, rows: &[TileRow]) -> Result<(), String> {
    let mut sets: Vec<&str> = Vec::new();
    for r in rows {
        if !sets.contains(&r.tile.set) {
            sets.push(r.tile.set);
        }
    }
    let mut forces: Vec<f64> = Vec::new();
    for r in rows {
        if !forces.contains(&r.force_g) {
            forces.push(r.force_g);
        }
    }
    forces.sort_by(f64::total_cmp);
    let paper = GroovedInput::paper(1.0, 1.0, 1.0);
    let title = format!(
        "Taylor & Lederman tile sets (figs. 2–4): k = {} mm/g, μ = {}, pad {} mm² at {} g ∝ F^{}; amplitude ‰ = 1000·A/A_max",
        paper.k_mm_per_g, paper.mu, paper.pad.area_ref_mm2, paper.pad.force_ref_g, paper.pad.exponent
    );
    let root = BitMapBackend::new(path, (1430, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let body = header(&root, &[&title], 15)?;
    let panels = body.split_evenly((2, sets.len().max(1)));
    // Rows share their y range, as matplotlib's sharey="row" did.
    type Quantity = fn(&TileRow) -> f64;
    let quantities: [(&str, Quantity); 2] = [
        ("A (mm², summed over pad)  [labels: amplitude ‰]", |r| {
            r.a_mm2
        }),
        ("D (mm)", |r| r.d_mm),
    ];
    for (qi, (y_desc, q)) in quantities.into_iter().enumerate() {
        let (_, y_hi) = min_max(rows.iter().map(q));
        for (si, set) in sets.iter().enumerate() {
            let in_set: Vec<&TileRow> = rows.iter().filter(|r| r.tile.set == *set).collect();
            // The set varies G or L; the other width is fixed.
            let varies_groove = in_set
                .iter()
                .any(|r| r.tile.groove_mm != in_set[0].tile.groove_mm);
            let x_of = |r: &TileRow| {
                if varies_groove {
                    r.tile.groove_mm
                } else {
                    r.tile.land_mm
                }
            };
            let (x_lo, x_hi) = min_max(in_set.iter().map(|r| x_of(r)));
            let panel = &panels[qi * sets.len() + si];
            let mut b = ChartBuilder::on(panel);
            b.margin(10)
                .x_label_area_size(if qi == 1 { 45 } else { 25 })
                .y_label_area_size(if si == 0 { 75 } else { 45 });
            if qi == 0 {
                b.caption(*set, (FONT, 17));
            }
            let mut c = b
                .build_cartesian_2d(lin_range(x_lo, x_hi), -0.03 * y_hi..y_hi * 1.08)
                .map_err(err)?;
            let x_desc = if varies_groove {
                "groove width G (mm)"
            } else {
                "land width L (mm)"
            };
            let mut mesh = c.configure_mesh();
            if qi == 1 {
                mesh.x_desc(x_desc);
            }
            if si == 0 {
                mesh.y_desc(y_desc);
            }
            house_style(&mut mesh).draw().map_err(err)?;
            for (fi, &f) in forces.iter().enumerate() {
                let colour = TAB10[fi % TAB10.len()];
                let pts: Vec<(f64, f64, u16)> = in_set
                    .iter()
                    .filter(|r| r.force_g == f)
                    .map(|r| (x_of(r), q(r), r.amplitude_permille))
                    .collect();
                let s = c
                    .draw_series(LineSeries::new(
                        pts.iter().map(|p| (p.0, p.1)),
                        colour.stroke_width(2),
                    ))
                    .map_err(err)?;
                if qi == 0 && si == 0 {
                    s.label(format!("F = {f:.0} g ({:.0} oz)", f / OZ_G))
                        .legend(move |(x, y)| {
                            EmptyElement::at((x, y))
                                + PathElement::new(vec![(0, 0), (24, 0)], colour.stroke_width(2))
                                + Circle::new((12, 0), 3, colour.filled())
                        });
                }
                c.draw_series(
                    pts.iter()
                        .map(|p| Circle::new((p.0, p.1), 3, colour.filled())),
                )
                .map_err(err)?;
                let extreme_force = fi == 0 || fi + 1 == forces.len();
                if qi == 0 && extreme_force {
                    let style = TextStyle::from((FONT, 10).into_font())
                        .pos(Pos::new(HPos::Center, VPos::Bottom));
                    c.draw_series(pts.iter().map(|p| {
                        EmptyElement::at((p.0, p.1))
                            + Text::new(p.2.to_string(), (0, -5), style.clone())
                    }))
                    .map_err(err)?;
                }
            }
            if qi == 0 && si == 0 {
                legend(&mut c, SeriesLabelPosition::UpperLeft, 12)?;
            }
        }
    }
    root.present().map_err(err)
}

/// atan: error against cost (or per implementation without a cost) and error against R.
pub fn draw_atan(
    path: &Path,
    errors: &[AtanError],
    cost: Option<&AtanCost>,
    curve: &[AtanCurvePoint],
) -> Result<(), String> {
    let root = BitMapBackend::new(path, (1210, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let panels = root.split_evenly((1, 2));
    let (e_lo, e_hi) = min_max(
        errors
            .iter()
            .flat_map(|e| [e.max_abs_rad, e.max_rel_f_ss])
            .filter(|&e| e > 0.0),
    );
    let y = log_range(e_lo, e_hi);
    match cost {
        Some(c) => {
            let (c_lo, c_hi) = min_max(c.atan_instr.iter().copied().filter(|&x| x > 0.0));
            let x = ImplAxis {
                range: log_range(c_lo, c_hi).log_scale(),
                desc: "cost: x86-64 instructions per call (callgrind, loop overhead subtracted)",
                tick: &log_tick,
                at: c.atan_instr,
            };
            let caption = format!("error against cost, R ∈ [0, {R_MAX}]");
            atan_error_panel(&panels[0], &caption, x, y, errors)?;
        }
        None => {
            // No cost axis: implementations side by side.
            let name = |x: &f64| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && (0.0..3.0).contains(&i) {
                    AtanImpl::ALL[i as usize].name().to_string()
                } else {
                    String::new()
                }
            };
            let x = ImplAxis {
                range: -0.5..2.5,
                desc: "implementation (cost not measured: valgrind missing or --no-cost)",
                tick: &name,
                at: [0.0, 1.0, 2.0],
            };
            let caption = format!("error per implementation, R ∈ [0, {R_MAX}]");
            atan_error_panel(&panels[0], &caption, x, y, errors)?;
        }
    }

    // Error against R.
    let floor = 1e-12;
    let (r_lo, r_hi) = min_max(curve.iter().map(|p| p.r as f64).filter(|&r| r > 0.0));
    let (a_lo, a_hi) = min_max(curve.iter().map(|p| p.abs_err_rad.max(floor)));
    let mut c = ChartBuilder::on(&panels[1])
        .caption("atan error over the R range", (FONT, 17))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            log_range(r_lo, r_hi).log_scale(),
            log_range(a_lo, a_hi).log_scale(),
        )
        .map_err(err)?;
    house_style(
        c.configure_mesh()
            .x_desc("R = Δμ P/(m ω0 U)")
            .y_desc("|atan(R) − atan_f64(R)| (rad), floored at 1e-12")
            .x_label_formatter(&log_tick)
            .y_label_formatter(&log_tick),
    )
    .draw()
    .map_err(err)?;
    for (i, imp) in AtanImpl::ALL.into_iter().enumerate() {
        let colour = TAB10[i];
        c.draw_series(LineSeries::new(
            curve
                .iter()
                .filter(|p| p.imp == imp && p.r > 0.0)
                .map(|p| (p.r as f64, p.abs_err_rad.max(floor))),
            colour.stroke_width(1),
        ))
        .map_err(err)?
        .label(imp.name())
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(2)));
    }
    legend(&mut c, SeriesLabelPosition::LowerLeft, 12)?;
    root.present().map_err(err)
}

/// The x axis of the left atan panel: cost (log) or the implementations side by side.
struct ImplAxis<'f, XR> {
    range: XR,
    desc: &'f str,
    tick: &'f dyn Fn(&f64) -> String,
    /// x of each implementation, in [`AtanImpl::ALL`] order.
    at: [f64; 3],
}

/// Left atan panel: max |atan error| (filled) and max relative f_ss error (hollow) per
/// implementation, at that implementation's x.
fn atan_error_panel<XR>(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    caption: &str,
    x: ImplAxis<'_, XR>,
    y: std::ops::Range<f64>,
    errors: &[AtanError],
) -> Result<(), String>
where
    XR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: ValueFormatter<f64>,
{
    let mut c = ChartBuilder::on(area)
        .caption(caption, (FONT, 17))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(x.range, y.log_scale())
        .map_err(err)?;
    house_style(
        c.configure_mesh()
            .x_desc(x.desc)
            .y_desc("error")
            .x_label_formatter(x.tick)
            .y_label_formatter(&log_tick),
    )
    .draw()
    .map_err(err)?;
    let shapes = [Shape::Circle, Shape::Square, Shape::Triangle];
    for e in errors {
        // Colour, shape and x follow the implementation, whatever order `errors` is in.
        let i = AtanImpl::ALL.iter().position(|&x| x == e.imp).unwrap_or(0);
        let (colour, shape, x) = (TAB10[i], shapes[i], x.at[i]);
        for (value, what, hollow) in [
            (e.max_abs_rad, "max |atan err|", false),
            (e.max_rel_f_ss, "max rel f_ss err", true),
        ] {
            let m = Marker {
                shape,
                size_px: 8,
                colour,
                hollow,
            };
            draw_markers(
                &mut c,
                &[(x, value)],
                m,
                Some(format!("{}: {what}", e.imp.name())),
                None,
            )?;
        }
    }
    legend(&mut c, SeriesLabelPosition::UpperRight, 12)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn callgrind_total_reads_summary_or_totals() {
        assert_eq!(
            callgrind_total("events: Ir\nfn=x\n1 2\nsummary: 12345\n"),
            Some(12345)
        );
        assert_eq!(callgrind_total("totals: 77 3\n"), Some(77));
        assert_eq!(callgrind_total("events: Ir\n"), None);
    }

    #[test]
    fn number_formats_match_the_docs_tables() {
        assert_eq!(exp(3.3e-4, 1), "3.3e-04");
        assert_eq!(exp(2.827e-3, 2), "2.83e-03");
        assert_eq!(sig(112.54, 4), "112.5");
        assert_eq!(sig(0.996, 4), "0.996");
        assert_eq!(sig(10.0, 4), "10");
        assert_eq!(superscript(-12), "⁻¹²");
    }

    #[test]
    fn log_range_always_holds_a_decade_tick() {
        for (lo, hi) in [(14.0, 76.0), (1e-3, 10.0), (0.5, 0.6)] {
            let r = log_range(lo, hi);
            assert!(r.start <= lo && r.end >= hi);
            assert!(r.end.log10().floor() >= r.start.log10().ceil(), "{r:?}");
        }
    }
}
