//! The hybrid grating renderer through the whole closed loop (rheostat/ADC model at 2 LSB,
//! default estimator, gate, timer model with delayed one-pulses): on a steady stroke its bursts
//! land within 10 µm of the ridges at 20–200 mm/s both ways, λ = 0.2 and 1 mm, one burst per
//! ridge; and it falls back to position phase where the prediction is not trusted.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::bench::renderers::grating_config_at;
use host_sim::metrics;
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::trajectory::Trajectory;
use saw_boards::NUCLEO_F446RE;
use saw_core::gate::GateAction;
use saw_core::texture::GratingRender;

/// Forth and back over 20 mm at `speed_um_s`, turning half a period from the ridges.
fn stroke(wavelength_um: u32, speed_um_s: f64) -> (Trajectory, f64) {
    let half = wavelength_um as f64 / 2.0;
    let t = Trajectory::Triangle {
        a_um: 10_000.0 + half,
        b_um: 30_000.0 + half,
        speed_um_s,
    };
    (t, 2.0 * 20_000.0 / speed_um_s)
}

/// The line needs its 64-sample window (6.4 ms at 10 kHz) after a turn; until then the
/// renderer is position phase. Hits this soon after a turn are scored apart.
const SETTLE_S: f64 = 0.0067;

/// Seeds of the ADC noise per case.
const SEEDS: std::ops::Range<u64> = 0..6;

/// Worst |placement error| on a steady stroke, stated in docs/estimators.md: 6.7 µm, the worst
/// of these 42 runs (6.61 µm, λ = 0.2 mm at 100 mm/s, seed 0), asserted as stated against the
/// issue's 10 µm. The line's end has σ = 0.25 of one sample's position noise (8.1 µm at 2 LSB
/// with 16 conversions, so 2.0 µm), and the worst of ~1 100 bursts is ≈ 3.3 σ of that. With the
/// 32-sample line it was 10.2 µm.
const STATED_STEADY_WORST_UM: f64 = 6.7;

struct Score {
    steady_worst_um: f64,
    steady_rms_um: f64,
    settling_worst_um: f64,
    bursts: usize,
    ridges: u64,
    delayed: usize,
}

fn score(r: &SimResult, wavelength_um: u32, speed_um_s: f64) -> Score {
    let hits = metrics::ridge_hits(r, wavelength_um as f64);
    let leg_s = 20_000.0 / speed_um_s;
    let (mut steady, mut settling) = (Vec::new(), Vec::new());
    for h in &hits {
        let since_turn_s = h.t_s % leg_s;
        if since_turn_s < SETTLE_S {
            settling.push(h.error_um.abs());
        } else {
            steady.push(h.error_um);
        }
    }
    let delayed = pulses(r).iter().filter(|(_, d)| *d).count();
    Score {
        steady_worst_um: steady.iter().map(|e| e.abs()).fold(0.0, f64::max),
        steady_rms_um: (steady.iter().map(|e| e * e).sum::<f64>() / steady.len().max(1) as f64)
            .sqrt(),
        settling_worst_um: settling.iter().copied().fold(0.0, f64::max),
        bursts: hits.len(),
        ridges: metrics::ridges_crossed(r, wavelength_um as f64),
        delayed,
    }
}

/// Every pulse action: (sample time s, delayed).
fn pulses(r: &SimResult) -> Vec<(f64, bool)> {
    r.trace
        .iter()
        .filter_map(|p| match p.action {
            Some(GateAction::Pulse(s)) => Some((p.t_us as f64 * 1e-6, s.arr > s.ccr)),
            _ => None,
        })
        .collect()
}

fn run(p: SimParams) -> SimResult {
    sim::run(&p).unwrap()
}

#[test]
fn hybrid_bursts_land_within_ten_microns_on_a_steady_stroke() {
    let mut worst = (0.0f64, String::new());
    for wavelength_um in [200u32, 1_000] {
        for mm_s in [20.0, 50.0, 100.0, 200.0] {
            // λ = 0.2 mm at 200 mm/s is 1 kHz: the board's top f_b; the ridge spacing check
            // can drop one in a run there, as position phase does (docs/estimators.md).
            if wavelength_um == 200 && mm_s == 200.0 {
                continue;
            }
            for seed in SEEDS {
                let v = mm_s * 1_000.0;
                let (traj, d) = stroke(wavelength_um, v);
                let r = run(SimParams::new(&NUCLEO_F446RE, traj, d)
                    .with_config(grating_config_at(GratingRender::Hybrid, wavelength_um))
                    .with_noise(2.0, seed));
                let s = score(&r, wavelength_um, v);
                let case = format!("λ {wavelength_um} µm, {mm_s} mm/s, seed {seed}");
                eprintln!(
                    "{case}: {} bursts / {} ridges, {} delayed; steady RMS {:.1} worst {:.1} µm; within {SETTLE_S} s of a turn worst {:.1} µm",
                    s.bursts, s.ridges, s.delayed, s.steady_rms_um, s.steady_worst_um, s.settling_worst_um
                );
                assert_eq!(s.bursts as u64, s.ridges, "{case}: one burst per ridge");
                assert!(
                    s.steady_worst_um <= STATED_STEADY_WORST_UM,
                    "{case}: worst {} µm",
                    s.steady_worst_um
                );
                // Most bursts are delayed into the period by the prediction (the others are
                // fired at once where the line had just passed the ridge, or by position
                // phase within a window of a turn).
                assert!(s.delayed * 2 >= s.bursts, "{case}: {} delayed", s.delayed);
                assert_eq!(r.telemetry.ridges_skipped, 0, "{case}");
                if s.steady_worst_um >= worst.0 {
                    worst = (s.steady_worst_um, case);
                }
            }
        }
    }
    eprintln!("hybrid steady worst {:.2} µm ({})", worst.0, worst.1);
}

/// Below the trust speed (10 mm/s) the line is not trusted: every burst comes from position
/// phase, undelayed, and there is still one per ridge.
#[test]
fn below_the_trust_speed_the_hybrid_is_position_phase() {
    let (traj, d) = stroke(1_000, 5_000.0);
    let r = run(SimParams::new(&NUCLEO_F446RE, traj, d / 4.0)
        .with_config(grating_config_at(GratingRender::Hybrid, 1_000))
        .with_noise(2.0, 1));
    let s = score(&r, 1_000, 5_000.0);
    assert!(s.ridges >= 4, "{}", s.ridges);
    assert_eq!(s.bursts as u64, s.ridges);
    assert_eq!(s.delayed, 0, "a delayed pulse below the trust speed");
    // Just above it: predicted.
    let (traj, d) = stroke(1_000, 15_000.0);
    let r = run(SimParams::new(&NUCLEO_F446RE, traj, d / 4.0)
        .with_config(grating_config_at(GratingRender::Hybrid, 1_000))
        .with_noise(2.0, 1));
    let s = score(&r, 1_000, 15_000.0);
    assert_eq!(s.bursts as u64, s.ridges);
    // Predicted: delayed into the period, except where the line had already passed the ridge
    // when it came in reach (fired at once, a fraction of a sample late).
    assert!(s.delayed * 2 >= s.bursts, "{} of {}", s.delayed, s.bursts);
}

/// A dropped sample and a glitch each empty the line: the ridges within the next 6.4 ms are
/// position phase (undelayed), and every ridge still gets one burst.
#[test]
fn a_dropped_sample_or_a_glitch_falls_back_for_one_window() {
    // 100 mm/s over λ = 0.2 mm: a ridge every 2 ms. The fault at 0.1 s, 10 mm past the start.
    for kind in [FaultKind::Dropout, FaultKind::Spike { offset_lsb: 200 }] {
        let (traj, _) = stroke(200, 100_000.0);
        let faults = vec![FaultWindow {
            kind,
            start_us: 100_000,
            end_us: 100_100,
        }];
        let r = run(SimParams::new(&NUCLEO_F446RE, traj, 0.15)
            .with_config(grating_config_at(GratingRender::Hybrid, 200))
            .with_noise(2.0, 3)
            .with_faults(faults));
        let pulse_rises = pulses(&r);
        let after: Vec<_> = pulse_rises
            .iter()
            .filter(|(t, _)| *t > 0.1001 && *t < 0.1001 + 0.0063)
            .collect();
        assert!(!after.is_empty(), "{kind:?}: no ridge in the window");
        assert!(
            after.iter().all(|(_, delayed)| !delayed),
            "{kind:?}: predicted inside the refill: {after:?}"
        );
        let later = pulse_rises
            .iter()
            .filter(|(t, _)| *t > 0.1066)
            .collect::<Vec<_>>();
        let delayed = later.iter().filter(|(_, d)| *d).count();
        assert!(
            delayed * 10 >= later.len() * 7,
            "{kind:?}: not predicted again: {later:?}"
        );
        let s = score(&r, 200, 100_000.0);
        assert_eq!(s.bursts as u64, s.ridges, "{kind:?}");
    }
}

/// A reversal on a ridge: the finger comes up to a ridge at 100 mm/s and turns on it. The
/// ridge fires once (it is crossed once, or touched), never twice, and the line is dropped at
/// the turn: the ridges after it, within the refill, are position phase.
#[test]
fn a_reversal_on_a_ridge_fires_it_once_and_falls_back() {
    for seed in 0..4 {
        let traj = Trajectory::Triangle {
            a_um: 10_000.0,
            b_um: 12_000.0,
            speed_um_s: 100_000.0,
        };
        let r = run(SimParams::new(&NUCLEO_F446RE, traj, 0.04)
            .with_config(grating_config_at(GratingRender::Hybrid, 200))
            .with_noise(2.0, seed));
        let hits = metrics::ridge_hits(&r, 200.0);
        // Bursts within 150 µm of the turn at 12 mm (t = 20 ms): at most one.
        let near_turn = hits
            .iter()
            .filter(|h| (h.t_s - 0.02).abs() < 0.0015)
            .count();
        assert!(
            near_turn <= 1,
            "seed {seed}: {near_turn} bursts at the turn"
        );
        let s = score(&r, 200, 100_000.0);
        assert!(
            s.bursts as u64 <= s.ridges + 1,
            "seed {seed}: {} / {}",
            s.bursts,
            s.ridges
        );
        assert!(
            s.bursts as u64 + 1 >= s.ridges,
            "seed {seed}: {} / {}",
            s.bursts,
            s.ridges
        );
    }
}

/// The bench's mixed motion (reversals, sines up to 300 mm/s and 10 m/s², 2 LSB): where the
/// 64-sample line's acceleration bias would show, the newer half's line takes over
/// (`DISAGREE_UM`). Stated in docs/estimators.md over seeds 2026–2029: hybrid RMS at most
/// 7.3 µm (7.09–7.24) and worst at most 20 µm (16.6–19.9), 0 ridges skipped; position phase on the same streams
/// RMS at least 15 µm (asserted: the hybrid at most half of it on every seed).
#[test]
fn on_the_mixed_motion_the_hybrid_halves_position_phase() {
    use host_sim::bench::{renderers::core_run, scenario};
    let (mixed, d) = scenario::mixed();
    for seed in 2026..2030 {
        let h = core_run(
            GratingRender::Hybrid,
            "mixed".into(),
            mixed.clone(),
            d,
            2.0,
            seed,
            None,
        );
        let p = core_run(
            GratingRender::PositionPhase,
            "mixed".into(),
            mixed.clone(),
            d,
            2.0,
            seed,
            None,
        );
        eprintln!(
            "seed {seed}: hybrid RMS {:.2} worst {:.2} µm, skipped {:?}; position phase RMS {:.2} worst {:.2}",
            h.rms_err_um, h.worst_err_um, h.skipped, p.rms_err_um, p.worst_err_um
        );
        assert!(h.rms_err_um <= 7.3, "seed {seed}: RMS {}", h.rms_err_um);
        assert!(
            h.worst_err_um <= 20.0,
            "seed {seed}: worst {}",
            h.worst_err_um
        );
        assert_eq!(h.skipped, Some(0), "seed {seed}");
        assert!(
            p.rms_err_um >= 15.0,
            "seed {seed}: position phase RMS {}",
            p.rms_err_um
        );
        assert!(2.0 * h.rms_err_um <= p.rms_err_um, "seed {seed}");
    }
}
