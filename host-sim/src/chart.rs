//! PNG chart of a run: stacked panels over time — position, velocity, region, gate line and the
//! RF drive the finger gets (enable × level); with lines, a last panel of every line pulse's
//! drive against the finger's distance from its line (the triangle and where it peaks).

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

/// Draws what the core saw (red, thin, in runs broken by faults) over the truth (pale blue,
/// wide), decimated to the panel's width, and the legend beside the plot: `(runs, label, line
/// width)` and `(truth, line width)`.
fn core_against_truth<'a, DB: DrawingBackend + 'a>(
    c: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    (core, label, core_width): (&[Vec<(f64, f64)>], &str, u32),
    (truth, truth_width): (&[(f64, f64)], u32),
    t_end: f64,
) -> Result<Vec<Entry>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    // The truth first, wide and pale, so the core's thin line stays visible on top of it.
    c.draw_series(LineSeries::new(
        decimate(truth, 0.0, t_end, BUCKETS),
        BLUE.mix(0.35).stroke_width(truth_width),
    ))?;
    for run in core {
        c.draw_series(LineSeries::new(
            decimate(run, 0.0, t_end, BUCKETS),
            RED.stroke_width(core_width),
        ))?;
    }
    Ok(vec![
        ("true".into(), BLUE.mix(0.35), truth_width),
        (label.into(), RED.to_rgba(), core_width.max(2)),
    ])
}

/// Room right of every panel's plot for its legend, px (the same on every panel, so the time
/// axes line up).
const LEGEND_PX: u32 = 230;

/// One entry of a panel's legend: its label and the colour and width of its line.
type Entry = (String, RGBAColor, u32);

/// A panel's legend, in the room right of its plot, never over the data: a short line in each
/// entry's style and its label, one under the other.
fn side_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[Entry],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let x0 = area.dim_in_pixel().0 as i32 - LEGEND_PX as i32 + 10;
    for (i, (label, color, width)) in entries.iter().enumerate() {
        let y = 20 + 22 * i as i32;
        area.draw(&PathElement::new(
            vec![(x0, y), (x0 + 24, y)],
            color.stroke_width(*width),
        ))?;
        area.draw(&Text::new(
            label.clone(),
            (x0 + 32, y - 8),
            ("sans-serif", 15).into_font(),
        ))?;
    }
    Ok(())
}

pub fn write_png(
    r: &SimResult,
    path: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let lines = &r.params.config.scene.lines;
    let with_lines = !lines.positions_um.is_empty();
    let height = if with_lines { 1520 } else { 1200 };
    let root = BitMapBackend::new(path, (1600, height)).into_drawing_area();
    root.fill(&WHITE)?;
    let (header, body) = root.split_vertically(40);
    header.draw(&Text::new(
        title.to_string(),
        (20, 10),
        ("sans-serif", 22).into_font(),
    ))?;
    let panels = if with_lines {
        body.split_by_breakpoints::<i32, i32, _, _>([], [330, 660, 860, 1160])
    } else {
        body.split_by_breakpoints::<i32, i32, _, _>([], [330, 660, 860])
    };
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
            .margin_right(LEGEND_PX)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -1.0..len_mm + 1.0)?;
        c.configure_mesh()
            .y_desc("position (mm)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        let mut legend: Vec<Entry> = Vec::new();
        for &b in r.params.config.scene.boundaries_um.iter() {
            let b = b as f64 / 1e3;
            c.draw_series(DashedLineSeries::new(
                vec![(0.0, b), (t_end, b)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?;
            legend.push((format!("boundary {b:.3} mm"), BLACK.mix(0.5), 1));
        }
        for (i, &l) in r.params.config.scene.lines.positions_um.iter().enumerate() {
            let l = l as f64 / 1e3;
            c.draw_series(DashedLineSeries::new(
                vec![(0.0, l), (t_end, l)],
                2,
                3,
                MAGENTA.mix(0.7).stroke_width(1),
            ))?;
            if i == 0 {
                legend.push(("tangible line".into(), MAGENTA.mix(0.7), 1));
            }
        }
        legend.extend(core_against_truth(
            &mut c,
            (&meas, "measured", 1),
            (&tp, 5),
            t_end,
        )?);
        side_legend(&panels[0], &legend)?;
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
            .margin_right(LEGEND_PX)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -vmax..vmax)?;
        c.configure_mesh()
            .y_desc("velocity (mm/s)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        let legend = core_against_truth(&mut c, (&est, "estimated (core)", 1), (&tv, 5), t_end)?;
        side_legend(&panels[1], &legend)?;
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
            .margin_right(LEGEND_PX)
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
            .margin_right(LEGEND_PX)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -0.2..1.2)?;
        c.configure_mesh()
            .y_desc("RF gate, drive")
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
        // Where bursts are denser than pixels the line is a solid band: there the share of
        // each pixel column's time it was on is drawn over it (the duty, and where it drops).
        let orange = RGBColor(230, 120, 0);
        for run in dense_duty(&pts, t_end, BUCKETS) {
            c.draw_series(LineSeries::new(run, orange.stroke_width(2)))?;
        }
        // The drive the finger gets: enable × the RF level (the reference circuit's amplitude
        // for the DAC code), as a share of full drive.
        let drive = drive_steps(w, t_end);
        let blue = RGBColor(30, 90, 220);
        c.draw_series(LineSeries::new(
            decimate(&drive, 0.0, t_end, 3 * BUCKETS),
            blue.mix(0.8).stroke_width(1),
        ))?;
        side_legend(
            &panels[3],
            &[
                ("gate line".into(), BLACK.to_rgba(), 1),
                ("RF drive (enable × level)".into(), blue.mix(0.8), 1),
                ("on-time share where".into(), orange.to_rgba(), 2),
                ("  bursts are denser".into(), WHITE.to_rgba(), 0),
                ("  than pixels".into(), WHITE.to_rgba(), 0),
            ],
        )?;
    }

    if with_lines {
        line_envelopes(r, &panels[4])?;
    }
    root.present()?;
    Ok(())
}

/// The drive (enable × level, share of full drive) as a step curve over `[0, t_end]`.
fn drive_steps(w: &crate::timer::Waveform, t_end: f64) -> Vec<(f64, f64)> {
    let mut times: Vec<u64> = w
        .edges
        .iter()
        .map(|e| e.t)
        .chain(w.levels.iter().map(|l| l.t))
        .collect();
    times.sort_unstable();
    times.dedup();
    let mut pts = vec![(0.0, 0.0)];
    let mut last = 0.0;
    for t in times {
        let x = w.clocks_to_s(t);
        let y = w.drive_at(t) / 1000.0;
        pts.push((x, last));
        pts.push((x, y));
        last = y;
    }
    pts.push((t_end, last));
    pts
}

/// Every line pulse's drive against the finger's true distance from the line it was fired
/// for (the nearest one at the pulse's middle), mm: the envelope the finger feels, overlaid.
fn line_envelopes<DB: DrawingBackend>(
    r: &SimResult,
    area: &DrawingArea<DB, plotters::coord::Shift>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let w = &r.waveform;
    let lines = &r.params.config.scene.lines;
    let mut curves: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut reach = 0.1f64;
    for p in w.pulses() {
        let mid = w.clocks_to_s((p.rise + p.fall) / 2);
        let at = r.params.trajectory.state(mid).position_um;
        let Some(&line) = lines
            .positions_um
            .iter()
            .min_by(|a, b| (**a as f64 - at).abs().total_cmp(&(**b as f64 - at).abs()))
        else {
            continue;
        };
        let x =
            |t: u64| (r.params.trajectory.state(w.clocks_to_s(t)).position_um - line as f64) / 1e3;
        let mut c = vec![(x(p.rise), 0.0)];
        let mut last = 0.0;
        for e in w.codes_within(p.rise, p.fall) {
            let y = crate::rf::permille_at_code(e.code) / 1000.0;
            c.push((x(e.t), last));
            c.push((x(e.t), y));
            last = y;
        }
        c.push((x(p.fall), last));
        c.push((x(p.fall), 0.0));
        reach = c.iter().fold(reach, |m, q| m.max(q.0.abs()));
        curves.push(c);
    }
    let reach = reach * 1.1;
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .margin_right(LEGEND_PX)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(-reach..reach, 0.0..1.1)?;
    c.configure_mesh()
        .y_desc("line pulse drive")
        .x_desc("finger's distance from the line (mm)")
        .axis_desc_style(("sans-serif", 18))
        .label_style(("sans-serif", 15))
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    c.draw_series(DashedLineSeries::new(
        vec![(0.0, 0.0), (0.0, 1.1)],
        2,
        3,
        MAGENTA.mix(0.7).stroke_width(1),
    ))?;
    let blue = RGBColor(30, 90, 220);
    for curve in &curves {
        c.draw_series(LineSeries::new(
            curve.clone(),
            blue.mix(0.5).stroke_width(1),
        ))?;
    }
    side_legend(
        area,
        &[
            (format!("{} line pulses,", curves.len()), blue.mix(0.5), 1),
            ("  overlaid".into(), WHITE.to_rgba(), 0),
            ("the line".into(), MAGENTA.mix(0.7), 1),
        ],
    )?;
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

/// The share of each of `bins` equal slices of 0..`t_end` that the step curve `pts` (t, 0 or 1,
/// a value holding until the next point) spent at 1, at each slice's middle, in runs of slices
/// with at least two rising edges (where the line is denser than the slices).
fn dense_duty(pts: &[(f64, f64)], t_end: f64, bins: usize) -> Vec<Vec<(f64, f64)>> {
    let width = t_end / bins as f64;
    let slice = |t: f64| ((t.max(0.0) / width) as usize).min(bins - 1);
    let mut on = vec![0.0f64; bins];
    let mut rises = vec![0u32; bins];
    for w in pts.windows(2) {
        let ((t0, level), (t1, next)) = (w[0], w[1]);
        if level < 0.5 && next > 0.5 && t1 == t0 {
            rises[slice(t0)] += 1;
        }
        if level < 0.5 || t1 <= t0 {
            continue;
        }
        // Spread [t0, t1) over the slices it overlaps.
        let (a, b) = (t0.max(0.0), t1.min(t_end));
        for (k, share) in on.iter_mut().enumerate().take(slice(b) + 1).skip(slice(a)) {
            let (lo, hi) = (k as f64 * width, (k + 1) as f64 * width);
            *share += (b.min(hi) - a.max(lo)).max(0.0);
        }
    }
    let mut runs: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut open = false;
    for k in 0..bins {
        if rises[k] >= 2 {
            if !open {
                runs.push(Vec::new());
                open = true;
            }
            let run = runs.last_mut().expect("a run was opened");
            run.push(((k as f64 + 0.5) * width, on[k] / width));
        } else {
            open = false;
        }
    }
    runs
}

#[cfg(test)]
mod duty_tests {
    use super::dense_duty;

    /// A step curve of `hz` bursts at 40 % duty over 1 s, as the gate panel builds it.
    fn square(hz: f64) -> Vec<(f64, f64)> {
        let mut pts = vec![(0.0, 0.0)];
        let period = 1.0 / hz;
        let mut t = 0.0;
        while t + period <= 1.0 + 1e-12 {
            pts.extend([
                (t, 0.0),
                (t, 1.0),
                (t + 0.4 * period, 1.0),
                (t + 0.4 * period, 0.0),
            ]);
            t += period;
        }
        pts.push((1.0, 0.0));
        pts
    }

    /// 1 kHz bursts (ten per 10 ms slice) read as one run at 0.4 everywhere; 20 Hz bursts (one
    /// per 50 ms, wider than a slice) draw no duty at all: there the line itself is readable.
    #[test]
    fn duty_only_where_bursts_are_denser_than_slices() {
        let runs = dense_duty(&square(1000.0), 1.0, 100);
        assert_eq!(runs.len(), 1);
        assert_eq!(runs[0].len(), 100);
        assert!(
            runs[0].iter().all(|&(_, d)| (d - 0.4).abs() < 1e-6),
            "{runs:?}"
        );
        assert!(dense_duty(&square(20.0), 1.0, 100).is_empty());
    }
}
