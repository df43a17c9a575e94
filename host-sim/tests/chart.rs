//! The run's chart drawn into memory and looked at pixel by pixel: nothing lands outside its
//! panel (the title band, the section headings, every panel's top margin and the gap between its
//! plot and its legend stay background), however dense the traces; a long run's chart covers
//! its last seconds in detail and adds the per-minute panels; the clipping every trace goes
//! through, on segments worked by hand.
//!
//! The runs are written out point by point (no simulator), so a test takes a second or two: a
//! 3600 s back-and-forth sampled every 10 ms, and 0.3 s of a trace with one-sample spikes (up
//! and back down within a pixel column: before, a wide line's miter join there spiked across
//! the whole picture).

use host_sim::chart::{self, ChartData, Recorder};
use host_sim::metrics::{Metrics, Online};
use host_sim::sim::{SimParams, TracePoint};
use host_sim::timer::Edge;
use host_sim::trajectory::Trajectory;
use plotters::prelude::*;

const CLOCK_HZ: u32 = 1_000_000;

/// A run of `duration_s` sampled every `period_us`, the finger at `at_um(t_us)` with velocity
/// `vel(t_us)` (µm/s), 20 Hz bursts throughout: its chart data and metrics.
fn written(
    duration_s: f64,
    period_us: u64,
    at_um: impl Fn(u64) -> f64,
    vel: impl Fn(u64) -> f64,
) -> (ChartData, Metrics) {
    let params = SimParams::new(
        &saw_boards::NUCLEO_F446RE,
        Trajectory::Rest { at_um: 1_500.0 },
        duration_s,
    );
    let mut rec = Recorder::new(&params, CLOCK_HZ);
    let mut m = Online::new(&params, CLOCK_HZ, period_us as u32, &[]);
    let end_us = (duration_s * 1e6) as u64;
    let mut edges = Vec::new();
    let mut t = 25;
    while t + 20_000 < end_us {
        edges.push(Edge { t, high: true });
        edges.push(Edge {
            t: t + 20_000,
            high: false,
        });
        t += 50_000;
    }
    m.edges(&edges);
    let mut next_edge = 0;
    for k in 0..end_us / period_us {
        let t_us = k * period_us;
        let x = at_um(t_us);
        let v = vel(t_us);
        let region = [18_963.0, 44_037.0].iter().filter(|b| x >= **b).count() as u8;
        let p = TracePoint {
            t_us,
            true_um: x,
            true_vel_um_s: v,
            sampled: true,
            code: None,
            meas_um: Some(x as i32 + 20),
            est_vel_um_s: Some(v as i32 + 500),
            region: Some(region),
            gate: false,
            fault: None,
            action: None,
            line: None,
        };
        m.point(&p);
        rec.point(&p);
        let upto = edges[next_edge..].partition_point(|e| e.t <= t_us) + next_edge;
        rec.edges(&edges[next_edge..upto], &[]);
        next_edge = upto;
    }
    rec.edges(&edges[next_edge..], &[]);
    (rec.finish(), m.finish())
}

/// The chart drawn into an RGB buffer, with its size.
fn drawn(d: &ChartData, m: &Metrics) -> (Vec<u8>, u32, u32) {
    let (w, h) = chart::size(d);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        chart::draw(d, m, &root, "t").unwrap();
        root.present().unwrap();
    }
    (buf, w, h)
}

/// Pixels of `rows` × `cols` that are not the white background, as (x, y).
fn inked(
    (buf, w, _): &(Vec<u8>, u32, u32),
    cols: std::ops::Range<i32>,
    rows: std::ops::Range<i32>,
) -> Vec<(i32, i32)> {
    let mut out = Vec::new();
    for y in rows {
        for x in cols.clone() {
            let i = ((y as u32 * w + x as u32) * 3) as usize;
            if buf[i..i + 3] != [255, 255, 255] {
                out.push((x, y));
            }
        }
    }
    out
}

/// Everything that must stay background: the title band right of the (one-letter) title, the
/// headings' bands right of their text, every panel's top margin over its plot's width, and the
/// gap between every plot and its legend (down to the x axis' labels).
fn assert_nothing_outside_panels(d: &ChartData, img: &(Vec<u8>, u32, u32)) {
    let (_, w, h) = *img;
    assert_eq!((w, h), chart::size(d));
    let w = w as i32;
    let title = chart::TITLE_PX as i32;
    let ink = inked(img, 60..w, 0..title);
    assert!(
        ink.is_empty(),
        "{} pixels drawn over the title band, e.g. {:?}",
        ink.len(),
        &ink[..ink.len().min(5)]
    );
    let rects = chart::panel_rects(d);
    // The headings: between the title and the first panel, and between the time panels and the
    // per-minute ones (a long chart only).
    let mut bands = vec![(title, rects[0].1)];
    if let Some(r) = rects.get(4) {
        bands.push((rects[3].3, r.1));
    }
    for (top, bottom) in bands.into_iter().filter(|b| b.1 > b.0) {
        let ink = inked(img, 1_000..w, top..bottom);
        assert!(
            ink.is_empty(),
            "{} pixels in the heading band {top}–{bottom}",
            ink.len()
        );
    }
    for (i, &(_, y0, _, y1)) in rects.iter().enumerate() {
        let ink = inked(img, 100..1_360, y0..y0 + 9);
        assert!(
            ink.is_empty(),
            "panel {i}: {} pixels in its top margin, e.g. {:?}",
            ink.len(),
            &ink[..ink.len().min(5)]
        );
        let ink = inked(img, w - 226..w - 222, y0..y1 - 50);
        assert!(
            ink.is_empty(),
            "panel {i}: {} pixels between its plot and its legend",
            ink.len()
        );
    }
}

/// A one-hour back-and-forth (60 mm/s between 1.5 and 61.5 mm): the chart is the long one, its
/// time panels cover the last 3 s, every panel stays in its place, and the per-minute panels
/// have something drawn in their plots.
#[test]
fn an_hour_long_run_draws_detail_and_minutes_inside_their_panels() {
    let tri = |t_us: u64| {
        let s = (t_us % 2_000_000) as f64 / 1e6;
        if s < 1.0 {
            1_500.0 + 60_000.0 * s
        } else {
            61_500.0 - 60_000.0 * (s - 1.0)
        }
    };
    let v = |t_us: u64| {
        if t_us % 2_000_000 < 1_000_000 {
            60_000.0
        } else {
            -60_000.0
        }
    };
    let (d, m) = written(3_600.0, 10_000, tri, v);
    assert!(d.is_long());
    assert_eq!(d.span_s(), (3_597.0, 3_600.0));
    assert_eq!(m.minutes.len(), 60);
    let img = drawn(&d, &m);
    assert_nothing_outside_panels(&d, &img);
    let rects = chart::panel_rects(&d);
    assert_eq!(rects.len(), 8);
    for (i, &(_, y0, _, y1)) in rects[4..].iter().enumerate() {
        assert!(
            !inked(&img, 100..1_360, y0 + 12..y1 - 50).is_empty(),
            "per-minute panel {i} is empty"
        );
    }
}

/// 0.3 s sampled every 100 µs (more samples than pixels) at rest at 30 mm, but for one sample
/// every 10 ms at the travel's far end: up and straight back down in one pixel column, the
/// sharpest turn a trace makes. The short chart, and its wide true-position and velocity lines
/// stay inside their plots (plotters' wide lines spiked down through every panel below, shown).
#[test]
fn the_sharpest_turns_stay_inside_their_panels() {
    let spike = |t_us: u64| t_us > 0 && t_us.is_multiple_of(10_000);
    let jump = |t_us: u64| if spike(t_us) { 61_500.0 } else { 30_000.0 };
    let v = |t_us: u64| if spike(t_us) { 600_000.0 } else { 0.0 };
    let (d, m) = written(0.3, 100, jump, v);
    assert!(!d.is_long());
    assert_eq!(d.span_s(), (0.0, 0.3));
    assert_nothing_outside_panels(&d, &drawn(&d, &m));
}

/// The clipping, by hand, against the rectangle 0–10 × 0–10: a line inside is kept whole; one
/// crossing the top is cut at y = 10; one that leaves and comes back splits in two runs, each
/// cut at the border; one wholly outside, or not finite, is dropped; a lone point is kept if
/// inside.
#[test]
fn clipping_by_hand() {
    let r = (0.0, 10.0);
    let clip = |pts: &[(f64, f64)]| chart::clip_polyline(pts, r, r);
    assert_eq!(
        clip(&[(1.0, 1.0), (2.0, 5.0), (3.0, 2.0)]),
        vec![vec![(1.0, 1.0), (2.0, 5.0), (3.0, 2.0)]]
    );
    assert_eq!(
        clip(&[(2.0, 6.0), (4.0, 14.0)]),
        vec![vec![(2.0, 6.0), (3.0, 10.0)]]
    );
    assert_eq!(
        clip(&[(1.0, 5.0), (3.0, 15.0), (5.0, 5.0), (6.0, 5.0)]),
        vec![
            vec![(1.0, 5.0), (2.0, 10.0)],
            vec![(4.0, 10.0), (5.0, 5.0), (6.0, 5.0)]
        ]
    );
    assert_eq!(
        clip(&[(-5.0, 20.0), (20.0, 20.0)]),
        Vec::<Vec<(f64, f64)>>::new()
    );
    assert_eq!(
        clip(&[(1.0, f64::NAN), (2.0, 2.0)]),
        Vec::<Vec<(f64, f64)>>::new()
    );
    assert_eq!(
        clip(&[(-10.0, 5.0), (20.0, 5.0)]),
        vec![vec![(0.0, 5.0), (10.0, 5.0)]]
    );
    assert_eq!(clip(&[(4.0, 4.0)]), vec![vec![(4.0, 4.0)]]);
    assert_eq!(clip(&[(40.0, 4.0)]), Vec::<Vec<(f64, f64)>>::new());
}
