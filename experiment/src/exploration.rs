//! What the finger did while a stimulus was explored, from the telemetry records of its window:
//! so an analysis can drop trials that were not explored, and so a grating's felt f_b (V/λ) is
//! known per trial.

use saw_link::msg::Record;
use serde::{Deserialize, Serialize};

/// Below this speed the finger counts as at rest, mm/s: well above the estimator's noise
/// (1.66 mm/s RMS, docs/conversion-budget.md) so noise is not exploration, well below a
/// slow stroke (the seed paper's U = 4 cm/s).
pub const MOVING_MM_S: f64 = 5.0;

/// A stroke ends where the finger reverses: the position must come back this far from the
/// stroke's furthest point (so noise at rest is not a stroke), mm.
pub const STROKE_MM: f64 = 2.0;

/// An exploration's summary.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Exploration {
    /// Records read.
    pub records: u32,
    /// Time the finger moved faster than [`MOVING_MM_S`], s.
    pub explored_s: f64,
    /// Strokes: runs in one direction of at least [`STROKE_MM`].
    pub strokes: u32,
    /// Mean speed while moving, mm/s (0 when it never moved).
    pub mean_speed_mm_s: f64,
    /// Peak speed, mm/s.
    pub peak_speed_mm_s: f64,
    /// Distance travelled, mm.
    pub distance_mm: f64,
    /// f_b produced: the mean burst frequency while bursting, Hz (0: no bursts).
    pub f_b_hz: f64,
    /// Records with a sensor fault.
    pub faults: u32,
    /// The scene ids seen in the window (the board's confirmation that the stimulus ran).
    pub scene_ids: Vec<u32>,
}

/// Summarises `records` (in time order).
pub fn summarize(records: &[Record]) -> Exploration {
    let mut e = Exploration {
        records: records.len() as u32,
        ..Exploration::default()
    };
    let mut moving_us = 0u64;
    // Distance summed in whole µm (the records' unit), so the sum has no rounding noise.
    let mut distance_um = 0u64;
    let mut speed_time = 0.0f64;
    let mut fb_sum = 0.0f64;
    let mut fb_n = 0u32;
    // Strokes: the direction of the current run and its extreme position.
    let mut dir = 0i8;
    let mut extreme_um = 0i64;
    let mut start_um: Option<i64> = None;
    let mut prev: Option<&Record> = None;
    for r in records {
        if !e.scene_ids.contains(&r.scene_id) {
            e.scene_ids.push(r.scene_id);
        }
        if r.fault.is_some() {
            e.faults += 1;
        }
        if r.bursting && r.burst_millihz > 0 {
            fb_sum += r.burst_millihz as f64 / 1000.0;
            fb_n += 1;
        }
        let speed = r.velocity_um_s.map(|v| (v as f64).abs() / 1000.0);
        if let Some(s) = speed {
            e.peak_speed_mm_s = e.peak_speed_mm_s.max(s);
        }
        if let Some(prev) = prev {
            let dt_us = r.time_us.saturating_sub(prev.time_us);
            // Only while the finger moves: at rest, position noise summed at the stream's
            // rate would add up to metres.
            let moving = speed.is_some_and(|s| s > MOVING_MM_S);
            if let (Some(a), Some(b), true) = (prev.position_um, r.position_um, moving) {
                distance_um += (i64::from(b) - i64::from(a)).unsigned_abs();
            }
            if let Some(s) = speed {
                if s > MOVING_MM_S {
                    moving_us += dt_us;
                    speed_time += s * dt_us as f64;
                }
            }
        }
        if r.position_um.is_none() {
            // No position (a sensor fault): the run is broken; a finger reappearing 2 mm away
            // is not a stroke.
            start_um = None;
            dir = 0;
        }
        if let Some(p) = r.position_um.map(i64::from) {
            let start = *start_um.get_or_insert(p);
            if dir == 0 {
                if (p - start).abs() as f64 >= STROKE_MM * 1000.0 {
                    dir = if p > start { 1 } else { -1 };
                    extreme_um = p;
                    e.strokes += 1;
                }
            } else if (dir > 0 && p > extreme_um) || (dir < 0 && p < extreme_um) {
                extreme_um = p;
            } else if (p - extreme_um).abs() as f64 >= STROKE_MM * 1000.0 {
                dir = -dir;
                extreme_um = p;
                e.strokes += 1;
            }
        }
        prev = Some(r);
    }
    e.explored_s = moving_us as f64 / 1e6;
    e.distance_mm = distance_um as f64 / 1000.0;
    if moving_us > 0 {
        // To the µm/s the records carry.
        e.mean_speed_mm_s = (speed_time / moving_us as f64 * 1000.0).round() / 1000.0;
    }
    if fb_n > 0 {
        // To the mHz the records carry (no float noise in the CSV).
        e.f_b_hz = (fb_sum / fb_n as f64 * 1000.0).round() / 1000.0;
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rec(t_us: u64, pos_um: i32, v_um_s: i32, fb_mhz: u32) -> Record {
        Record {
            time_us: t_us,
            scene_id: 7,
            change: 1,
            position_um: Some(pos_um),
            velocity_um_s: Some(v_um_s),
            region: Some(0),
            burst_millihz: fb_mhz,
            bursting: fb_mhz > 0,
            fault: None,
        }
    }

    /// A finger at 50 mm/s back and forth over 20 mm for 2 s, records every ms: 100 mm
    /// travelled, 5 strokes, all of it explored.
    #[test]
    fn a_triangle_is_counted_by_hand() {
        let mut rs = Vec::new();
        for k in 0..=2000u64 {
            let t_ms = k as f64;
            // 400 ms per 20 mm leg.
            let leg = (k / 400) as i64;
            let into = (k % 400) as f64 / 400.0 * 20_000.0;
            let pos = if leg % 2 == 0 { into } else { 20_000.0 - into };
            let v = if leg % 2 == 0 { 50_000 } else { -50_000 };
            let _ = t_ms;
            rs.push(rec(k * 1000, pos as i32, v, 80_000));
        }
        let e = summarize(&rs);
        assert_eq!(e.records, 2001);
        assert!((e.distance_mm - 100.0).abs() < 0.2, "{e:?}");
        assert_eq!(e.strokes, 5, "{e:?}");
        assert!((e.explored_s - 2.0).abs() < 0.002, "{e:?}");
        assert!((e.mean_speed_mm_s - 50.0).abs() < 1e-9, "{e:?}");
        assert_eq!(e.peak_speed_mm_s, 50.0);
        assert_eq!(e.f_b_hz, 80.0);
        assert_eq!(e.scene_ids, vec![7]);
    }

    /// At rest with noise of ±0.5 mm and ±3 mm/s: nothing explored, no stroke.
    #[test]
    fn noise_at_rest_is_not_exploration() {
        let rs: Vec<Record> = (0..1000u64)
            .map(|k| {
                let wobble = if k % 2 == 0 { 500 } else { -500 };
                rec(
                    k * 1000,
                    30_000 + wobble,
                    if k % 2 == 0 { 3000 } else { -3000 },
                    0,
                )
            })
            .collect();
        let e = summarize(&rs);
        assert_eq!(e.strokes, 0, "{e:?}");
        assert_eq!(e.explored_s, 0.0, "{e:?}");
        assert_eq!(e.distance_mm, 0.0, "noise at rest travels nowhere: {e:?}");
        assert_eq!(e.mean_speed_mm_s, 0.0);
        assert_eq!(e.f_b_hz, 0.0, "no bursts");
    }

    /// A position lost (a fault) and back 3 mm away, at rest either side: no stroke, no
    /// distance; a stroke after it still counts.
    #[test]
    fn a_gap_in_position_is_not_a_stroke() {
        let mut rs: Vec<Record> = (0..10u64).map(|k| rec(k * 1000, 10_000, 0, 0)).collect();
        let mut gap = rec(10_000, 0, 0, 0);
        gap.position_um = None;
        gap.velocity_um_s = None;
        rs.push(gap);
        rs.extend((11..20u64).map(|k| rec(k * 1000, 13_000, 0, 0)));
        let e = summarize(&rs);
        assert_eq!((e.strokes, e.distance_mm), (0, 0.0), "{e:?}");
        // Then a 5 mm run at 50 mm/s: one stroke, 5 mm.
        rs.extend((0..=100u64).map(|k| rec(20_000 + k * 1000, 13_000 + 50 * k as i32, 50_000, 0)));
        let e = summarize(&rs);
        assert_eq!(e.strokes, 1, "{e:?}");
        assert!((e.distance_mm - 5.0).abs() < 0.06, "{e:?}");
    }

    #[test]
    fn faults_and_scenes_are_counted() {
        let mut rs = vec![rec(0, 0, 0, 0), rec(1000, 0, 0, 0)];
        rs[1].fault = Some(saw_core::position::SensorFault::RailLow);
        rs[1].scene_id = 9;
        let e = summarize(&rs);
        assert_eq!(e.faults, 1);
        assert_eq!(e.scene_ids, vec![7, 9]);
        assert_eq!(summarize(&[]), Exploration::default());
    }
}
