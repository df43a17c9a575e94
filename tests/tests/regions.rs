//! Region switching on noisy positions: no chatter at rest on a boundary, and real crossings
//! switch within 0.2 mm past the boundary at 20–300 mm/s in both directions.
//!
//! README.md states the worst switch as measured here: 160 µm past the boundary, worst of 40 ADC
//! noise seeds at 200 and 300 mm/s and of 8 at 20–100 mm/s (the 100 µm hysteresis plus up to
//! two samples' travel, 2 × 30 µm at 300 mm/s; one sample's, 130 µm, on most seeds).

use host_sim::metrics;
use host_sim::sim::{self, SimParams};
use host_sim::trajectory::Trajectory;
use saw_boards::NUCLEO_F446RE;

fn params(trajectory: Trajectory, duration_s: f64, noise: f64, seed: u64) -> SimParams {
    SimParams::new(&NUCLEO_F446RE, trajectory, duration_s).with_noise(noise, seed)
}

/// 0 switches in 10 s at rest on each boundary with 3 LSB, on two noise seeds per boundary.
#[test]
fn ten_seconds_at_rest_on_a_boundary_never_switches() {
    let cfg = saw_core::default_config();
    for (i, &b) in cfg.scene.boundaries_um.iter().enumerate() {
        for seed in [100, 200].map(|s| s + i as u64) {
            let p = params(Trajectory::Rest { at_um: b as f64 }, 10.0, 3.0, seed);
            let r = sim::run(&p).unwrap();
            let sw = metrics::switches(&r);
            // The position really does dither across the boundary (the test is not vacuous).
            let (below, above) =
                r.trace
                    .iter()
                    .filter_map(|t| t.meas_um)
                    .fold((0, 0), |(lo, hi), m| {
                        if m < b as i32 {
                            (lo + 1, hi)
                        } else {
                            (lo, hi + 1)
                        }
                    });
            let (n, k) = (r.trace.len(), sw.len());
            let what = format!("boundary {b} µm, seed {seed}");
            eprintln!("{what}: {n} samples, {below} below, {above} above, {k} switches");
            assert_eq!(r.trace.len(), 100_000);
            assert!(below > 10_000 && above > 10_000, "{below} / {above}");
            assert!(
                sw.is_empty(),
                "{} switches at rest: {:?}",
                sw.len(),
                &sw[..1]
            );
            assert_eq!(r.telemetry.region_switches, 0);
            assert_eq!(r.telemetry.faults, 0);
        }
    }
}

/// The same rest without hysteresis chatters: the zero-switch check can fail.
#[test]
fn without_hysteresis_the_same_rest_chatters() {
    let mut p = params(Trajectory::Rest { at_um: 18_963.0 }, 1.0, 3.0, 100);
    p.config.scene.hysteresis_um = 0;
    let r = sim::run(&p).unwrap();
    let n = metrics::switches(&r).len();
    eprintln!("no hysteresis: {n} switches in 1 s");
    assert!(n > 100, "{n}");
}

/// Worst switch distance stated in README.md, µm, asserted as is: at 200–300 mm/s the distance
/// moves in whole samples' travel (20–30 µm), so a worse seed would add a step, not a rounding.
const STATED_WORST_PAST_UM: f64 = 160.0;

/// Noise seeds per speed: the distance only reaches its worst at the fast speeds, and on a few
/// seeds (160 µm on seed 35 at +300 mm/s), so those run on 40 seeds; the slow crossings, which
/// take most of the time, on 8 (worst 106 µm at 20 mm/s, 105 at 50, 120 at 100).
fn seeds(speed_mm_s: f64) -> std::ops::Range<u64> {
    if speed_mm_s >= 200.0 {
        0..40
    } else {
        0..8
    }
}

#[test]
fn crossings_switch_within_0_2_mm_past_the_boundary() {
    let cfg = saw_core::default_config();
    let mut worst = (0.0f64, String::new());
    let mut runs = 0;
    for &b in cfg.scene.boundaries_um.iter() {
        let b = b as f64;
        for speed_mm_s in [20.0, 50.0, 100.0, 200.0, 300.0] {
            for dir in [1.0, -1.0] {
                for seed in seeds(speed_mm_s) {
                    let v = speed_mm_s * 1e3 * dir;
                    let from = b - dir * 5_000.0;
                    let duration = 10_000.0 / (speed_mm_s * 1e3);
                    let p = params(
                        Trajectory::Constant {
                            from_um: from,
                            speed_um_s: v,
                        },
                        duration,
                        3.0,
                        seed,
                    );
                    let r = sim::run(&p).unwrap();
                    let sw = metrics::switches(&r);
                    let case = format!("boundary {b} µm, {:+} mm/s, seed {seed}", v / 1e3);
                    assert_eq!(sw.len(), 1, "{case}: {sw:?}");
                    let s = sw[0];
                    assert_eq!(s.boundary_um, b, "{case}");
                    assert_eq!(s.to as i32 - s.from as i32, dir as i32, "{case}");
                    assert!(
                        (0.0..=200.0).contains(&s.past_um),
                        "{case}: switched {:.1} µm past the boundary",
                        s.past_um
                    );
                    assert!(
                        s.past_um <= STATED_WORST_PAST_UM,
                        "{case}: {:.1} µm past the boundary, README says ≤ {STATED_WORST_PAST_UM}",
                        s.past_um
                    );
                    if s.past_um >= worst.0 {
                        worst = (s.past_um, case);
                    }
                    runs += 1;
                }
            }
        }
    }
    eprintln!(
        "{runs} crossings; worst switch {:.1} µm past the boundary ({})",
        worst.0, worst.1
    );
    assert_eq!(runs, 2 * 2 * (3 * 8 + 2 * 40));
}
