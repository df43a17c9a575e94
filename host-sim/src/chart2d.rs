//! The 2D run's chart (issue #36): the scene as a map (windows filled and numbered, edges drawn
//! thick), the true finger's path coloured by the burst frequency f_b playing there (grey where
//! the carrier is off or pulsing), each edge pulse marked where it fired and each window switch
//! where it happened, each ridge pulse of a grating a small triangle.

use std::path::Path;

use plotters::prelude::*;
use saw_core::plane::Config2d;

use crate::sim2d::{scene_edges, Run2d};

/// Pixels.
const SIZE: (u32, u32) = (1400, 900);

/// Where f_b lies on the scale over `lo..=hi`, 0 to 1, logarithmic: the felt bands are ratios
/// (bumpy under 30 Hz, rough to 100 Hz, smooth above 1 kHz: the seed paper), and on a linear
/// scale to 1 kHz a scene's 20 and 80 Hz windows came out the same blue.
fn fb_scale(fb: f64, lo: f64, hi: f64) -> f64 {
    if hi > lo && lo > 0.0 && fb > 0.0 {
        ((fb / lo).ln() / (hi / lo).ln()).clamp(0.0, 1.0)
    } else {
        0.5
    }
}

/// A colour for f_b on a blue (low) → red (high) logarithmic scale over `lo..=hi`.
fn fb_colour(fb: f64, lo: f64, hi: f64) -> RGBColor {
    let u = fb_scale(fb, lo, hi);
    let c = HSLColor(0.66 * (1.0 - u), 0.9, 0.45).to_rgba();
    RGBColor(c.0, c.1, c.2)
}

/// Writes the chart of `run` over `config`'s scene to `path` (PNG).
pub fn write_png(
    config: &Config2d,
    run: &Run2d,
    path: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let (w, h) = run.plate_mm;
    // Show the plate and anything of the scene or path beyond it.
    let (mut x0, mut x1, mut y0, mut y1) = (0.0f64, w, 0.0f64, h);
    let mut grow = |x: f64, y: f64| {
        if x.is_finite() && y.is_finite() {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
    };
    for win in &config.scene.windows {
        for v in &win.outline.vertices {
            grow(v.x_um as f64 / 1e3, v.y_um as f64 / 1e3);
        }
    }
    for p in &run.trace {
        grow(p.x_mm, p.y_mm);
    }
    let pad = 2.0;
    let fbs: Vec<f64> = run.trace.iter().filter_map(|p| p.fb_hz).collect();
    let lo = fbs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = fbs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (main, legend) = root.split_horizontally(SIZE.0 - 260);
    let mut chart = ChartBuilder::on(&main)
        .caption(title, ("sans-serif", 18).into_font())
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d((x0 - pad)..(x1 + pad), (y0 - pad)..(y1 + pad))?;
    chart
        .configure_mesh()
        .x_desc("x, mm")
        .y_desc("y, mm")
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    // The plate.
    chart.draw_series(std::iter::once(Rectangle::new(
        [(0.0, 0.0), (w, h)],
        BLACK.mix(0.4).stroke_width(1),
    )))?;
    // Windows, topmost drawn last.
    let fills = [
        RGBColor(255, 224, 178),
        RGBColor(200, 230, 201),
        RGBColor(225, 225, 240),
        RGBColor(225, 225, 240),
        RGBColor(248, 215, 230),
        RGBColor(215, 235, 250),
        RGBColor(240, 240, 200),
        RGBColor(220, 220, 220),
    ];
    for (i, win) in config.scene.windows.iter().enumerate().rev() {
        let pts: Vec<(f64, f64)> = win
            .outline
            .vertices
            .iter()
            .map(|v| (v.x_um as f64 / 1e3, v.y_um as f64 / 1e3))
            .collect();
        chart.draw_series(std::iter::once(Polygon::new(
            pts.clone(),
            fills[i % fills.len()].filled(),
        )))?;
        let mut closed = pts.clone();
        closed.extend(pts.first().copied());
        chart.draw_series(std::iter::once(PathElement::new(
            closed,
            BLACK.mix(0.3).stroke_width(1),
        )))?;
        let (cx, top) = (
            pts.iter().map(|p| p.0).sum::<f64>() / pts.len().max(1) as f64,
            pts.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max),
        );
        chart.draw_series(std::iter::once(Text::new(
            format!("window {i}"),
            (cx - 3.0, top - 1.5),
            ("sans-serif", 15).into_font(),
        )))?;
    }
    // Edges.
    for (i, e) in scene_edges(&config.scene).iter().enumerate() {
        chart.draw_series(std::iter::once(PathElement::new(
            vec![e.a, e.b],
            RGBColor(90, 60, 20).stroke_width(4),
        )))?;
        if e.window.is_none() {
            chart.draw_series(std::iter::once(Text::new(
                format!("edge {i}"),
                (e.b.0 + 0.5, e.b.1),
                ("sans-serif", 14).into_font(),
            )))?;
        }
    }
    // The path, a segment per frame, coloured by f_b.
    for pair in run.trace.windows(2) {
        let (a, b) = (pair[0], pair[1]);
        if !b.touching {
            continue;
        }
        let style = match b.fb_hz {
            Some(fb) => fb_colour(fb, lo, hi).stroke_width(3),
            None => RGBColor(120, 120, 120).stroke_width(2),
        };
        chart.draw_series(std::iter::once(PathElement::new(
            vec![(a.x_mm, a.y_mm), (b.x_mm, b.y_mm)],
            style,
        )))?;
    }
    let ridge = RGBColor(120, 0, 160);
    chart.draw_series(
        run.trace
            .iter()
            .filter(|p| p.ridge_pulse)
            .map(|p| TriangleMarker::new((p.x_mm, p.y_mm), 5, ridge.filled())),
    )?;
    chart.draw_series(
        run.window_switches
            .iter()
            .map(|s| Circle::new((s.x_mm, s.y_mm), 6, RGBColor(0, 100, 0).stroke_width(2))),
    )?;
    chart.draw_series(
        run.edge_pulses
            .iter()
            .map(|p| Cross::new((p.x_mm, p.y_mm), 8, RED.stroke_width(3))),
    )?;
    // Legend: the f_b scale and the marks.
    let font = ("sans-serif", 16).into_font();
    legend.draw(&Text::new("f_b of the burst", (20, 60), font.clone()))?;
    if fbs.is_empty() {
        legend.draw(&Text::new("(no burst ran)", (20, 85), font.clone()))?;
    } else {
        for k in 0..=20 {
            let u = k as f64 / 20.0;
            let fb = lo * (hi / lo).powf(u);
            let y = 380 - (u * 280.0) as i32;
            legend.draw(&Rectangle::new(
                [(20, y - 14), (50, y)],
                fb_colour(fb, lo, hi).filled(),
            ))?;
        }
        legend.draw(&Text::new(format!("{hi:.1} Hz"), (60, 95), font.clone()))?;
        legend.draw(&Text::new(format!("{lo:.1} Hz"), (60, 370), font.clone()))?;
        legend.draw(&Text::new("(log scale)", (60, 395), font.clone()))?;
    }
    legend.draw(&PathElement::new(
        vec![(20, 430), (50, 430)],
        RGBColor(120, 120, 120).stroke_width(2),
    ))?;
    legend.draw(&Text::new("off or pulse", (60, 422), font.clone()))?;
    legend.draw(&Cross::new((35, 470), 8, RED.stroke_width(3)))?;
    legend.draw(&Text::new(
        format!("edge pulse ({})", run.edge_pulses.len()),
        (60, 462),
        font.clone(),
    ))?;
    legend.draw(&Circle::new(
        (35, 510),
        6,
        RGBColor(0, 100, 0).stroke_width(2),
    ))?;
    legend.draw(&Text::new(
        format!("window switch ({})", run.window_switches.len()),
        (60, 502),
        font.clone(),
    ))?;
    legend.draw(&TriangleMarker::new((35, 590), 5, ridge.filled()))?;
    legend.draw(&Text::new(
        format!(
            "ridge pulse ({})",
            run.trace.iter().filter(|p| p.ridge_pulse).count()
        ),
        (60, 582),
        font.clone(),
    ))?;
    legend.draw(&PathElement::new(
        vec![(20, 550), (50, 550)],
        RGBColor(90, 60, 20).stroke_width(4),
    ))?;
    legend.draw(&Text::new("edge", (60, 542), font))?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::fb_scale;

    /// fig. 12's 20 and 80 Hz windows under a 1 kHz background sit apart on the scale: 80 Hz
    /// is a third of the way up (ln 4 / ln 50 = 0.354), not 6 % as on a linear one.
    #[test]
    fn the_f_b_scale_is_logarithmic() {
        assert_eq!(fb_scale(20.0, 20.0, 1000.0), 0.0);
        assert!((fb_scale(1000.0, 20.0, 1000.0) - 1.0).abs() < 1e-12);
        assert!((fb_scale(80.0, 20.0, 1000.0) - 0.354).abs() < 0.001);
        assert_eq!(fb_scale(80.0, 80.0, 80.0), 0.5);
    }
}
