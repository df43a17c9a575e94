//! PNG chart of a run: stacked panels over time — position, velocity, region, gate line.

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::sim::{SimResult, TracePoint};

/// Points per trace after decimation (min/max per bucket, so spikes survive).
const BUCKETS: usize = 1_500;

/// Min/max decimation of `(t, y)` points (sorted by t) into `buckets` buckets over `[t0, t1]`.
fn decimate(points: &[(f64, f64)], t0: f64, t1: f64, buckets: usize) -> Vec<(f64, f64)> {
    if points.len() <= 2 * buckets {
        return points.to_vec();
    }
    let width = (t1 - t0) / buckets as f64;
    let mut out = Vec::with_capacity(2 * buckets);
    let mut i = 0;
    for b in 0..buckets {
        let end = t0 + (b + 1) as f64 * width;
        let start = i;
        let (mut lo, mut hi) = ((0.0, f64::MAX), (0.0, f64::MIN));
        while i < points.len() && (points[i].0 < end || b + 1 == buckets) {
            let p = points[i];
            if p.1 < lo.1 {
                lo = p;
            }
            if p.1 > hi.1 {
                hi = p;
            }
            i += 1;
        }
        if i == start {
            continue;
        }
        if lo.0 <= hi.0 {
            out.push(lo);
            out.push(hi);
        } else {
            out.push(hi);
            out.push(lo);
        }
    }
    out
}

/// Splits a series at `None` values into continuous runs.
fn runs(points: impl Iterator<Item = (f64, Option<f64>)>) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (t, y) in points {
        match y {
            Some(y) => out.last_mut().unwrap().push((t, y)),
            None => {
                if !out.last().unwrap().is_empty() {
                    out.push(Vec::new());
                }
            }
        }
    }
    out.retain(|r| !r.is_empty());
    out
}

/// Writes the chart of `r` to `path` (PNG).
/// (t s, value) points.
type Series = Vec<(f64, f64)>;

/// One quantity over time from the trace: the truth, and what the core saw (in runs broken where
/// it saw nothing).
fn truth_and_core(
    r: &SimResult,
    truth: impl Fn(&TracePoint) -> f64,
    core: impl Fn(&TracePoint) -> Option<f64>,
) -> (Series, Vec<Series>) {
    let t_s = |p: &TracePoint| p.t_us as f64 * 1e-6;
    let truth = r.trace.iter().map(|p| (t_s(p), truth(p))).collect();
    (truth, runs(r.trace.iter().map(|p| (t_s(p), core(p)))))
}

/// Draws what the core saw (red, in runs broken by faults) over the truth (blue), decimated to
/// the panel's width, and the legend: `(runs, label, line width)` and `(truth, line width)`.
fn core_against_truth<'a, DB: DrawingBackend + 'a>(
    c: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    (core, label, core_width): (&[Vec<(f64, f64)>], &str, u32),
    (truth, truth_width): (&[(f64, f64)], u32),
    t_end: f64,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    for (i, run) in core.iter().enumerate() {
        let s = c.draw_series(LineSeries::new(
            decimate(run, 0.0, t_end, BUCKETS),
            RED.stroke_width(core_width),
        ))?;
        if i == 0 {
            s.label(label)
                .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        }
    }
    c.draw_series(LineSeries::new(
        decimate(truth, 0.0, t_end, BUCKETS),
        BLUE.stroke_width(truth_width),
    ))?
    .label("true")
    .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    c.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    Ok(())
}

pub fn write_png(
    r: &SimResult,
    path: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1600, 1200)).into_drawing_area();
    root.fill(&WHITE)?;
    let (header, body) = root.split_vertically(40);
    header.draw(&Text::new(
        title.to_string(),
        (20, 10),
        ("sans-serif", 22).into_font(),
    ))?;
    let panels = body.split_by_breakpoints::<i32, i32, _, _>([], [330, 660, 860]);
    let t_end = r.params.duration_s;
    let label_font = ("sans-serif", 18);

    // Position.
    {
        let (tp, meas) = truth_and_core(
            r,
            |p| p.true_um / 1e3,
            |p| p.meas_um.map(|m| m as f64 / 1e3),
        );
        let len_mm = r.params.config.calibration.length_um as f64 / 1e3;
        let mut c = ChartBuilder::on(&panels[0])
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -1.0..len_mm + 1.0)?;
        c.configure_mesh()
            .y_desc("position (mm)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        for &b in r.params.config.scene.boundaries_um.iter() {
            let b = b as f64 / 1e3;
            c.draw_series(DashedLineSeries::new(
                vec![(0.0, b), (t_end, b)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?
            .label(format!("boundary {b:.3} mm"))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5)));
        }
        core_against_truth(&mut c, (&meas, "measured", 2), (&tp, 1), t_end)?;
    }

    // Velocity.
    {
        let (tv, est) = truth_and_core(
            r,
            |p| p.true_vel_um_s / 1e3,
            |p| p.est_vel_um_s.map(|v| v as f64 / 1e3),
        );
        let vmax = tv
            .iter()
            .map(|p| p.1.abs())
            .chain(est.iter().flatten().map(|p| p.1.abs()))
            .fold(10.0f64, f64::max)
            * 1.15;
        let mut c = ChartBuilder::on(&panels[1])
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -vmax..vmax)?;
        c.configure_mesh()
            .y_desc("velocity (mm/s)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        core_against_truth(&mut c, (&est, "estimated (core)", 1), (&tv, 2), t_end)?;
    }

    // Region (−1 = none: fault or no scene).
    {
        let n = r.params.config.scene.textures.len() as f64;
        let mut pts = Vec::new();
        let mut last: Option<f64> = None;
        for p in &r.trace {
            let t = p.t_us as f64 * 1e-6;
            let y = p.region.map(|x| x as f64).unwrap_or(-1.0);
            if last != Some(y) {
                if let Some(l) = last {
                    pts.push((t, l));
                }
                pts.push((t, y));
                last = Some(y);
            }
        }
        if let Some(l) = last {
            pts.push((t_end, l));
        }
        let mut c = ChartBuilder::on(&panels[2])
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -1.5..n - 0.5)?;
        let labels: Vec<String> = r
            .params
            .config
            .scene
            .textures
            .iter()
            .map(region_label)
            .collect();
        c.configure_mesh()
            .y_desc("region")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .y_labels(n as usize + 2)
            .y_label_formatter(&|y: &f64| {
                let i = y.round() as i64;
                if (y - i as f64).abs() > 0.01 {
                    String::new()
                } else if i < 0 {
                    "none".into()
                } else {
                    format!(
                        "{i}: {}",
                        labels.get(i as usize).cloned().unwrap_or_default()
                    )
                }
            })
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        c.draw_series(LineSeries::new(pts, GREEN.mix(0.9).stroke_width(2)))?;
    }

    // Gate line, from the timer model's edges: min/max per pixel column, so a kHz burst shows as
    // a filled band and a 20 Hz burst as separate pulses.
    {
        let w = &r.waveform;
        let mut pts = vec![(0.0, 0.0)];
        let mut level = 0.0;
        for e in &w.edges {
            let t = w.clocks_to_s(e.t);
            pts.push((t, level));
            level = if e.high { 1.0 } else { 0.0 };
            pts.push((t, level));
        }
        pts.push((t_end, level));
        let mut c = ChartBuilder::on(&panels[3])
            .margin(10)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -0.2..1.2)?;
        c.configure_mesh()
            .y_desc("RF gate")
            .x_desc("time (s)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .y_labels(3)
            .y_label_formatter(&|y: &f64| {
                if (*y - 1.0).abs() < 0.01 {
                    "on".into()
                } else if y.abs() < 0.01 {
                    "off".into()
                } else {
                    String::new()
                }
            })
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        c.draw_series(LineSeries::new(
            decimate(&pts, 0.0, t_end, 3 * BUCKETS),
            BLACK.stroke_width(1),
        ))?;
    }
    root.present()?;
    Ok(())
}

/// A region's short label on the region panel: what its texture is, in the scene file's units
/// (f_b for constant bursts, λ for a grating, Δμ for a material, the central f_b of random draws).
fn region_label(t: &saw_core::texture::Texture) -> String {
    use saw_core::texture::Texture;
    match t {
        Texture::Constant(c) => format!("{} Hz", c.burst_millihz as f64 / 1e3),
        Texture::Grating(g) => format!("λ {} mm", g.wavelength_um as f64 / 1e3),
        Texture::Material(m) => format!("Δμ {:.2}", m.delta_mu),
        Texture::Random(r) => format!("~{} Hz", r.center_millihz as f64 / 1e3),
        _ => "off".into(),
    }
}
