//! Charts of an analysis [`Report`]: one PNG, a panel per part present, apart from the analysis
//! (which returns data and draws nothing), as statsmodels keeps its plotting apart.
//!
//! Panels, top to bottom ([`panel_rects`] gives their rectangles):
//! - per paired block, its scale: the stimuli as points on a horizontal scale-value axis,
//!   labelled, with the yardsticks (Y at 5 % and 1 %) drawn as bars of length Y above the axis,
//!   as Japanese sensory-evaluation texts draw them (two stimuli further apart than a bar
//!   differ at that level), and Thurstone's and Bradley–Terry's values on rows of their own
//!   below, each mapped onto Scheffé's axis by matching mean and standard deviation (interval
//!   scales agree up to a linear map; this one keeps their spread, a regression would shrink
//!   it), joined to the Scheffé point of the same stimulus so changes of order show;
//! - per subject and staircase block, its tracks: level against trial number, filled dots for
//!   correct answers and crosses for wrong ones, the reversals circled, the threshold dashed;
//! - per constant-stimuli block: proportion correct per level (a dot whose area grows with the
//!   trials), the fitted Weibull and logistic ψ, and each fit's level at the target proportion
//!   with its bootstrap interval as a horizontal bar at that proportion.
//!
//! Nothing in a report makes it panic: NaN and infinite values are skipped, empty parts get
//! a note in their panel, and what falls outside a plot is clipped here (plotters does not
//! clip). An empty report (nothing to draw) is an error sentence and no file is written: a
//! blank PNG would pass for a chart. At most [`MAX_PANELS`] panels are drawn (the title says
//! how many were left out), so a report of any size makes an image of bounded memory.

use std::error::Error;
use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::analysis::psychometric::Model;
use crate::analysis::report::{ConstantBlock, Correlation, PairedBlock, Report, Track};

/// The chart's width, px.
pub const WIDTH_PX: u32 = 1400;
/// The title band's height, px.
pub const TITLE_PX: u32 = 44;
/// A paired block's panel height, px.
pub const PAIRED_PX: u32 = 380;
/// A staircase panel's height (one subject's tracks in one block), px.
pub const TRACKS_PX: u32 = 320;
/// A constant-stimuli panel's height, px.
pub const CONSTANT_PX: u32 = 380;
/// Panels drawn at most: 32 of the tallest make a 1400 × 12 200 px image (51 MB of RGB while
/// it is drawn); a lab's report of dozens of subjects' tracks would otherwise grow without bound.
pub const MAX_PANELS: usize = 32;
/// Room right of every plot for its legend, px (the same on every panel, so plots line up).
const LEGEND_PX: u32 = 330;
/// Room left of every plot for the y axis and the paired panels' row names, px.
const Y_AXIS_PX: u32 = 110;

/// Colours of tracks and yardsticks, in order (repeating): matplotlib's tab10, as host-sim.
const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
    RGBColor(23, 190, 207),
];
/// Thurstone's markers.
const THURSTONE: RGBColor = RGBColor(44, 160, 44);
/// Bradley–Terry's markers.
const BRADLEY_TERRY: RGBColor = RGBColor(148, 103, 189);
/// The Weibull fit.
const WEIBULL: RGBColor = RGBColor(31, 119, 180);
/// The logistic fit.
const LOGISTIC: RGBColor = RGBColor(214, 39, 40);

/// One panel and what it draws.
enum Panel<'a> {
    /// A paired block and the correlations naming it.
    Paired(&'a PairedBlock, Vec<&'a Correlation>),
    /// One subject's tracks in one block (interleaved tracks share a panel).
    Tracks(Vec<&'a Track>),
    /// A constant-stimuli block.
    Constant(&'a ConstantBlock),
}

impl Panel<'_> {
    fn height(&self) -> u32 {
        match self {
            Panel::Paired(..) => PAIRED_PX,
            Panel::Tracks(_) => TRACKS_PX,
            Panel::Constant(_) => CONSTANT_PX,
        }
    }
}

/// Every panel the report has, in order: paired blocks, staircase groups (by subject and block,
/// in order of first appearance), constant-stimuli blocks.
fn all_panels(report: &Report) -> Vec<Panel<'_>> {
    let mut out: Vec<Panel<'_>> = Vec::new();
    for p in &report.paired {
        let corr = report
            .correlations
            .iter()
            .filter(|c| c.blocks.0 == p.block || c.blocks.1 == p.block)
            .collect();
        out.push(Panel::Paired(p, corr));
    }
    let mut groups: Vec<Vec<&Track>> = Vec::new();
    for t in &report.tracks {
        match groups
            .iter_mut()
            .find(|g| g[0].subject == t.subject && g[0].block == t.block)
        {
            Some(g) => g.push(t),
            None => groups.push(vec![t]),
        }
    }
    out.extend(groups.into_iter().map(Panel::Tracks));
    out.extend(report.constant.iter().map(Panel::Constant));
    out
}

/// The panels drawn: the first [`MAX_PANELS`].
fn panels(report: &Report) -> Vec<Panel<'_>> {
    let mut p = all_panels(report);
    p.truncate(MAX_PANELS);
    p
}

/// The chart's size in pixels: the title band and the panels drawn.
pub fn size(report: &Report) -> (u32, u32) {
    let h: u32 = panels(report).iter().map(Panel::height).sum();
    (WIDTH_PX, TITLE_PX + h)
}

/// The pixel rectangles `(x0, y0, x1, y1)` of the panels drawn, top to bottom: paired blocks,
/// staircase groups, constant-stimuli blocks. Each draws only inside its own.
pub fn panel_rects(report: &Report) -> Vec<(i32, i32, i32, i32)> {
    let mut y = TITLE_PX as i32;
    panels(report)
        .iter()
        .map(|p| {
            let r = (0, y, WIDTH_PX as i32, y + p.height() as i32);
            y = r.3;
            r
        })
        .collect()
}

/// Draws the chart of `report` into `png` (a PNG file, of [`size`]). Drawn in memory first
/// ([`pixels`]), so a chart that cannot be drawn leaves no half-written file.
pub fn draw(report: &Report, png: &Path) -> Result<(), String> {
    let is_png = png
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("png"));
    if !is_png {
        // The encoder picks the format by the extension: refuse rather than write another.
        return Err(format!(
            "the chart is a PNG, so its file name must end in .png, which \"{}\" does not",
            png.display()
        ));
    }
    let (w, h, rgb) = pixels(report)?;
    let write = || -> Result<(), Box<dyn Error>> {
        let mut b = BitMapBackend::new(png, (w, h));
        b.blit_bitmap((0, 0), (w, h), &rgb)?;
        b.present()?;
        Ok(())
    };
    write().map_err(|e| {
        format!(
            "the chart could not be written to \"{}\": {}",
            png.display(),
            one_line(&e.to_string())
        )
    })
}

/// The chart of `report` in memory: `(width, height, RGB bytes row by row)`, what [`draw`]
/// writes.
pub fn pixels(report: &Report) -> Result<(u32, u32, Vec<u8>), String> {
    if all_panels(report).is_empty() {
        return Err(
            "the report has nothing to chart: no paired block, staircase track or constant-stimuli block"
                .to_string(),
        );
    }
    let (w, h) = size(report);
    let mut rgb = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
        draw_on(report, &root)
            .and_then(|()| root.present().map_err(Into::into))
            .map_err(|e| format!("the chart could not be drawn: {}", one_line(&e.to_string())))?;
    }
    Ok((w, h, rgb))
}

/// A message on one line (an error sentence must not break the line it is printed on).
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Draws the chart on `root` (of [`size`], origin at its top-left pixel): the title, then
/// each panel in its rectangle of [`panel_rects`].
pub fn draw_on<DB: DrawingBackend>(
    report: &Report,
    root: &DrawingArea<DB, Shift>,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let all = all_panels(report).len();
    let drawn = panels(report);
    let mut title = format!(
        "analysis: {} paired block{}, {} staircase track{}, {} constant-stimuli block{}",
        report.paired.len(),
        plural(report.paired.len()),
        report.tracks.len(),
        plural(report.tracks.len()),
        report.constant.len(),
        plural(report.constant.len()),
    );
    if all > drawn.len() {
        title.push_str(&format!(
            " (the first {} of {all} panels drawn)",
            drawn.len()
        ));
    }
    root.draw(&Text::new(title, (20, 12), ("sans-serif", 22).into_font()))?;
    for (panel, r) in drawn.iter().zip(panel_rects(report)) {
        let area = root
            .clone()
            .shrink((r.0, r.1), ((r.2 - r.0) as u32, (r.3 - r.1) as u32));
        // A hairline between panels, so each reads as its own.
        root.draw(&PathElement::new(
            vec![(0, r.1), (r.2, r.1)],
            BLACK.mix(0.15).stroke_width(1),
        ))?;
        match panel {
            Panel::Paired(p, corr) => paired_panel(root, &area, p, corr)?,
            Panel::Tracks(tracks) => tracks_panel(root, &area, tracks)?,
            Panel::Constant(c) => constant_panel(root, &area, c)?,
        }
    }
    Ok(())
}

fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// A panel's plot: f64 on both axes.
type Plot<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// The axis range that shows `values` (the finite ones) with a margin: None when there are
/// none or they cannot make a range (e.g. their span overflows). A single value, or values
/// equal to the precision of an f64, get a range of their own size around them, so the
/// axis never has zero width.
fn range_of(values: impl IntoIterator<Item = f64>, margin: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.into_iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        return None;
    }
    let mid = lo / 2.0 + hi / 2.0;
    let w = hi - lo;
    // The tick labels need a span the digits of f64 can tell apart.
    let least = (mid.abs() * 1e-9).max(1e-12);
    let pad = if w < least {
        if mid == 0.0 {
            1.0
        } else {
            mid.abs() * 0.5
        }
    } else {
        w * margin
    };
    let (a, b) = (lo - pad, hi + pad);
    (a.is_finite() && b.is_finite() && b - a > 0.0 && (b - a).is_finite()).then_some((a, b))
}

/// A plot in `area` over `x` × `y`, its mesh drawn: labels on x only unless `y_desc` is
/// given, no light grid (data read against a plain background, as host-sim draws).
fn plot<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: (f64, f64),
    y: (f64, f64),
    (x_desc, x_whole): (&str, bool),
    y_desc: Option<&str>,
) -> Result<Plot<'a, DB>, Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let mut c = ChartBuilder::on(area)
        .caption(
            caption,
            ("sans-serif", 19).into_font().style(FontStyle::Bold),
        )
        .margin(10)
        .margin_right(LEGEND_PX)
        .x_label_area_size(45)
        .y_label_area_size(Y_AXIS_PX)
        .build_cartesian_2d(x.0..x.1, y.0..y.1)?;
    // Whole numbers (trials) label only whole ticks; values keep four significant digits, so a
    // huge or tiny axis does not print digits over digits.
    let whole = |v: &f64| {
        if (v - v.round()).abs() < 1e-9 {
            num(v.round())
        } else {
            String::new()
        }
    };
    // A tick a rounding error off zero (-1.11e-16) is zero.
    let near = |span: f64| {
        move |v: &f64| {
            if v.abs() < span * 1e-9 {
                num(0.0)
            } else {
                num(*v)
            }
        }
    };
    let (x_value, y_value) = (near(x.1 - x.0), near(y.1 - y.0));
    let mut mesh = c.configure_mesh();
    if x_whole {
        mesh.x_label_formatter(&whole);
    } else {
        mesh.x_label_formatter(&x_value);
    }
    mesh.y_label_formatter(&y_value);
    mesh.x_desc(x_desc)
        .axis_desc_style(("sans-serif", 17))
        .label_style(("sans-serif", 15))
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.08));
    match y_desc {
        Some(d) => {
            mesh.y_desc(d);
        }
        None => {
            mesh.disable_y_mesh().disable_y_axis();
        }
    }
    mesh.draw()?;
    Ok(c)
}

/// Whether `(x, y)` lies in the plot (and is finite).
fn inside<DB: DrawingBackend>(c: &Plot<'_, DB>, (x, y): (f64, f64)) -> bool {
    let (xr, yr) = (c.x_range(), c.y_range());
    x.is_finite() && y.is_finite() && xr.start <= x && x <= xr.end && yr.start <= y && y <= yr.end
}

/// Segment `p`–`q` cut to the plot (Liang–Barsky), in pixels; None when it misses it or is
/// not finite.
fn clip<DB: DrawingBackend>(
    c: &Plot<'_, DB>,
    p: (f64, f64),
    q: (f64, f64),
) -> Option<((i32, i32), (i32, i32))> {
    if ![p.0, p.1, q.0, q.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (xr, yr) = (c.x_range(), c.y_range());
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (pk, qk) in [
        (-dx, p.0 - xr.start),
        (dx, xr.end - p.0),
        (-dy, p.1 - yr.start),
        (dy, yr.end - p.1),
    ] {
        if pk == 0.0 {
            if qk < 0.0 {
                return None;
            }
        } else if pk < 0.0 {
            t0 = t0.max(qk / pk);
        } else {
            t1 = t1.min(qk / pk);
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| c.backend_coord(&(p.0 + t * dx, p.1 + t * dy));
    Some((at(t0), at(t1)))
}

/// Draws the polyline `pts` clipped to the plot (on `root`, in pixels), broken where a point is
/// not finite; dashed when `dash` is given (`(dash, gap)` px).
fn polyline<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    c: &Plot<'_, DB>,
    pts: &[(f64, f64)],
    style: ShapeStyle,
    dash: Option<(u32, u32)>,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let mut run: Vec<(i32, i32)> = Vec::new();
    let flush = |run: &mut Vec<(i32, i32)>| -> Result<(), Box<dyn Error>> {
        if run.len() >= 2 {
            match dash {
                None => root.draw(&PathElement::new(std::mem::take(run), style))?,
                Some((d, g)) => {
                    for dash in dashes(run, d, g) {
                        root.draw(&PathElement::new(dash, style))?;
                    }
                }
            }
        }
        run.clear();
        Ok(())
    };
    for w in pts.windows(2) {
        match clip(c, w[0], w[1]) {
            None => flush(&mut run)?,
            Some((a, b)) => {
                if run.last() != Some(&a) {
                    flush(&mut run)?;
                    run.push(a);
                }
                run.push(b);
            }
        }
    }
    flush(&mut run)
}

/// The pixel polyline `run` cut into dashes `dash` px long with gaps `gap` px between (the
/// pattern running on across its corners). Drawn on the root in pixels, as everything here, so
/// plotters' own dashed series (for chart coordinates) is not used.
fn dashes(run: &[(i32, i32)], dash: u32, gap: u32) -> Vec<Vec<(i32, i32)>> {
    let (dash, period) = (dash.max(1) as f64, (dash + gap).max(1) as f64);
    let mut out: Vec<Vec<(i32, i32)>> = Vec::new();
    // Distance along the pattern, and whether the last point ended inside a dash.
    let mut phase = 0.0f64;
    let mut open = false;
    let at = |a: (i32, i32), b: (i32, i32), t: f64| {
        (
            (a.0 as f64 + (b.0 - a.0) as f64 * t).round() as i32,
            (a.1 as f64 + (b.1 - a.1) as f64 * t).round() as i32,
        )
    };
    for w in run.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = (((b.0 - a.0) as f64).powi(2) + ((b.1 - a.1) as f64).powi(2)).sqrt();
        if len == 0.0 {
            continue;
        }
        let mut s = 0.0f64;
        while s < len {
            let in_dash = phase < dash;
            let left = if in_dash {
                dash - phase
            } else {
                period - phase
            };
            let e = (s + left).min(len);
            if in_dash {
                if !open {
                    out.push(vec![at(a, b, s / len)]);
                }
                if let Some(d) = out.last_mut() {
                    d.push(at(a, b, e / len));
                }
            }
            open = in_dash && e - s < left;
            phase = (phase + (e - s)) % period;
            s = e;
        }
    }
    out
}

/// A sample of a legend entry.
#[derive(Clone, Copy)]
enum Key {
    /// A line of this colour and width, dashed or not.
    Line(RGBAColor, u32, bool),
    /// A filled dot.
    Dot(RGBAColor),
    /// A cross.
    Cross(RGBAColor),
    /// An open ring (a reversal).
    Ring,
    /// A filled triangle.
    Triangle(RGBAColor),
    /// A filled square.
    Square(RGBAColor),
    /// Text only.
    Note,
}

/// Characters per legend line (15 px sans-serif in the legend's room).
const LEGEND_CHARS: usize = 40;

/// A panel's legend, in the room right of its plot (never over the data): each entry's sample
/// and its text, wrapped, one under the other, as far as the panel has room.
fn legend<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    entries: &[(Key, String)],
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let (ax, ay) = area.get_base_pixel();
    let (aw, ah) = area.dim_in_pixel();
    let x0 = ax + aw as i32 - LEGEND_PX as i32 + 20;
    let bottom = ay + ah as i32 - 10;
    let mut y = ay + 42;
    let font = ("sans-serif", 15).into_font();
    for (key, text) in entries {
        let lines = wrap(text, LEGEND_CHARS);
        if y + 18 * lines.len() as i32 > bottom {
            break;
        }
        let c = (x0 + 12, y + 8);
        match *key {
            Key::Line(col, w, dashed) => {
                let style = col.stroke_width(w);
                if dashed {
                    for dash in dashes(&[(x0, c.1), (x0 + 24, c.1)], 5, 3) {
                        root.draw(&PathElement::new(dash, style))?;
                    }
                } else {
                    root.draw(&PathElement::new(vec![(x0, c.1), (x0 + 24, c.1)], style))?;
                }
            }
            Key::Dot(col) => root.draw(&Circle::new(c, 4, col.filled()))?,
            Key::Cross(col) => root.draw(&Cross::new(c, 4, col.stroke_width(2)))?,
            Key::Ring => root.draw(&Circle::new(c, 8, BLACK.stroke_width(1)))?,
            Key::Triangle(col) => root.draw(&TriangleMarker::new(c, 5, col.filled()))?,
            Key::Square(col) => root.draw(&Rectangle::new(
                [(c.0 - 4, c.1 - 4), (c.0 + 4, c.1 + 4)],
                col.filled(),
            ))?,
            Key::Note => {}
        }
        let tx = if matches!(key, Key::Note) {
            x0
        } else {
            x0 + 32
        };
        for line in lines {
            root.draw(&Text::new(line, (tx, y), font.clone()))?;
            y += 18;
        }
        y += 3;
    }
    Ok(())
}

/// `s` broken at spaces into lines of at most `n` characters (a longer word is cut).
fn wrap(s: &str, n: usize) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in s.split_whitespace() {
        let mut word: String = word.to_string();
        loop {
            let len = line.chars().count();
            let wl = word.chars().count();
            if len > 0 && len + 1 + wl <= n {
                line.push(' ');
                line.push_str(&word);
                break;
            }
            if len == 0 && wl <= n {
                line = word;
                break;
            }
            if len > 0 {
                out.push(std::mem::take(&mut line));
                continue;
            }
            // A word longer than a line: cut it.
            let head: String = word.chars().take(n).collect();
            word = word.chars().skip(n).collect();
            out.push(head);
        }
    }
    if !line.is_empty() || out.is_empty() {
        out.push(line);
    }
    out
}

/// A note in the middle of a plot (why there is nothing to draw).
fn note<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    text: &str,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let (ax, ay) = area.get_base_pixel();
    let (aw, ah) = area.dim_in_pixel();
    let style = TextStyle::from(("sans-serif", 17).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Center));
    let x = ax + (aw as i32 - LEGEND_PX as i32) / 2;
    root.draw(&Text::new(text.to_string(), (x, ay + ah as i32 / 2), style))?;
    Ok(())
}

/// A number as the labels write it: four significant digits without trailing zeros, an
/// exponent only outside 0.001 to 10⁶ (so 0.41, 5, 19.33, 1e308; the ticks' 0.30000000000000004
/// is 0.3).
fn num(v: f64) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        // Not "-0".
        return "0".into();
    }
    let trim = |s: String| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    };
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        let s = format!("{v:.3e}");
        match s.split_once('e') {
            Some((m, e)) => format!("{}e{e}", trim(m.to_string())),
            None => s,
        }
    } else {
        let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        trim(format!("{v:.decimals$}"))
    }
}

/// `values` mapped onto `onto`'s mean and standard deviation over the stimuli both have
/// finite: `onto`'s mean + (v − mean) × sd(onto)/sd(values); only shifted when either
/// spread is zero or there is one stimulus; None when none is shared.
fn matched(
    values: &std::collections::BTreeMap<String, f64>,
    onto: &[(String, f64)],
) -> Option<Vec<(String, f64)>> {
    let shared: Vec<(f64, f64)> = onto
        .iter()
        .filter_map(|(k, s)| values.get(k).map(|&v| (*s, v)))
        .filter(|(s, v)| s.is_finite() && v.is_finite())
        .collect();
    if shared.is_empty() {
        return None;
    }
    let n = shared.len() as f64;
    let (ms, mv) = (
        shared.iter().map(|p| p.0).sum::<f64>() / n,
        shared.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sd = |f: &dyn Fn(&(f64, f64)) -> f64, m: f64| {
        (shared.iter().map(|p| (f(p) - m).powi(2)).sum::<f64>() / n).sqrt()
    };
    let (ss, sv) = (sd(&|p| p.0, ms), sd(&|p| p.1, mv));
    let gain = if ss > 0.0 && sv > 0.0 && (ss / sv).is_finite() {
        ss / sv
    } else {
        1.0
    };
    Some(
        values
            .iter()
            .map(|(k, &v)| (k.clone(), ms + (v - mv) * gain))
            .filter(|(_, v)| v.is_finite())
            .collect(),
    )
}

/// Rows of the paired panel, in plot units (the y axis is only rows: -3 to 4).
const ROW_SCHEFFE: f64 = 0.0;
const ROW_THURSTONE: f64 = -1.3;
const ROW_BT: f64 = -2.4;
/// The yardsticks' band: the first bar at the top, the others under it.
const ROW_YARD_TOP: f64 = 3.5;
const ROW_YARD_BOTTOM: f64 = 2.0;

/// A paired block's scale: its stimuli on a horizontal axis, labelled (staggered so labels do
/// not overlap), the yardsticks as bars of length Y above it starting at the lowest stimulus,
/// Thurstone's and Bradley–Terry's values on rows below (mapped onto Scheffé's axis, see the
/// module docs).
fn paired_panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    p: &PairedBlock,
    corr: &[&Correlation],
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let caption = format!(
        "block \"{}\": scale values ({} subject{}, {} judgment{})",
        p.block,
        p.subjects,
        plural(p.subjects),
        p.judgments,
        plural(p.judgments)
    );
    let mut points: Vec<(String, f64)> = p
        .scale
        .iter()
        .filter(|(_, v)| v.is_finite())
        .map(|(k, &v)| (k.clone(), v))
        .collect();
    points.sort_by(|a, b| a.1.total_cmp(&b.1));
    let thurstone = p.thurstone.as_ref().and_then(|t| matched(t, &points));
    let bt = p.bradley_terry.as_ref().and_then(|t| matched(t, &points));
    // Yardsticks drawable: finite, positive Y at a finite level, largest α first (the 5 %
    // bar on top, the 1 % under it).
    let mut yards: Vec<(f64, f64)> = p
        .scheffe
        .yardstick
        .iter()
        .map(|y| (y.alpha, y.y))
        .filter(|(a, y)| a.is_finite() && y.is_finite() && *y > 0.0)
        .collect();
    yards.sort_by(|a, b| b.0.total_cmp(&a.0));
    let lowest = points.first().map(|p| p.1);
    let mut xs: Vec<f64> = points.iter().map(|p| p.1).collect();
    for s in [&thurstone, &bt].into_iter().flatten() {
        xs.extend(s.iter().map(|p| p.1));
    }
    if let Some(lo) = lowest {
        xs.extend(yards.iter().map(|(_, y)| lo + y));
    }
    let Some(x) = range_of(xs, 0.06) else {
        plot(
            area,
            &caption,
            (-1.0, 1.0),
            (-3.0, 4.0),
            ("scale value (Scheffé)", false),
            None,
        )?;
        return note(root, area, "no finite scale values to draw");
    };
    let c = plot(
        area,
        &caption,
        x,
        (-3.0, 4.0),
        ("scale value (Scheffé)", false),
        None,
    )?;
    let row_font = TextStyle::from(("sans-serif", 15).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Right, VPos::Center));
    let row_name = |name: &str, row: f64| -> Result<(), Box<dyn Error>> {
        let (px, py) = c.backend_coord(&(x.0, row));
        root.draw(&Text::new(name.to_string(), (px - 8, py), row_font.clone()))?;
        Ok(())
    };
    // The secondary rows first, with thin joins to the Scheffé point of each stimulus.
    let rows = [
        (&ROW_THURSTONE, &thurstone, "Thurstone", THURSTONE),
        (&ROW_BT, &bt, "Bradley–Terry", BRADLEY_TERRY),
    ];
    for (row, values, name, col) in rows {
        let Some(values) = values else {
            continue;
        };
        row_name(name, *row)?;
        polyline(
            root,
            &c,
            &[(x.0, *row), (x.1, *row)],
            BLACK.mix(0.25).into(),
            None,
        )?;
        for (k, v) in values.iter() {
            if let Some((_, s)) = points.iter().find(|p| &p.0 == k) {
                polyline(
                    root,
                    &c,
                    &[(*s, ROW_SCHEFFE), (*v, *row)],
                    BLACK.mix(0.2).into(),
                    None,
                )?;
            }
            if inside(&c, (*v, *row)) {
                let at = c.backend_coord(&(*v, *row));
                if *row == ROW_THURSTONE {
                    root.draw(&TriangleMarker::new(at, 6, col.filled()))?;
                } else {
                    root.draw(&Rectangle::new(
                        [(at.0 - 5, at.1 - 5), (at.0 + 5, at.1 + 5)],
                        col.filled(),
                    ))?;
                }
            }
        }
    }
    // The scale itself: the axis line, the stimuli, their labels staggered in up to three rows
    // above (the next row where the previous label in it ends before this one starts).
    row_name("Scheffé", ROW_SCHEFFE)?;
    polyline(
        root,
        &c,
        &[(x.0, ROW_SCHEFFE), (x.1, ROW_SCHEFFE)],
        BLACK.stroke_width(2),
        None,
    )?;
    let label_style = TextStyle::from(("sans-serif", 15).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Center, VPos::Bottom));
    let mut row_ends: Vec<i32> = Vec::new();
    for (name, v) in &points {
        let at = c.backend_coord(&(*v, ROW_SCHEFFE));
        root.draw(&PathElement::new(
            vec![(at.0, at.1 - 6), (at.0, at.1 + 6)],
            BLACK.stroke_width(2),
        ))?;
        root.draw(&Circle::new(at, 5, BLACK.filled()))?;
        let w = root.estimate_text_size(name, &label_style)?.0 as i32;
        let left = at.0 - w / 2;
        let row = match row_ends.iter().position(|&end| end + 8 <= left) {
            Some(r) => r,
            None if row_ends.len() < 3 => {
                row_ends.push(i32::MIN);
                row_ends.len() - 1
            }
            // No free row: the one whose last label ends first.
            None => (0..row_ends.len())
                .min_by_key(|&r| row_ends[r])
                .unwrap_or(0),
        };
        row_ends[row] = left + w;
        let y = at.1 - 10 - 18 * row as i32;
        if row > 0 {
            // A leader from a raised label down to its point.
            root.draw(&PathElement::new(
                vec![(at.0, at.1 - 7), (at.0, y)],
                BLACK.mix(0.3).stroke_width(1),
            ))?;
        }
        root.draw(&Text::new(name.clone(), (at.0, y - 1), label_style.clone()))?;
    }
    // The yardsticks: bars of length Y from the lowest stimulus, end ticks, the value above.
    let mut keys: Vec<(Key, String)> =
        vec![(Key::Dot(BLACK.to_rgba()), "Scheffé's scale value".into())];
    if let Some(lo) = lowest {
        let n = yards.len();
        let step = if n > 1 {
            ((ROW_YARD_TOP - ROW_YARD_BOTTOM) / (n - 1) as f64).min(0.7)
        } else {
            0.0
        };
        let text_style = TextStyle::from(("sans-serif", 14).into_font())
            .color(&BLACK)
            .pos(Pos::new(HPos::Left, VPos::Bottom));
        for (i, (alpha, y)) in yards.iter().enumerate() {
            let row = ROW_YARD_TOP - step * i as f64;
            let col = COLOURS[i % COLOURS.len()];
            let (a, b) = ((lo, row), (lo + y, row));
            polyline(root, &c, &[a, b], col.stroke_width(4), None)?;
            for end in [a, b] {
                if inside(&c, end) {
                    let at = c.backend_coord(&end);
                    root.draw(&PathElement::new(
                        vec![(at.0, at.1 - 7), (at.0, at.1 + 7)],
                        col.stroke_width(2),
                    ))?;
                }
            }
            let label = format!("Y {} % = {}", num(alpha * 100.0), num(*y));
            if inside(&c, a) {
                let at = c.backend_coord(&a);
                root.draw(&Text::new(
                    label.clone(),
                    (at.0, at.1 - 8),
                    text_style.clone(),
                ))?;
            }
            keys.push((
                Key::Line(col.to_rgba(), 4, false),
                format!("yardstick {label}"),
            ));
        }
    }
    if yards.is_empty() {
        keys.push((Key::Note, "no yardstick".into()));
    }
    if thurstone.is_some() {
        keys.push((
            Key::Triangle(THURSTONE.to_rgba()),
            "Thurstone case V, mean and SD matched to Scheffé's".into(),
        ));
    }
    if bt.is_some() {
        keys.push((
            Key::Square(BRADLEY_TERRY.to_rgba()),
            "Bradley–Terry log-worth, mean and SD matched to Scheffé's".into(),
        ));
    }
    for k in corr {
        let other = if k.blocks.0 == p.block {
            &k.blocks.1
        } else {
            &k.blocks.0
        };
        let r = k.pearson.map_or("–".to_string(), |v| format!("{v:.3}"));
        let rho = k.spearman.map_or("–".to_string(), |v| format!("{v:.3}"));
        keys.push((Key::Note, format!("with \"{other}\": r = {r}, ρ = {rho}")));
    }
    let skipped = p.scale.len() - points.len();
    if skipped > 0 {
        keys.push((
            Key::Note,
            format!(
                "{skipped} stimul{} without a finite value not drawn",
                if skipped == 1 { "us" } else { "i" }
            ),
        ));
    }
    legend(root, area, &keys)
}

/// The trials that are reversals: `reversal_levels` located, in order, on the trials where
/// the track turns (the step after the trial opposite to the step before it; the last trial
/// may turn too, its step not being seen); if some are not found so, on any later trial at
/// that level; a level found nowhere is skipped. The report keeps the reversals' levels, not
/// their trials.
fn reversal_trials(levels: &[f64], reversal_levels: &[f64]) -> Vec<usize> {
    let same = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0);
    let n = levels.len();
    let mut turns = vec![false; n];
    let mut last = 0.0f64;
    for i in 0..n {
        let step = if i + 1 < n {
            levels[i + 1] - levels[i]
        } else {
            f64::NAN
        };
        if !step.is_finite() {
            // The last trial (or a gap): its step is unknown, so it may be a turn.
            turns[i] = true;
            continue;
        }
        if step != 0.0 {
            let dir = step.signum();
            turns[i] = last != 0.0 && dir != last;
            last = dir;
        }
    }
    let locate = |only_turns: bool| {
        let mut out = Vec::new();
        let mut from = 0;
        for &r in reversal_levels {
            if let Some(i) = (from..n).find(|&i| (!only_turns || turns[i]) && same(levels[i], r)) {
                out.push(i);
                from = i + 1;
            }
        }
        out
    };
    let on_turns = locate(true);
    if on_turns.len() == reversal_levels.len() {
        on_turns
    } else {
        locate(false)
    }
}

/// One subject's staircase tracks in one block: level against trial number (within its track),
/// each track in its colour; dots correct, crosses wrong, rings reversals, the threshold
/// dashed.
fn tracks_panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    tracks: &[&Track],
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let first = tracks[0];
    let caption = format!(
        "subject \"{}\", block \"{}\": staircase{}",
        first.subject,
        first.block,
        if tracks.len() > 1 { "s" } else { "" }
    );
    let trials = tracks.iter().map(|t| t.levels.len()).max().unwrap_or(0);
    let x = (0.5, trials.max(1) as f64 + 0.5);
    let ys = tracks
        .iter()
        .flat_map(|t| t.levels.iter().copied().chain(t.threshold));
    let Some(y) = range_of(ys, 0.08) else {
        plot(
            area,
            &caption,
            x,
            (0.0, 1.0),
            ("trial (within its track)", true),
            Some("level"),
        )?;
        return note(root, area, "no trials with a finite level to draw");
    };
    let c = plot(
        area,
        &caption,
        x,
        y,
        ("trial (within its track)", true),
        Some("level"),
    )?;
    let mut keys: Vec<(Key, String)> = Vec::new();
    for (i, t) in tracks.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = t
            .levels
            .iter()
            .enumerate()
            .map(|(j, &l)| ((j + 1) as f64, l))
            .collect();
        polyline(root, &c, &pts, col.mix(0.6).stroke_width(1), None)?;
        if let Some(th) = t.threshold {
            polyline(
                root,
                &c,
                &[(x.0, th), (x.1, th)],
                col.stroke_width(2),
                Some((8, 5)),
            )?;
        }
        for (j, &p) in pts.iter().enumerate() {
            if !inside(&c, p) {
                continue;
            }
            let at = c.backend_coord(&p);
            match t.correct.get(j) {
                Some(true) => root.draw(&Circle::new(at, 4, col.filled()))?,
                Some(false) => root.draw(&Cross::new(at, 4, col.stroke_width(2)))?,
                // An answer missing (a shorter list): the level alone, open.
                None => root.draw(&Circle::new(at, 3, col.stroke_width(1)))?,
            }
        }
        for j in reversal_trials(&t.levels, &t.reversal_levels) {
            if inside(&c, pts[j]) {
                root.draw(&Circle::new(
                    c.backend_coord(&pts[j]),
                    9,
                    BLACK.stroke_width(1),
                ))?;
            }
        }
        let threshold = match t.threshold {
            Some(v) if v.is_finite() => format!(
                "threshold {} (last {} reversals)",
                num(v),
                t.threshold_reversals
            ),
            Some(v) => format!("threshold {v} (not drawn)"),
            None => format!(
                "no threshold ({} of {} reversals)",
                t.reversal_levels.len(),
                t.threshold_reversals
            ),
        };
        keys.push((
            Key::Line(col.to_rgba(), 2, true),
            format!(
                "track \"{}\": {} trials, {threshold}",
                t.track,
                t.levels.len()
            ),
        ));
    }
    keys.push((Key::Dot(BLACK.to_rgba()), "correct".into()));
    keys.push((Key::Cross(BLACK.to_rgba()), "wrong".into()));
    keys.push((Key::Ring, "reversal".into()));
    legend(root, area, &keys)
}

/// A constant-stimuli block: proportion correct per level (dot area by trials), the fits' ψ,
/// and each fit's level at its target with the bootstrap interval as a bar at the target.
fn constant_panel<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    area: &DrawingArea<DB, Shift>,
    b: &ConstantBlock,
) -> Result<(), Box<dyn Error>>
where
    DB::ErrorType: 'static,
{
    let caption = format!("block \"{}\": constant stimuli", b.block);
    // Levels with trials and a finite proportion.
    let pts: Vec<(f64, f64, u32)> = b
        .points
        .iter()
        .filter(|p| p.n_trials > 0 && p.level.is_finite())
        .map(|p| (p.level, p.n_correct as f64 / p.n_trials as f64, p.n_trials))
        .collect();
    let fits: Vec<_> = b
        .fits
        .iter()
        .filter_map(|f| f.result.as_ref().ok().map(|ci| (f.model, ci)))
        .collect();
    // The x axis spans the levels, and the fits' thresholds and intervals where these are
    // within a span of them (a degenerate fit's interval can run off to any length: it is
    // clipped, not allowed to squeeze the data into a corner).
    let base = range_of(pts.iter().map(|p| p.0), 0.0);
    let mut xs: Vec<f64> = pts.iter().map(|p| p.0).collect();
    for (_, ci) in &fits {
        let mut extra: Vec<f64> = ci.fit.level_at_target.into_iter().collect();
        if let Some(i) = ci.level_at_target {
            extra.extend([i.lower, i.upper]);
        }
        xs.extend(extra.into_iter().filter(|v| match base {
            Some((lo, hi)) => (lo - (hi - lo)..=hi + (hi - lo)).contains(v),
            None => true,
        }));
    }
    let Some(x) = range_of(xs, 0.05) else {
        plot(
            area,
            &caption,
            (0.0, 1.0),
            (0.0, 1.05),
            ("level", false),
            Some("proportion correct"),
        )?;
        return note(root, area, "no level with trials to draw");
    };
    // Proportions from 0 (or from just under the lowest seen or the guess rate, which for a
    // forced choice keeps the plot on the range that matters) to 1.
    let low = pts
        .iter()
        .map(|p| p.1)
        .chain(fits.iter().map(|(_, ci)| ci.fit.guess))
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::min);
    let y0 = ((low - 0.05) * 10.0).floor().clamp(0.0, 9.0) / 10.0;
    let c = plot(
        area,
        &caption,
        x,
        (y0, 1.04),
        ("level", false),
        Some("proportion correct"),
    )?;
    let mut keys: Vec<(Key, String)> = Vec::new();
    // The fitted ψ over the axis, 400 samples.
    for (model, ci) in &fits {
        let col = model_colour(*model);
        let curve: Vec<(f64, f64)> = (0..=400)
            .map(|i| {
                let l = x.0 + (x.1 - x.0) * i as f64 / 400.0;
                (l, ci.fit.psi(l))
            })
            .collect();
        polyline(root, &c, &curve, col.stroke_width(2), None)?;
    }
    // The points over the curves, dot area proportional to trials (radius 3 to 12 px).
    let most = pts.iter().map(|p| p.2).max().unwrap_or(1).max(1) as f64;
    for &(l, p, n) in &pts {
        if inside(&c, (l, p)) {
            let at = c.backend_coord(&(l, p));
            let r = (3.0 + 9.0 * (n as f64 / most).sqrt()).round() as i32;
            root.draw(&Circle::new(at, r, BLACK.mix(0.35).filled()))?;
            root.draw(&Circle::new(at, r, BLACK.stroke_width(1)))?;
        }
    }
    keys.push((
        Key::Dot(BLACK.mix(0.35)),
        format!("proportion correct (dot area by trials, at most {most})"),
    ));
    // Threshold bars: at the target proportion, the second fit a little lower so both show.
    for (i, (model, ci)) in fits.iter().enumerate() {
        let col = model_colour(*model);
        let row = ci.fit.target - 0.025 * i as f64;
        if let Some(iv) = ci.level_at_target {
            let (a, bb) = ((iv.lower, row), (iv.upper, row));
            polyline(root, &c, &[a, bb], col.stroke_width(3), None)?;
            for end in [a, bb] {
                if inside(&c, end) {
                    let at = c.backend_coord(&end);
                    root.draw(&PathElement::new(
                        vec![(at.0, at.1 - 6), (at.0, at.1 + 6)],
                        col.stroke_width(2),
                    ))?;
                }
            }
        }
        if let Some(t) = ci.fit.level_at_target {
            if inside(&c, (t, row)) {
                let at = c.backend_coord(&(t, row));
                root.draw(&Rectangle::new(
                    [(at.0 - 4, at.1 - 4), (at.0 + 4, at.1 + 4)],
                    col.filled(),
                ))?;
            }
        }
    }
    for f in &b.fits {
        let name = model_name(f.model);
        match &f.result {
            Ok(ci) => {
                let fit = &ci.fit;
                let at = match (fit.level_at_target, ci.level_at_target) {
                    (Some(t), Some(iv)) => format!(
                        "; {} % at {} [{}, {}] ({} % CI)",
                        num(fit.target * 100.0),
                        num(t),
                        num(iv.lower),
                        num(iv.upper),
                        num(ci.confidence * 100.0)
                    ),
                    (Some(t), None) => format!("; {} % at {}", num(fit.target * 100.0), num(t)),
                    _ => String::new(),
                };
                let degenerate = if fit.degenerate { " (degenerate)" } else { "" };
                keys.push((
                    Key::Line(model_colour(f.model).to_rgba(), 2, false),
                    format!(
                        "{name}: α = {}, β = {}{at}{degenerate}",
                        num(fit.alpha),
                        num(fit.beta)
                    ),
                ));
            }
            Err(why) => keys.push((Key::Note, format!("{name}: no fit ({})", one_line(why)))),
        }
    }
    legend(root, area, &keys)
}

fn model_colour(m: Model) -> RGBColor {
    match m {
        Model::Weibull => WEIBULL,
        Model::Logistic => LOGISTIC,
    }
}

fn model_name(m: Model) -> &'static str {
    match m {
        Model::Weibull => "Weibull",
        Model::Logistic => "logistic",
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::staircase::{Staircase, StaircaseSpec, StepScale};

    /// The reversals located from the levels alone are the trials the staircase flagged, over
    /// many seeded tracks (clamped at both ends, steps shrinking) — the report keeps only the
    /// levels, so the rings are only right if this is.
    #[test]
    fn reversals_are_located_on_the_trials_the_staircase_flagged() {
        for seed in 0..200u64 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mut s = Staircase::new(StaircaseSpec {
                name: "t".into(),
                start: 20.0,
                down: 1 + (seed % 3) as u32,
                up: 1,
                steps: vec![8.0, 4.0, 2.0],
                scale: StepScale::Linear,
                min: 0.0,
                max: 40.0,
                max_trials: Some(60),
                max_reversals: None,
                threshold_reversals: 4,
            })
            .expect("a valid spec");
            for _ in 0..60 {
                let p = 0.3 + 0.02 * s.level();
                s.respond(rng.random::<f64>() < p);
            }
            let levels: Vec<f64> = s.trials().iter().map(|t| t.level).collect();
            let flagged: Vec<usize> = (0..levels.len())
                .filter(|&i| s.trials()[i].reversal)
                .collect();
            assert_eq!(
                reversal_trials(&levels, &s.reversal_levels()),
                flagged,
                "seed {seed}"
            );
        }
    }

    #[test]
    fn reversal_levels_not_on_the_track_are_not_located() {
        assert!(reversal_trials(&[1.0, 2.0, 1.0], &[5.0]).is_empty());
        // A level found nowhere is skipped, the others still located.
        assert_eq!(reversal_trials(&[1.0, 2.0, 1.0], &[2.0, 5.0]), vec![1]);
        assert!(reversal_trials(&[], &[1.0]).is_empty());
        assert_eq!(
            reversal_trials(&[1.0, f64::NAN, 1.0], &[1.0, 1.0]),
            vec![0, 2]
        );
    }

    #[test]
    fn dashes_alternate_along_the_line() {
        let d = dashes(&[(0, 0), (20, 0)], 5, 3);
        assert_eq!(
            d,
            vec![
                vec![(0, 0), (5, 0)],
                vec![(8, 0), (13, 0)],
                vec![(16, 0), (20, 0)]
            ]
        );
        // The pattern runs on across a corner: one dash bends round it.
        let d = dashes(&[(0, 0), (3, 0), (3, 4)], 5, 3);
        assert_eq!(d[0], vec![(0, 0), (3, 0), (3, 2)]);
        assert!(dashes(&[(1, 1)], 5, 3).is_empty());
    }

    #[test]
    fn ranges_are_finite_and_wide() {
        assert_eq!(range_of([f64::NAN], 0.1), None);
        assert_eq!(range_of([], 0.1), None);
        assert_eq!(range_of([0.0], 0.1), Some((-1.0, 1.0)));
        assert_eq!(range_of([f64::MAX, -f64::MAX], 0.1), None);
        let (a, b) = range_of([1e20, 1e20], 0.1).unwrap();
        assert!(a < 1e20 && b > 1e20);
        let (a, b) = range_of([1.0, 3.0, f64::INFINITY], 0.1).unwrap();
        assert!((a - 0.8).abs() < 1e-12 && (b - 3.2).abs() < 1e-12);
    }

    #[test]
    fn numbers_are_short() {
        assert_eq!(num(0.05 * 100.0), "5");
        assert_eq!(num(0.41), "0.41");
        assert_eq!(num(19.333333), "19.33");
        assert_eq!(num(-0.0), "0");
        assert_eq!(num(0.30000000000000004), "0.3");
        assert_eq!(num(1e308), "1e308");
        assert_eq!(num(-1.5e-7), "-1.5e-7");
        assert_eq!(num(123456.0), "123456");
        assert_eq!(num(f64::NAN), "NaN");
    }

    #[test]
    fn wrapped_lines_fit() {
        assert_eq!(wrap("a bb ccc", 4), vec!["a bb", "ccc"]);
        assert_eq!(wrap("abcdefghij", 4), vec!["abcd", "efgh", "ij"]);
        assert_eq!(wrap("", 4), vec![""]);
    }
}
