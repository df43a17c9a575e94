//! Charts of the bench (plotters, PNG): error against delay, against cost, against speed.

use std::ops::Range;
use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::methods::Family;

/// One method as a point.
#[derive(Clone, Debug)]
pub struct Point {
    /// Method name.
    pub name: String,
    /// Family (colour).
    pub family: Family,
    /// x value.
    pub x: f64,
    /// y value.
    pub y: f64,
}

fn colour(f: Family) -> RGBColor {
    match f {
        Family::Difference => RGBColor(120, 120, 120),
        Family::Lsq => RGBColor(31, 119, 180),
        Family::Foaw => RGBColor(214, 39, 40),
        Family::AlphaBeta => RGBColor(44, 160, 44),
        Family::SuperTwisting => RGBColor(148, 103, 189),
        Family::Median => RGBColor(255, 127, 14),
    }
}

/// Indices of the points no other point beats on both axes (lower is better on both).
pub fn pareto(points: &[Point]) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let p = &points[i];
            !points
                .iter()
                .any(|q| q.x <= p.x && q.y <= p.y && (q.x < p.x || q.y < p.y))
        })
        .collect()
}

fn range(vals: impl Iterator<Item = f64> + Clone) -> (f64, f64) {
    let lo = vals.clone().fold(f64::INFINITY, f64::min);
    let hi = vals.fold(f64::NEG_INFINITY, f64::max);
    (lo, hi)
}

/// Scatter on log–log axes with every point labelled and the Pareto front drawn.
pub fn scatter(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    points: &[Point],
) -> Result<(), String> {
    let pts: Vec<Point> = points
        .iter()
        .filter(|p| p.x > 0.0 && p.y > 0.0 && p.x.is_finite() && p.y.is_finite())
        .cloned()
        .collect();
    let (x0, x1) = range(pts.iter().map(|p| p.x));
    let (y0, y1) = range(pts.iter().map(|p| p.y));
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    let axes = (x_label, y_label, x0 / 1.5..x1 * 1.5, y0 / 1.5..y1 * 1.5);
    let mut chart = log_log_panel(&root, title, axes)?;
    let front = pareto(&pts);
    let mut line: Vec<(f64, f64)> = front.iter().map(|&i| (pts[i].x, pts[i].y)).collect();
    line.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))
        .map_err(|e| e.to_string())?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    for (i, p) in pts.iter().enumerate() {
        let c = colour(p.family);
        let on_front = front.contains(&i);
        let r = if on_front { 7 } else { 5 };
        chart
            .draw_series(std::iter::once(Circle::new((p.x, p.y), r, c.filled())))
            .map_err(|e| e.to_string())?;
        let label = if on_front {
            format!("{} *", p.name)
        } else {
            p.name.clone()
        };
        chart
            .draw_series(std::iter::once(Text::new(
                label,
                (p.x * 1.04, p.y * 1.03),
                ("sans-serif", 14).into_font().color(&c),
            )))
            .map_err(|e| e.to_string())?;
    }
    // plotters' default place for the legend.
    finish(chart, &root, SeriesLabelPosition::MiddleRight)
}

/// A log–log chart on both axes.
type LogLog<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>;

/// Clears `root` to white and sets up the bench's log–log panel: caption, margins, and the mesh
/// with `(x label, y label, x range, y range)`.
fn log_log_panel<'a, 'b>(
    root: &'a DrawingArea<BitMapBackend<'b>, Shift>,
    title: &str,
    (x_label, y_label, x, y): (&str, &str, Range<f64>, Range<f64>),
) -> Result<LogLog<'a, 'b>, String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(root)
        .caption(title, ("sans-serif", 24))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(70)
        .build_cartesian_2d(x.log_scale(), y.log_scale())
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(chart)
}

/// Draws the legend of `chart` at `position` in the bench's box and writes `root`'s PNG.
fn finish<'a, 'b: 'a>(
    mut chart: LogLog<'a, 'b>,
    root: &DrawingArea<BitMapBackend<'b>, Shift>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

/// One curve.
#[derive(Clone, Debug)]
pub struct Curve {
    /// Method name.
    pub name: String,
    /// Family (colour).
    pub family: Family,
    /// (x, y) points.
    pub points: Vec<(f64, f64)>,
}

/// Curves on log–log axes.
pub fn curves(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    curves: &[Curve],
) -> Result<(), String> {
    let all = curves
        .iter()
        .flat_map(|c| c.points.iter().copied())
        .filter(|(x, y)| *x > 0.0 && *y > 0.0);
    let (x0, x1) = range(all.clone().map(|p| p.0));
    let (y0, y1) = range(all.map(|p| p.1));
    let root = BitMapBackend::new(path, (1200, 800)).into_drawing_area();
    let axes = (x_label, y_label, x0 / 1.2..x1 * 1.2, y0 / 1.5..y1 * 1.5);
    let mut chart = log_log_panel(&root, title, axes)?;
    for (i, c) in curves.iter().enumerate() {
        let base = colour(c.family);
        // Members of a family get different line widths so they stay apart.
        let style = base.stroke_width(1 + (i % 3) as u32);
        let pts: Vec<(f64, f64)> = c
            .points
            .iter()
            .copied()
            .filter(|(x, y)| *x > 0.0 && *y > 0.0)
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), style))
            .map_err(|e| e.to_string())?
            .label(c.name.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
        chart
            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, base.filled())))
            .map_err(|e| e.to_string())?;
    }
    finish(chart, &root, SeriesLabelPosition::UpperLeft)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let p = |x, y| Point {
            name: String::new(),
            family: Family::Lsq,
            x,
            y,
        };
        let pts = [
            p(1.0, 5.0),
            p(2.0, 2.0),
            p(3.0, 3.0),
            p(4.0, 1.0),
            p(2.0, 2.5),
        ];
        assert_eq!(pareto(&pts), vec![0, 1, 3]);
    }
}
