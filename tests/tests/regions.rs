//! Region switching on noisy positions: no chatter at rest on a boundary, and real crossings
//! switch within 0.2 mm past the boundary at 20–300 mm/s in both directions.

use host_sim::adc::AdcParams;
use host_sim::metrics;
use host_sim::sim::{self, SimParams};
use host_sim::trajectory::Trajectory;
use saw_boards::NUCLEO_F446RE;

fn params(trajectory: Trajectory, duration_s: f64, noise: f64, seed: u64) -> SimParams {
    let mut p = SimParams::new(&NUCLEO_F446RE, trajectory, duration_s);
    p.adc = AdcParams {
        noise_lsb_rms: noise,
        seed,
        ..AdcParams::default()
    };
    p
}

#[test]
fn ten_seconds_at_rest_on_a_boundary_never_switches() {
    let cfg = saw_core::default_config();
    for (i, &b) in cfg.scene.boundaries_um.iter().enumerate() {
        let p = params(
            Trajectory::Rest { at_um: b as f64 },
            10.0,
            3.0,
            100 + i as u64,
        );
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
        eprintln!(
            "boundary {b} µm: {} samples, {below} read below, {above} at/above, {} switches",
            r.trace.len(),
            sw.len()
        );
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

#[test]
fn crossings_switch_within_0_2_mm_past_the_boundary() {
    let cfg = saw_core::default_config();
    let mut worst = (0.0f64, String::new());
    let mut runs = 0;
    for &b in cfg.scene.boundaries_um.iter() {
        let b = b as f64;
        for speed_mm_s in [20.0, 50.0, 100.0, 200.0, 300.0] {
            for dir in [1.0, -1.0] {
                for seed in 0..3 {
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
}
