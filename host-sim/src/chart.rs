//! PNG chart of a run: stacked panels over time — position, velocity, region, gate line and the
//! RF drive the finger gets (enable × level); with lines, a last panel of every line pulse's
//! drive against the finger's distance from its line (the triangle and where it peaks).

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::sim::{SimResult, TracePoint};
use crate::timer::{Edge, LevelEdge};

/// Points per trace after decimation (min/max per bucket, so spikes survive).
const BUCKETS: usize = 1_500;

/// Min/max decimation of `(t, y)` points (sorted by t) into `buckets` buckets over `[t0, t1]`,
/// over the whole series at once: the reference [`Decimator`] is tested against.
#[cfg(test)]
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

/// (t s, value) points.
type Series = Vec<(f64, f64)>;

/// A bucket's lowest point and when it arrived, and its highest and when (arrival u64::MAX:
/// none yet).
type Extremes = ((f64, f64), u64, (f64, f64), u64);

/// Min/max decimation done as the points arrive: the points themselves while there are at most
/// `2 × buckets` of them, then per bucket of `[t0, t1]` its lowest and highest point (in the
/// order they came), so a run of any length is drawn from bounded memory, spikes kept — the
/// same points [`decimate`] gives for the whole series.
#[derive(Clone, Debug, PartialEq)]
pub struct Decimator {
    t0: f64,
    /// Buckets per second.
    per_s: f64,
    buckets: usize,
    raw: Option<Series>,
    /// Per bucket: (lowest, its arrival, highest, its arrival); empty buckets have no arrival.
    minmax: Vec<Extremes>,
    arrivals: u64,
}

impl Decimator {
    /// A decimator into `buckets` buckets over `[t0, t1]`.
    pub fn new(t0: f64, t1: f64, buckets: usize) -> Self {
        Self {
            t0,
            per_s: buckets.max(1) as f64 / (t1 - t0),
            buckets: buckets.max(1),
            raw: Some(Vec::new()),
            minmax: Vec::new(),
            arrivals: 0,
        }
    }

    /// The bucket time `t_s` falls in.
    #[inline]
    pub fn bucket_of(&self, t_s: f64) -> usize {
        (((t_s - self.t0) * self.per_s).max(0.0) as usize).min(self.buckets - 1)
    }

    /// The next point (in time order), whose bucket the caller computed with
    /// [`Self::bucket_of`] (series sampled at the same times share it).
    #[inline]
    pub fn push_in(&mut self, bucket: usize, p: (f64, f64)) {
        if self.raw.is_some() {
            return self.push(p);
        }
        self.bucket_at(bucket, p);
    }

    /// The next point (in time order).
    pub fn push(&mut self, p: (f64, f64)) {
        if let Some(raw) = &mut self.raw {
            raw.push(p);
            if raw.len() <= 2 * self.buckets {
                return;
            }
            let raw = self.raw.take().unwrap_or_default();
            self.minmax =
                vec![((0.0, f64::MAX), u64::MAX, (0.0, f64::MIN), u64::MAX); self.buckets];
            for q in raw {
                self.bucket(q);
            }
            return;
        }
        self.bucket(p);
    }

    fn bucket(&mut self, p: (f64, f64)) {
        self.bucket_at(self.bucket_of(p.0), p);
    }

    #[inline]
    fn bucket_at(&mut self, b: usize, p: (f64, f64)) {
        self.arrivals += 1;
        let slot = &mut self.minmax[b];
        if p.1 < slot.0 .1 {
            slot.0 = p;
            slot.1 = self.arrivals;
        }
        if p.1 > slot.2 .1 {
            slot.2 = p;
            slot.3 = self.arrivals;
        }
    }

    /// The decimated points.
    pub fn points(&self) -> Series {
        if let Some(raw) = &self.raw {
            return raw.clone();
        }
        let mut out = Vec::with_capacity(2 * self.buckets);
        for &(lo, lo_at, hi, hi_at) in &self.minmax {
            if lo_at == u64::MAX {
                continue;
            }
            if (lo.0, lo_at) <= (hi.0, hi_at) {
                out.extend([lo, hi]);
            } else {
                out.extend([hi, lo]);
            }
        }
        out
    }
}

/// A quantity the core may not have (None during a fault), decimated in runs broken where it is
/// missing: one [`Decimator`] per run while the runs are few, then one for all with the breaks
/// kept at bucket resolution.
#[derive(Clone, Debug, PartialEq)]
pub struct GappyDecimator {
    t0: f64,
    t1: f64,
    buckets: usize,
    runs: Vec<Decimator>,
    open: bool,
}

/// Runs kept apart before a gappy series is merged into one decimator with breaks.
const RUNS_KEPT: usize = 64;

impl GappyDecimator {
    /// A decimator into `buckets` buckets over `[t0, t1]`.
    pub fn new(t0: f64, t1: f64, buckets: usize) -> Self {
        Self {
            t0,
            t1,
            buckets,
            runs: Vec::new(),
            open: false,
        }
    }

    /// The next point, in `bucket` (see [`Decimator::push_in`]).
    #[inline]
    pub fn push_in(&mut self, bucket: usize, t: f64, y: Option<f64>) {
        match (y, self.open) {
            (Some(y), true) => {
                if let Some(run) = self.runs.last_mut() {
                    run.push_in(bucket, (t, y));
                }
            }
            _ => self.push(t, y),
        }
    }

    /// The next point.
    pub fn push(&mut self, t: f64, y: Option<f64>) {
        match y {
            None => self.open = false,
            Some(y) => {
                if !self.open && self.runs.len() < RUNS_KEPT {
                    self.runs
                        .push(Decimator::new(self.t0, self.t1, self.buckets));
                }
                self.open = true;
                if let Some(run) = self.runs.last_mut() {
                    run.push((t, y));
                }
            }
        }
    }

    /// The decimated runs.
    pub fn runs(&self) -> Vec<Series> {
        self.runs
            .iter()
            .map(Decimator::points)
            .filter(|r| !r.is_empty())
            .collect()
    }
}

/// Accumulates [`dense_duty`]'s figures from a step curve fed point by point.
#[derive(Clone, Debug, PartialEq)]
struct DutyBins {
    t_end: f64,
    width: f64,
    on: Vec<f64>,
    rises: Vec<u32>,
    last: Option<(f64, f64)>,
}

impl DutyBins {
    fn new(t_end: f64, bins: usize) -> Self {
        Self {
            t_end,
            width: t_end / bins as f64,
            on: vec![0.0; bins],
            rises: vec![0; bins],
            last: None,
        }
    }

    fn slice(&self, t: f64) -> usize {
        ((t.max(0.0) / self.width) as usize).min(self.on.len() - 1)
    }

    fn push(&mut self, p: (f64, f64)) {
        let Some((t0, level)) = self.last.replace(p) else {
            return;
        };
        let (t1, next) = p;
        if level < 0.5 && next > 0.5 && t1 == t0 {
            let k = self.slice(t0);
            self.rises[k] += 1;
        }
        if level < 0.5 || t1 <= t0 {
            return;
        }
        // Spread [t0, t1) over the slices it overlaps.
        let (a, b) = (t0.max(0.0), t1.min(self.t_end));
        for k in self.slice(a)..=self.slice(b) {
            let (lo, hi) = (k as f64 * self.width, (k + 1) as f64 * self.width);
            self.on[k] += (b.min(hi) - a.max(lo)).max(0.0);
        }
    }

    fn runs(&self) -> Vec<Series> {
        let mut runs: Vec<Series> = Vec::new();
        let mut open = false;
        for k in 0..self.on.len() {
            if self.rises[k] >= 2 {
                if !open {
                    runs.push(Vec::new());
                    open = true;
                }
                if let Some(run) = runs.last_mut() {
                    run.push(((k as f64 + 0.5) * self.width, self.on[k] / self.width));
                }
            } else {
                open = false;
            }
        }
        runs
    }
}

/// Line pulses drawn on the line panel (the first ones; the legend gives the total).
pub const LINE_PULSES_DRAWN: usize = 100;

/// Everything the chart draws, in memory bounded by the chart's width, not the run's length:
/// fed point by point and edge by edge by [`Recorder`].
#[derive(Clone, Debug, PartialEq)]
pub struct ChartData {
    t_end: f64,
    length_mm: f64,
    boundaries_mm: Vec<f64>,
    lines_mm: Vec<f64>,
    region_labels: Vec<String>,
    pos_truth: Decimator,
    pos_core: GappyDecimator,
    vel_truth: Decimator,
    vel_core: GappyDecimator,
    vel_max_mm_s: f64,
    region: Decimator,
    gate: Decimator,
    duty: DutyBins,
    drive: Decimator,
    line_curves: Vec<Series>,
    line_pulses: usize,
}

/// Builds a [`ChartData`] as a run goes: [`Recorder::point`] per trace point,
/// [`Recorder::edges`] with the timer model's edges and DAC changes (in time order).
#[derive(Clone, Debug)]
pub struct Recorder {
    data: ChartData,
    clock_hz: f64,
    trajectory: crate::trajectory::Trajectory,
    last_region: Option<f64>,
    gate_high: bool,
    code: u16,
    drive_last: f64,
    /// The line pulse being drawn: (finger position at each step µm, drive) while the gate is
    /// high, with the rise's time.
    pulse: Option<(u64, Vec<(f64, f64)>)>,
}

impl Recorder {
    /// A recorder for a run of `params` on a burst timer clocked at `clock_hz`.
    pub fn new(params: &crate::sim::SimParams, clock_hz: u32) -> Self {
        let t_end = params.duration_s;
        let scene = &params.config.scene;
        let mut gate = Decimator::new(0.0, t_end, 3 * BUCKETS);
        gate.push((0.0, 0.0));
        let mut duty = DutyBins::new(t_end, BUCKETS);
        duty.push((0.0, 0.0));
        let mut drive = Decimator::new(0.0, t_end, 3 * BUCKETS);
        drive.push((0.0, 0.0));
        Self {
            data: ChartData {
                t_end,
                length_mm: params.config.calibration.length_um as f64 / 1e3,
                boundaries_mm: scene
                    .boundaries_um
                    .iter()
                    .map(|&b| b as f64 / 1e3)
                    .collect(),
                lines_mm: scene
                    .lines
                    .positions_um
                    .iter()
                    .map(|&l| l as f64 / 1e3)
                    .collect(),
                region_labels: scene.textures.iter().map(region_label).collect(),
                pos_truth: Decimator::new(0.0, t_end, BUCKETS),
                pos_core: GappyDecimator::new(0.0, t_end, BUCKETS),
                vel_truth: Decimator::new(0.0, t_end, BUCKETS),
                vel_core: GappyDecimator::new(0.0, t_end, BUCKETS),
                vel_max_mm_s: 10.0,
                region: Decimator::new(0.0, t_end, BUCKETS),
                gate,
                duty,
                drive,
                line_curves: Vec::new(),
                line_pulses: 0,
            },
            clock_hz: clock_hz as f64,
            trajectory: params.trajectory.clone(),
            last_region: None,
            gate_high: false,
            code: 0,
            drive_last: 0.0,
            pulse: None,
        }
    }

    /// The next trace point.
    pub fn point(&mut self, p: &TracePoint) {
        let d = &mut self.data;
        let t = p.t_us as f64 * 1e-6;
        // The four series share the sample's time, so its bucket is worked out once.
        let b = d.pos_truth.bucket_of(t);
        d.pos_truth.push_in(b, (t, p.true_um / 1e3));
        d.pos_core.push_in(b, t, p.meas_um.map(|m| m as f64 / 1e3));
        let v = p.true_vel_um_s / 1e3;
        d.vel_truth.push_in(b, (t, v));
        let est = p.est_vel_um_s.map(|v| v as f64 / 1e3);
        d.vel_core.push_in(b, t, est);
        d.vel_max_mm_s = d.vel_max_mm_s.max(v.abs()).max(est.unwrap_or(0.0).abs());
        // Region (−1 = none: fault or no scene) as a step curve.
        let y = p.region.map(|x| x as f64).unwrap_or(-1.0);
        if self.last_region != Some(y) {
            if let Some(l) = self.last_region {
                d.region.push((t, l));
            }
            d.region.push((t, y));
            self.last_region = Some(y);
        }
    }

    /// The enable line's edges and the DAC's changes up to some time, each in time order and
    /// after those fed before.
    pub fn edges(&mut self, edges: &[Edge], levels: &[LevelEdge]) {
        let (mut i, mut j) = (0, 0);
        while i < edges.len() || j < levels.len() {
            let t = match (edges.get(i), levels.get(j)) {
                (Some(e), Some(l)) => e.t.min(l.t),
                (Some(e), None) => e.t,
                (None, Some(l)) => l.t,
                (None, None) => break,
            };
            let was_high = self.gate_high;
            while let Some(e) = edges.get(i).filter(|e| e.t == t) {
                self.gate_high = e.high;
                i += 1;
            }
            let mut code_changed = false;
            while let Some(l) = levels.get(j).filter(|l| l.t == t) {
                code_changed |= self.code != l.code;
                self.code = l.code;
                j += 1;
            }
            self.at(t, was_high, code_changed);
        }
    }

    /// The curves' points at kernel-clock time `t`, after every change at `t`.
    fn at(&mut self, t: u64, was_high: bool, code_changed: bool) {
        let x = t as f64 / self.clock_hz;
        let d = &mut self.data;
        let (before, after) = (
            f64::from(u8::from(was_high)),
            f64::from(u8::from(self.gate_high)),
        );
        if before != after {
            d.gate.push((x, before));
            d.gate.push((x, after));
            d.duty.push((x, before));
            d.duty.push((x, after));
        }
        let level = crate::rf::permille_at_code(self.code) / 1000.0;
        let y = if self.gate_high { level } else { 0.0 };
        d.drive.push((x, self.drive_last));
        d.drive.push((x, y));
        self.drive_last = y;
        if d.lines_mm.is_empty() {
            return;
        }
        let at_um = self.trajectory.state(x).position_um;
        match (was_high, self.gate_high) {
            (false, true) => self.pulse = Some((t, vec![(at_um, 0.0), (at_um, level)])),
            (true, true) if code_changed => {
                if let Some((_, c)) = &mut self.pulse {
                    let last = c.last().map_or(0.0, |q| q.1);
                    c.extend([(at_um, last), (at_um, level)]);
                }
            }
            (true, false) => {
                if let Some((rise, mut c)) = self.pulse.take() {
                    let last = c.last().map_or(0.0, |q| q.1);
                    c.extend([(at_um, last), (at_um, 0.0)]);
                    d.line_pulses += 1;
                    if d.line_curves.len() < LINE_PULSES_DRAWN {
                        // Against the line nearest the finger at the pulse's middle.
                        let mid = (rise + t) as f64 / 2.0 / self.clock_hz;
                        let mid_um = self.trajectory.state(mid).position_um;
                        if let Some(&line_mm) = d.lines_mm.iter().min_by(|a, b| {
                            (**a * 1e3 - mid_um)
                                .abs()
                                .total_cmp(&(**b * 1e3 - mid_um).abs())
                        }) {
                            let mut curve: Series = c
                                .into_iter()
                                .map(|(um, y)| ((um / 1e3 - line_mm), y))
                                .collect();
                            curve.shrink_to_fit();
                            d.line_curves.push(curve);
                        }
                    }
                }
            }
            _ => {}
        }
    }

    /// The chart's data, the curves closed at the run's end.
    pub fn finish(mut self) -> ChartData {
        let d = &mut self.data;
        let t_end = d.t_end;
        if let Some(l) = self.last_region {
            d.region.push((t_end, l));
        }
        let g = f64::from(u8::from(self.gate_high));
        d.gate.push((t_end, g));
        d.duty.push((t_end, g));
        d.drive.push((t_end, self.drive_last));
        self.data
    }
}

impl ChartData {
    /// The chart's data of a recorded run.
    pub fn of(r: &SimResult) -> Self {
        let mut rec = Recorder::new(&r.params, r.timer.clock_hz);
        for p in &r.trace {
            rec.point(p);
        }
        rec.edges(&r.waveform.edges, &r.waveform.levels);
        rec.finish()
    }

    /// Heap the data holds, bytes: bounded by the chart's buckets and [`LINE_PULSES_DRAWN`],
    /// whatever the run's length.
    pub fn heap_bytes(&self) -> usize {
        let series = |d: &Decimator| {
            d.raw.as_ref().map_or(0, |r| r.capacity() * 16) + d.minmax.capacity() * 48
        };
        let gappy = |g: &GappyDecimator| {
            g.runs.capacity() * std::mem::size_of::<Decimator>()
                + g.runs.iter().map(series).sum::<usize>()
        };
        series(&self.pos_truth)
            + series(&self.vel_truth)
            + series(&self.region)
            + series(&self.gate)
            + series(&self.drive)
            + gappy(&self.pos_core)
            + gappy(&self.vel_core)
            + self.duty.on.capacity() * 12
            + self
                .line_curves
                .iter()
                .map(|c| c.capacity() * 16)
                .sum::<usize>()
    }

    /// Line pulses in the run (the panel draws the first [`LINE_PULSES_DRAWN`]).
    pub fn line_pulses(&self) -> usize {
        self.line_pulses
    }
}

/// Draws what the core saw (red, thin, in runs broken by faults) over the truth (pale blue,
/// wide), both already decimated to the panel's width by the [`Recorder`], and the legend
/// beside the plot: `(runs, label, line width)` and `(truth, line width)`.
fn core_against_truth<'a, DB: DrawingBackend + 'a>(
    c: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    (core, label, core_width): (&[Vec<(f64, f64)>], &str, u32),
    (truth, truth_width): (&[(f64, f64)], u32),
) -> Result<Vec<Entry>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    // The truth first, wide and pale, so the core's thin line stays visible on top of it.
    c.draw_series(LineSeries::new(
        truth.iter().copied(),
        BLUE.mix(0.35).stroke_width(truth_width),
    ))?;
    for run in core {
        c.draw_series(LineSeries::new(
            run.iter().copied(),
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

/// Writes the chart of a run (its [`ChartData`]) to `path` (PNG).
pub fn write_png(
    d: &ChartData,
    path: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let with_lines = !d.lines_mm.is_empty();
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
    let t_end = d.t_end;
    let label_font = ("sans-serif", 18);

    // Position.
    {
        let (tp, meas) = (d.pos_truth.points(), d.pos_core.runs());
        let len_mm = d.length_mm;
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
        for &b in &d.boundaries_mm {
            c.draw_series(DashedLineSeries::new(
                vec![(0.0, b), (t_end, b)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?;
            legend.push((format!("boundary {b:.3} mm"), BLACK.mix(0.5), 1));
        }
        for (i, &l) in d.lines_mm.iter().enumerate() {
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
        )?);
        side_legend(&panels[0], &legend)?;
    }

    // Velocity.
    {
        let (tv, est) = (d.vel_truth.points(), d.vel_core.runs());
        let vmax = d.vel_max_mm_s * 1.15;
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
        let legend = core_against_truth(&mut c, (&est, "estimated (core)", 1), (&tv, 5))?;
        side_legend(&panels[1], &legend)?;
    }

    // Region (−1 = none: fault or no scene).
    {
        let n = d.region_labels.len() as f64;
        let pts = d.region.points();
        let mut c = ChartBuilder::on(&panels[2])
            .margin(10)
            .margin_right(LEGEND_PX)
            .x_label_area_size(30)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..t_end, -1.5..n - 0.5)?;
        let labels = &d.region_labels;
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
        let pts = d.gate.points();
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
        c.draw_series(LineSeries::new(pts, BLACK.stroke_width(1)))?;
        // Where bursts are denser than pixels the line is a solid band: there the share of
        // each pixel column's time it was on is drawn over it (the duty, and where it drops).
        let orange = RGBColor(230, 120, 0);
        for run in d.duty.runs() {
            c.draw_series(LineSeries::new(run, orange.stroke_width(2)))?;
        }
        // The drive the finger gets: enable × the RF level (the reference circuit's amplitude
        // for the DAC code), as a share of full drive.
        let blue = RGBColor(30, 90, 220);
        c.draw_series(LineSeries::new(
            d.drive.points(),
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
        line_envelopes(d, &panels[4])?;
    }
    root.present()?;
    Ok(())
}

/// Every line pulse's drive against the finger's true distance from the line it was fired
/// for (the nearest one at the pulse's middle), mm: the envelope the finger feels, overlaid.
fn line_envelopes<DB: DrawingBackend>(
    d: &ChartData,
    area: &DrawingArea<DB, plotters::coord::Shift>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let curves = &d.line_curves;
    let reach = curves
        .iter()
        .flatten()
        .fold(0.1f64, |m, q| m.max(q.0.abs()));
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
    for curve in curves {
        c.draw_series(LineSeries::new(
            curve.clone(),
            blue.mix(0.5).stroke_width(1),
        ))?;
    }
    side_legend(
        area,
        &[
            (format!("{} line pulses,", d.line_pulses), blue.mix(0.5), 1),
            (
                if d.line_pulses > curves.len() {
                    format!("  the first {} overlaid", curves.len())
                } else {
                    "  overlaid".into()
                },
                WHITE.to_rgba(),
                0,
            ),
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
#[cfg(test)]
fn dense_duty(pts: &[(f64, f64)], t_end: f64, bins: usize) -> Vec<Vec<(f64, f64)>> {
    let mut d = DutyBins::new(t_end, bins);
    for &p in pts {
        d.push(p);
    }
    d.runs()
}

#[cfg(test)]
mod duty_tests {
    use super::{decimate, dense_duty, Decimator};

    /// The decimator fed point by point gives the points the whole-series decimation gives: a
    /// noisy series with spikes, long enough to turn to buckets, and a short one kept raw.
    #[test]
    fn decimator_matches_the_whole_series_decimation() {
        for n in [500usize, 20_000] {
            let pts: Vec<(f64, f64)> = (0..n)
                .map(|i| {
                    let t = i as f64 / n as f64 * 3.0;
                    let spike = if i % 997 == 0 { 50.0 } else { 0.0 };
                    (t, (t * 7.0).sin() + ((i * 7919) % 13) as f64 * 0.01 + spike)
                })
                .collect();
            let mut d = Decimator::new(0.0, 3.0, 300);
            for &p in &pts {
                d.push(p);
            }
            assert_eq!(d.points(), decimate(&pts, 0.0, 3.0, 300), "{n} points");
        }
    }

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
