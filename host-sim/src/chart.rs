//! PNG chart of a run: stacked panels over time — position, velocity, region, gate line and the
//! RF drive the finger gets (enable × level); with lines, a last panel of every line pulse's
//! drive against the finger's distance from its line (the triangle and where it peaks).
//!
//! A run longer than [`LONG_RUN_S`] would crowd hundreds of strokes into each pixel column (the
//! traces alias into moiré), so its chart draws those panels over its last [`DETAIL_S`] only,
//! and under them the run minute by minute ([`crate::metrics::Minute`], computed by the
//! metrics): f_b produced per region and the lines' pulse rate, how far past their boundary the
//! switches came, the velocity error, the time under fault. Every trace is clipped to its plot
//! and wide lines are drawn without miter joins, so nothing lands outside its panel.

use std::path::Path;

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

use crate::metrics::{Metrics, Minute};
use crate::sim::{CoreOut, SimResult, TracePoint};
use crate::timer::{Edge, LevelEdge};
use crate::trajectory::State;

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

/// Accumulates [`dense_duty`]'s figures from a step curve fed point by point, over `t0..t_end`.
#[derive(Clone, Debug, PartialEq)]
struct DutyBins {
    t0: f64,
    t_end: f64,
    width: f64,
    on: Vec<f64>,
    rises: Vec<u32>,
    last: Option<(f64, f64)>,
}

impl DutyBins {
    fn new(t0: f64, t_end: f64, bins: usize) -> Self {
        Self {
            t0,
            t_end,
            width: (t_end - t0) / bins as f64,
            on: vec![0.0; bins],
            rises: vec![0; bins],
            last: None,
        }
    }

    fn slice(&self, t: f64) -> usize {
        (((t - self.t0).max(0.0) / self.width) as usize).min(self.on.len() - 1)
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
        let (a, b) = (t0.max(self.t0), t1.min(self.t_end));
        for k in self.slice(a)..=self.slice(b) {
            let lo = self.t0 + k as f64 * self.width;
            let hi = lo + self.width;
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
                    run.push((
                        self.t0 + (k as f64 + 0.5) * self.width,
                        self.on[k] / self.width,
                    ));
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

/// Runs longer than this, s, get the long chart: the last [`DETAIL_S`] in detail and the run
/// minute by minute. A minute of 60 mm/s strokes is 60 of them over the time axis, still
/// readable; five minutes alias.
pub const LONG_RUN_S: f64 = 60.0;

/// The long chart's detail: its last seconds, as many as the default run's whole chart shows.
pub const DETAIL_S: f64 = 3.0;

/// Everything the chart draws, in memory bounded by the chart's width, not the run's length:
/// fed point by point and edge by edge by [`Recorder`].
#[derive(Clone, Debug, PartialEq)]
pub struct ChartData {
    /// Where the time panels start: 0, or the detail's start for a long run.
    t0: f64,
    t_end: f64,
    /// A long run's chart (detail and per-minute panels).
    long: bool,
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
    /// The first sample time, µs, at or after the time panels' start (`t0`): earlier points
    /// only keep their region (`before`). Compared as an integer, not as the f64 seconds
    /// whose conversion was most of a point's cost before a long run's detail.
    detail_from_us: u64,
    /// The region of the last point before the detail (None before any), turned into
    /// `last_region` when the detail starts.
    before: Option<Option<u8>>,
    gate_high: bool,
    code: u16,
    /// The RF level of a DAC code, 0 … 1, with the code it is for: the code changes seldom,
    /// and the level takes a power (every edge asked for it).
    level_of: Option<(u16, f64)>,
    drive_last: f64,
    /// The line pulse being drawn: (finger position at each step µm, drive) while the gate is
    /// high, with the rise's time.
    pulse: Option<(u64, Vec<(f64, f64)>)>,
    /// Whether the gate, duty and drive curves have their point at the time panels' start.
    opened: bool,
    /// Whether the region curve has its first point.
    region_opened: bool,
}

impl Recorder {
    /// A recorder for a run of `params` on a burst timer clocked at `clock_hz`.
    pub fn new(params: &crate::sim::SimParams, clock_hz: u32) -> Self {
        let t_end = params.duration_s;
        let long = t_end > LONG_RUN_S;
        let t0 = if long { t_end - DETAIL_S } else { 0.0 };
        let scene = &params.config.scene;
        Self {
            data: ChartData {
                t0,
                t_end,
                long,
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
                pos_truth: Decimator::new(t0, t_end, BUCKETS),
                pos_core: GappyDecimator::new(t0, t_end, BUCKETS),
                vel_truth: Decimator::new(t0, t_end, BUCKETS),
                vel_core: GappyDecimator::new(t0, t_end, BUCKETS),
                vel_max_mm_s: 10.0,
                region: Decimator::new(t0, t_end, BUCKETS),
                gate: Decimator::new(t0, t_end, 3 * BUCKETS),
                duty: DutyBins::new(t0, t_end, BUCKETS),
                drive: Decimator::new(t0, t_end, 3 * BUCKETS),
                line_curves: Vec::new(),
                line_pulses: 0,
            },
            clock_hz: clock_hz as f64,
            trajectory: params.trajectory.clone(),
            last_region: None,
            detail_from_us: first_us_from(t0),
            before: None,
            gate_high: false,
            code: 0,
            level_of: None,
            drive_last: 0.0,
            pulse: None,
            opened: false,
            region_opened: false,
        }
    }

    /// The gate, duty and drive curves' first point, at the time panels' start: the line as it
    /// stood then (`gate_high`).
    fn open(&mut self, gate_high: bool) {
        if self.opened {
            return;
        }
        self.opened = true;
        let d = &mut self.data;
        let g = f64::from(u8::from(gate_high));
        d.gate.push((d.t0, g));
        d.duty.push((d.t0, g));
        d.drive.push((d.t0, self.drive_last));
    }

    /// The next trace point.
    pub fn point(&mut self, p: &TracePoint) {
        self.period(p.t_us, p.region, &p.state(), &p.core_out());
    }

    /// The next sample period, given as its parts: [`Self::point`] of the trace point with
    /// time `t_us`, the finger at `state` and the core's `out`, whose region is `region` (as a
    /// value: read back from `out` just after the loop stored it byte by byte, it waited for
    /// those stores).
    #[inline]
    pub fn period(&mut self, t_us: u64, region: Option<u8>, state: &State, out: &CoreOut) {
        if t_us < self.detail_from_us {
            // Before a long run's detail only the region the curve starts from is kept.
            self.before = Some(region);
            return;
        }
        self.region_before();
        let d = &mut self.data;
        let t = t_us as f64 * 1e-6;
        // Region (−1 = none: fault or no scene) as a step curve.
        let y = region_y(region);
        if !self.region_opened {
            // A long run's detail starts with the region it was in.
            self.region_opened = true;
            if let Some(l) = self.last_region {
                d.region.push((d.t0, l));
            }
        }
        // The four series share the sample's time, so its bucket is worked out once.
        let b = d.pos_truth.bucket_of(t);
        d.pos_truth.push_in(b, (t, state.position_um / 1e3));
        d.pos_core
            .push_in(b, t, out.meas_um.map(|m| m as f64 / 1e3));
        let v = state.velocity_um_s / 1e3;
        d.vel_truth.push_in(b, (t, v));
        let est = out.est_vel_um_s.map(|v| v as f64 / 1e3);
        d.vel_core.push_in(b, t, est);
        d.vel_max_mm_s = d.vel_max_mm_s.max(v.abs()).max(est.unwrap_or(0.0).abs());
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
        let level = match self.level_of {
            Some((code, level)) if code == self.code => level,
            _ => {
                let level = crate::rf::permille_at_code(self.code) / 1000.0;
                self.level_of = Some((self.code, level));
                level
            }
        };
        let y = if self.gate_high { level } else { 0.0 };
        if x >= self.data.t0 {
            self.open(was_high);
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
            d.drive.push((x, self.drive_last));
            d.drive.push((x, y));
        }
        self.drive_last = y;
        let d = &mut self.data;
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

    /// The region curve's value of the last point before the detail (if it has not been
    /// worked out yet): what the detail's first point, or the run's end, starts it from.
    fn region_before(&mut self) {
        if let Some(r) = self.before.take() {
            self.last_region = Some(region_y(r));
        }
    }

    /// The chart's data, the curves closed at the run's end.
    pub fn finish(mut self) -> ChartData {
        self.region_before();
        self.open(self.gate_high);
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

/// The region curve's value of a point's region: its index, −1 for none (fault or no scene).
fn region_y(region: Option<u8>) -> f64 {
    region.map(|x| x as f64).unwrap_or(-1.0)
}

/// The first sample time, µs, whose time in seconds (`t_us as f64 * 1e-6`, as the curves take
/// it) is not before `t0_s`: the conversion never decreases as t_us grows, so the times
/// before `t0_s` are exactly those below it.
fn first_us_from(t0_s: f64) -> u64 {
    let before = |t_us: u64| (t_us as f64 * 1e-6) < t0_s;
    let mut t_us = (t0_s * 1e6).max(0.0) as u64;
    while t_us > 0 && !before(t_us - 1) {
        t_us -= 1;
    }
    while before(t_us) {
        t_us += 1;
    }
    t_us
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

    /// The time the time panels cover, s: the whole run, or a long run's last [`DETAIL_S`].
    pub fn span_s(&self) -> (f64, f64) {
        (self.t0, self.t_end)
    }

    /// Whether this is a long run's chart (detail and per-minute panels).
    pub fn is_long(&self) -> bool {
        self.long
    }
}

/// The pale blue the truth is drawn in: blue at 35 % over the white background, opaque, so the
/// strokes of a wide line overlapping themselves do not darken.
const TRUTH: RGBColor = RGBColor(166, 166, 255);

/// A time panel's plot: f64 on both axes.
type Plot<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// A clipped segment: its ends, and whether each is the segment's own (not a cut).
type Clipped = ((f64, f64), (f64, f64), bool, bool);

/// Segment `p`–`q` cut to the rectangle `x` × `y` (Liang–Barsky): its ends inside, and whether
/// each is the segment's own (not a cut); None when it misses the rectangle or is not finite.
fn clip_segment(p: (f64, f64), q: (f64, f64), x: (f64, f64), y: (f64, f64)) -> Option<Clipped> {
    if ![p.0, p.1, q.0, q.1].iter().all(|v| v.is_finite()) {
        return None;
    }
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (pk, qk) in [
        (-dx, p.0 - x.0),
        (dx, x.1 - p.0),
        (-dy, p.1 - y.0),
        (dy, y.1 - p.1),
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
    let at = |t: f64| (p.0 + t * dx, p.1 + t * dy);
    let a = if t0 == 0.0 { p } else { at(t0) };
    let b = if t1 == 1.0 { q } else { at(t1) };
    Some((a, b, t0 == 0.0, t1 == 1.0))
}

/// The runs of polyline `pts` inside the rectangle `x` × `y` (data coordinates): every segment
/// cut where it crosses the border, a new run wherever the line comes back in. What a plot draws
/// goes through this, so no trace lands outside its plot (plotters does not clip).
pub fn clip_polyline(pts: &[(f64, f64)], x: (f64, f64), y: (f64, f64)) -> Vec<Series> {
    let mut runs: Vec<Series> = Vec::new();
    if let [p] = pts {
        if clip_segment(*p, *p, x, y).is_some() {
            runs.push(vec![*p]);
        }
        return runs;
    }
    let mut open = false;
    for w in pts.windows(2) {
        match clip_segment(w[0], w[1], x, y) {
            None => open = false,
            Some((a, b, whole_start, whole_end)) => {
                match runs.last_mut() {
                    Some(run) if open && whole_start => run.push(b),
                    _ => runs.push(vec![a, b]),
                }
                open = whole_end;
            }
        }
    }
    runs
}

/// Draws `pts` as a 1-px line, clipped to the plot.
fn thin<DB: DrawingBackend>(
    c: &mut Plot<'_, DB>,
    pts: &[(f64, f64)],
    style: ShapeStyle,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (x, y) = (c.x_range(), c.y_range());
    for run in clip_polyline(pts, (x.start, x.end), (y.start, y.end)) {
        c.draw_series(LineSeries::new(run, style))?;
    }
    Ok(())
}

/// Pixel offsets a line `width` px wide is stamped at: a disc of that diameter.
fn stamp(width: u32) -> Vec<(i32, i32)> {
    let w = width.max(1) as i32;
    let (lo, hi) = (-(w - 1) / 2, w / 2);
    let c = (lo + hi) as f64 / 2.0;
    let r2 = (w as f64 / 2.0).powi(2);
    let mut out = Vec::new();
    for dx in lo..=hi {
        for dy in lo..=hi {
            if (dx as f64 - c).powi(2) + (dy as f64 - c).powi(2) <= r2 {
                out.push((dx, dy));
            }
        }
    }
    out
}

/// Draws `pts` as a line `width` px wide in an opaque `color`, clipped to the plot: the 1-px
/// polyline stamped at every offset of a disc. (plotters' own wide lines join segments with
/// unbounded miters: a decimated zigzag's joins spiked across the whole picture.)
fn wide<DB: DrawingBackend>(
    c: &mut Plot<'_, DB>,
    pts: &[(f64, f64)],
    color: RGBColor,
    width: u32,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (x, y) = (c.x_range(), c.y_range());
    let area = c.plotting_area().strip_coord_spec();
    let base = c.plotting_area().get_base_pixel();
    let offsets = stamp(width);
    for run in clip_polyline(pts, (x.start, x.end), (y.start, y.end)) {
        let mut px: Vec<(i32, i32)> = Vec::with_capacity(run.len());
        for p in &run {
            let b = c.backend_coord(p);
            let q = (b.0 - base.0, b.1 - base.1);
            if px.last() != Some(&q) {
                px.push(q);
            }
        }
        if px.len() == 1 {
            px.push(px[0]);
        }
        for &(dx, dy) in &offsets {
            let shifted: Vec<(i32, i32)> = px.iter().map(|&(a, b)| (a + dx, b + dy)).collect();
            area.draw(&PathElement::new(shifted, color.stroke_width(1)))?;
        }
    }
    Ok(())
}

/// Draws what the core saw (red, thin, in runs broken by faults) over the truth (pale blue,
/// wide), both already decimated to the panel's width by the [`Recorder`], and the legend
/// beside the plot: `(runs, label, line width)` and `(truth, line width)`.
fn core_against_truth<DB: DrawingBackend>(
    c: &mut Plot<'_, DB>,
    (core, label, core_width): (&[Vec<(f64, f64)>], &str, u32),
    (truth, truth_width): (&[(f64, f64)], u32),
) -> Result<Vec<Entry>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    // The truth first, wide and pale, so the core's thin line stays visible on top of it.
    wide(c, truth, TRUTH, truth_width)?;
    for run in core {
        thin(c, run, RED.stroke_width(core_width))?;
    }
    Ok(vec![
        ("true".into(), TRUTH.to_rgba(), truth_width),
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

/// The chart's width, px.
pub const WIDTH_PX: u32 = 1600;
/// The title band's height, px.
pub const TITLE_PX: u32 = 40;
/// The time panels' height (position, velocity, region, gate), px.
const TIME_PANELS_PX: u32 = 1160;
/// The line panel's height, px.
const LINE_PANEL_PX: u32 = 320;
/// A long chart's section headings' height, px.
const HEADING_PX: u32 = 30;
/// A long chart's per-minute panels' height, px.
const MINUTE_PANELS_PX: u32 = 4 * 240;

/// The chart's size in pixels: the short chart's, or the long one's with its headings and
/// per-minute panels.
pub fn size(d: &ChartData) -> (u32, u32) {
    let lines = if d.lines_mm.is_empty() {
        0
    } else {
        LINE_PANEL_PX
    };
    let long = if d.long {
        2 * HEADING_PX + MINUTE_PANELS_PX
    } else {
        0
    };
    (WIDTH_PX, TITLE_PX + TIME_PANELS_PX + lines + long)
}

/// The pixel rectangles `(x0, y0, x1, y1)` of the chart's panels, top to bottom: the time
/// panels, then a long run's per-minute panels, then the line panel. Each draws only inside
/// its own rectangle; the title band and the headings are the rest.
pub fn panel_rects(d: &ChartData) -> Vec<(i32, i32, i32, i32)> {
    let w = WIDTH_PX as i32;
    let mut y = TITLE_PX as i32;
    if d.long {
        y += HEADING_PX as i32;
    }
    let mut out = Vec::new();
    for h in [330, 330, 200, 300] {
        out.push((0, y, w, y + h));
        y += h;
    }
    if d.long {
        y += HEADING_PX as i32;
        for _ in 0..4 {
            let h = (MINUTE_PANELS_PX / 4) as i32;
            out.push((0, y, w, y + h));
            y += h;
        }
    }
    if !d.lines_mm.is_empty() {
        out.push((0, y, w, y + LINE_PANEL_PX as i32));
    }
    out
}

/// Writes the chart of a run (its [`ChartData`], and for a long run its per-minute figures from
/// `m`) to `path` (PNG).
pub fn write_png(
    d: &ChartData,
    m: &Metrics,
    path: &Path,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, size(d)).into_drawing_area();
    draw(d, m, &root, title)?;
    root.present()?;
    Ok(())
}

/// Draws the chart on `root` (of [`size`]): the title, the time panels and, for a long run,
/// the per-minute panels under headings; the line panel last.
pub fn draw<DB: DrawingBackend>(
    d: &ChartData,
    m: &Metrics,
    root: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    root.draw(&Text::new(
        title.to_string(),
        (20, 10),
        ("sans-serif", 22).into_font(),
    ))?;
    let heading = |y: i32, text: String| {
        root.draw(&Text::new(
            text,
            (20, y + 6),
            ("sans-serif", 19).into_font().style(FontStyle::Bold),
        ))
    };
    let rects = panel_rects(d);
    let area = |r: (i32, i32, i32, i32)| {
        root.clone()
            .shrink((r.0, r.1), ((r.2 - r.0) as u32, (r.3 - r.1) as u32))
    };
    if d.long {
        heading(
            TITLE_PX as i32,
            format!(
                "the last {} s in detail (t = {:.1} to {:.1} s)",
                fmt_s(d.t_end - d.t0),
                d.t0,
                d.t_end
            ),
        )?;
    }
    let time: Vec<_> = rects[..4].iter().map(|&r| area(r)).collect();
    time_panels(d, &time)?;
    if d.long {
        heading(
            rects[3].3,
            format!(
                "minute by minute over the whole {} s ({} minutes; the last one {} s)",
                fmt_s(d.t_end),
                m.minutes.len(),
                fmt_s(m.minutes.last().map_or(0.0, |x| x.span_s))
            ),
        )?;
        let minutes: Vec<_> = rects[4..8].iter().map(|&r| area(r)).collect();
        minute_panels(d, m, &minutes)?;
    }
    if let Some(&r) = rects.last().filter(|_| !d.lines_mm.is_empty()) {
        line_envelopes(d, &area(r))?;
    }
    Ok(())
}

/// Seconds as the headings write them: whole seconds without decimals.
fn fmt_s(s: f64) -> String {
    if (s - s.round()).abs() < 1e-9 {
        format!("{s:.0}")
    } else {
        format!("{s:.2}")
    }
}

/// The position, velocity, region and gate panels over `d.t0 .. d.t_end`.
fn time_panels<DB: DrawingBackend>(
    d: &ChartData,
    panels: &[DrawingArea<DB, plotters::coord::Shift>],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let (t0, t_end) = (d.t0, d.t_end);
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
            .build_cartesian_2d(t0..t_end, -1.0..len_mm + 1.0)?;
        c.configure_mesh()
            .y_desc("position (mm)")
            .axis_desc_style(label_font)
            .label_style(("sans-serif", 15))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        let mut legend: Vec<Entry> = Vec::new();
        for &b in &d.boundaries_mm {
            c.draw_series(DashedLineSeries::new(
                vec![(t0, b), (t_end, b)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?;
            legend.push((format!("boundary {b:.3} mm"), BLACK.mix(0.5), 1));
        }
        for (i, &l) in d.lines_mm.iter().enumerate() {
            c.draw_series(DashedLineSeries::new(
                vec![(t0, l), (t_end, l)],
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
        // The boundaries and lines again over the opaque truth, so they stay visible.
        for &b in &d.boundaries_mm {
            c.draw_series(DashedLineSeries::new(
                vec![(t0, b), (t_end, b)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))?;
        }
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
            .build_cartesian_2d(t0..t_end, -vmax..vmax)?;
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
            .build_cartesian_2d(t0..t_end, -1.5..n - 0.5)?;
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
        // GREEN at 90 % over white, opaque.
        wide(&mut c, &pts, RGBColor(25, 255, 25), 2)?;
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
            .build_cartesian_2d(t0..t_end, -0.2..1.2)?;
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
        thin(&mut c, &pts, BLACK.stroke_width(1))?;
        // The drive the finger gets: enable × the RF level (the reference circuit's amplitude
        // for the DAC code), as a share of full drive.
        let blue = RGBColor(30, 90, 220);
        thin(&mut c, &d.drive.points(), blue.mix(0.8).stroke_width(1))?;
        // Where bursts are denser than pixels the line is a solid band: there the share of
        // each pixel column's time it was on is drawn over it (the duty, and where it drops),
        // last, so the drive's own band does not hide it.
        let orange = RGBColor(230, 120, 0);
        for run in d.duty.runs() {
            wide(&mut c, &run, orange, 2)?;
        }
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
    Ok(())
}

/// Colours of the regions on the per-minute panels, in order (repeating).
const REGION_COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(127, 127, 127),
    RGBColor(23, 190, 207),
];

/// A per-minute plot: minutes on x, f64 on y.
fn minute_plot<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, plotters::coord::Shift>,
    minutes: f64,
    y: std::ops::Range<f64>,
    y_desc: &str,
    last: bool,
    y_labels: Option<&dyn Fn(&f64) -> String>,
) -> Result<Plot<'a, DB>, Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mut c = ChartBuilder::on(area)
        .margin(10)
        .margin_right(LEGEND_PX)
        .x_label_area_size(if last { 45 } else { 30 })
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..minutes, y)?;
    let mut mesh = c.configure_mesh();
    mesh.y_desc(y_desc)
        .axis_desc_style(("sans-serif", 18))
        .label_style(("sans-serif", 15))
        .light_line_style(WHITE.mix(0.0));
    if last {
        mesh.x_desc("time (minutes)");
    }
    if let Some(f) = y_labels {
        mesh.y_labels(12).y_label_formatter(f);
    }
    mesh.draw()?;
    Ok(c)
}

/// The run minute by minute ([`Metrics::minutes`]), one point per minute at its middle: f_b
/// produced per region (log scale, the commanded or model f_b dashed) and the lines' pulse
/// rate; how far past their boundary the minute's switches came (least to most); the velocity
/// error at zero lag and at the run's delay; the share of the minute under fault.
fn minute_panels<DB: DrawingBackend>(
    d: &ChartData,
    m: &Metrics,
    panels: &[DrawingArea<DB, plotters::coord::Shift>],
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    let mins = &m.minutes;
    let span = mins
        .last()
        .map_or(1.0, |x| (x.start_s + x.span_s) / 60.0)
        .max(1e-3);
    let mid = |x: &Minute| (x.start_s + x.span_s / 2.0) / 60.0;

    // f_b per region, and the lines' pulses per second.
    {
        let colour = |i: usize| REGION_COLOURS[i % REGION_COLOURS.len()];
        let line_rate = |x: &Minute| {
            (x.line_pulses > 0 && x.span_s > 0.0).then(|| x.line_pulses as f64 / x.span_s)
        };
        let mut all: Vec<f64> = Vec::new();
        for x in mins {
            for r in &x.regions {
                all.extend(r.produced_hz.iter().chain(&r.expected_hz));
            }
            all.extend(line_rate(x));
        }
        all.extend(m.regions.iter().filter_map(|r| r.commanded_hz));
        let all: Vec<f64> = all
            .into_iter()
            .filter(|v| *v > 0.0 && v.is_finite())
            .collect();
        let lo = all.iter().copied().fold(f64::MAX, f64::min).min(1.0);
        let hi = all.iter().copied().fold(1.0, f64::max);
        let (lo, hi) = (lo.log10().floor() - 0.1, hi.log10().ceil() + 0.1);
        // A log axis drawn as log10 values: decades labelled.
        let decades = |v: &f64| {
            if (v - v.round()).abs() < 1e-6 {
                format!("{}", 10f64.powi(v.round() as i32))
            } else {
                String::new()
            }
        };
        let mut c = minute_plot(
            &panels[0],
            span,
            lo..hi,
            "f_b produced (Hz, log)",
            false,
            Some(&decades),
        )?;
        let mut legend: Vec<Entry> = Vec::new();
        for (i, label) in d.region_labels.iter().enumerate() {
            let produced: Vec<(f64, f64)> = mins
                .iter()
                .filter_map(|x| {
                    let f = x.regions.get(i)?.produced_hz?;
                    Some((mid(x), f.log10()))
                })
                .collect();
            let asked: Vec<(f64, f64)> = match m.regions.get(i).and_then(|r| r.commanded_hz) {
                Some(f) => vec![(0.0, f.log10()), (span, f.log10())],
                None => mins
                    .iter()
                    .filter_map(|x| Some((mid(x), x.regions.get(i)?.expected_hz?.log10())))
                    .collect(),
            };
            if produced.is_empty() && asked.is_empty() {
                continue;
            }
            let col = colour(i);
            for run in clip_polyline(&asked, (0.0, span), (lo, hi)) {
                c.draw_series(DashedLineSeries::new(run, 5, 4, col.stroke_width(1)))?;
            }
            thin(&mut c, &produced, col.stroke_width(1))?;
            c.draw_series(produced.iter().map(|&p| Circle::new(p, 3, col.filled())))?;
            legend.push((format!("{i}: {label}"), col.to_rgba(), 2));
        }
        let lines: Vec<(f64, f64)> = mins
            .iter()
            .filter_map(|x| Some((mid(x), line_rate(x)?.log10())))
            .collect();
        if !lines.is_empty() {
            thin(&mut c, &lines, MAGENTA.stroke_width(1))?;
            c.draw_series(lines.iter().map(|&p| Circle::new(p, 3, MAGENTA.filled())))?;
            legend.push(("line pulses per second".into(), MAGENTA.to_rgba(), 2));
        }
        legend.push(("dashed: commanded, or".into(), BLACK.mix(0.6), 1));
        legend.push(("  the texture's model".into(), WHITE.to_rgba(), 0));
        side_legend(&panels[0], &legend)?;
    }

    // Switches: how far past its boundary each minute's switches came.
    {
        let ranges: Vec<(f64, (f64, f64))> = mins
            .iter()
            .filter_map(|x| Some((mid(x), x.switch_past_um?)))
            .map(|(t, (a, b))| (t, (a / 1e3, b / 1e3)))
            .collect();
        let lo = ranges.iter().map(|r| r.1 .0).fold(0.0, f64::min);
        let hi = ranges.iter().map(|r| r.1 .1).fold(0.1, f64::max);
        let pad = 0.1 * (hi - lo);
        let mut c = minute_plot(
            &panels[1],
            span,
            lo - pad..hi + pad,
            "switch past boundary (mm)",
            false,
            None,
        )?;
        let col = RGBColor(30, 90, 220);
        for &(t, (a, b)) in &ranges {
            thin(&mut c, &[(t, a), (t, b)], col.stroke_width(1))?;
            c.draw_series([a, b].map(|v| Circle::new((t, v), 3, col.filled())))?;
        }
        thin(
            &mut c,
            &[(0.0, 0.0), (span, 0.0)],
            BLACK.mix(0.5).stroke_width(1),
        )?;
        side_legend(
            &panels[1],
            &[
                (
                    format!("{} switches; per minute", m.switch_count),
                    col.to_rgba(),
                    2,
                ),
                ("  the least and the most".into(), WHITE.to_rgba(), 0),
                ("  past the boundary".into(), WHITE.to_rgba(), 0),
                ("the boundary".into(), BLACK.mix(0.5), 1),
            ],
        )?;
    }

    // Velocity error.
    {
        let zero: Vec<(f64, f64)> = mins
            .iter()
            .filter_map(|x| Some((mid(x), x.velocity_rms_um_s? / 1e3)))
            .collect();
        let delayed: Vec<(f64, f64)> = mins
            .iter()
            .filter_map(|x| Some((mid(x), x.velocity_rms_at_delay_um_s? / 1e3)))
            .collect();
        let hi = zero.iter().chain(&delayed).map(|p| p.1).fold(0.1, f64::max) * 1.15;
        let mut c = minute_plot(
            &panels[2],
            span,
            0.0..hi,
            "velocity RMS error (mm/s)",
            false,
            None,
        )?;
        let blue = RGBColor(30, 90, 220);
        thin(&mut c, &zero, RED.stroke_width(1))?;
        c.draw_series(zero.iter().map(|&p| Circle::new(p, 3, RED.filled())))?;
        thin(&mut c, &delayed, blue.stroke_width(1))?;
        c.draw_series(delayed.iter().map(|&p| Circle::new(p, 3, blue.filled())))?;
        let delay = m
            .velocity
            .map_or("—".into(), |v| format!("{:.1} ms", v.delay_us / 1e3));
        side_legend(
            &panels[2],
            &[
                ("at zero lag".into(), RED.to_rgba(), 2),
                (format!("at the run's delay, {delay}"), blue.to_rgba(), 2),
            ],
        )?;
    }

    // Faults: the share of each minute with a fault in force.
    {
        let pct: Vec<(f64, f64, f64)> = mins
            .iter()
            .map(|x| {
                (
                    x.start_s / 60.0,
                    (x.start_s + x.span_s) / 60.0,
                    100.0 * x.fault_samples as f64 / x.samples.max(1) as f64,
                )
            })
            .collect();
        let hi = pct.iter().map(|p| p.2).fold(1.0, f64::max) * 1.15;
        let mut c = minute_plot(
            &panels[3],
            span,
            0.0..hi,
            "time under fault (%)",
            true,
            None,
        )?;
        let col = RGBColor(214, 39, 40);
        c.draw_series(
            pct.iter()
                .filter(|p| p.2 > 0.0)
                .map(|&(a, b, v)| Rectangle::new([(a, 0.0), (b, v)], col.mix(0.6).filled())),
        )?;
        side_legend(
            &panels[3],
            &[
                ("time under fault".into(), col.mix(0.6), 8),
                (
                    format!("{} fault onsets in all", m.fault_onsets),
                    WHITE.to_rgba(),
                    0,
                ),
            ],
        )?;
    }
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
        thin(&mut c, curve, blue.mix(0.5).stroke_width(1))?;
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
    let mut d = DutyBins::new(0.0, t_end, bins);
    for &p in pts {
        d.push(p);
    }
    d.runs()
}

#[cfg(test)]
mod duty_tests {
    use super::{decimate, dense_duty, first_us_from, Decimator};

    /// The detail's first sample time is the first whose seconds are not before its start:
    /// every time below it is before (the one just below is), and it is not, for starts on
    /// and between whole µs, at 0 and a day's run.
    #[test]
    fn detail_starts_at_the_first_time_not_before_it() {
        for t0_s in [
            0.0,
            1e-7,
            0.1,
            57.0,
            58.37,
            297.0,
            3597.0,
            86_397.0,
            86_396.9999995,
        ] {
            let from_us = first_us_from(t0_s);
            assert!(from_us as f64 * 1e-6 >= t0_s, "{t0_s}: {from_us}");
            if from_us > 0 {
                assert!(((from_us - 1) as f64 * 1e-6) < t0_s, "{t0_s}: {from_us}");
            }
            // Within a µs of t0_s (no search ran away).
            assert!(
                (from_us as f64 - t0_s * 1e6).abs() <= 1.0,
                "{t0_s}: {from_us}"
            );
        }
    }

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
