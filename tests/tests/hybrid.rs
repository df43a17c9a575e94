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

/// The specification, issue #17's figure (docs/estimators.md, "the 10 µm"): every burst
/// on a steady stroke within 10 µm of its ridge, on every run.
const SPEC_STEADY_WORST_UM: f64 = 10.0;

/// 95 % of the steady bursts of all runs within 5 µm of their ridge: 2.5 σ of the line's end
/// (σ ≈ 2.0 µm, docs/estimators.md: 0.25 of one sample's position noise, 8.1 µm at 2 LSB with
/// 16 conversions), where a Gaussian puts 98.8 %. Measured over 30 seeds a case (22 320 bursts):
/// 95th percentile 4.0 µm, RMS 2.1 µm, and worst 8.7 µm (λ = 0.2 mm, 100 mm/s, seed 17), so a
/// bound at the worst of a few seeds is the noise realisation's, not the renderer's.
const STEADY_P95_UM: f64 = 5.0;

/// Snapshot: the worst |placement error| on a steady stroke over [`SEEDS`] on today's noise
/// stream, 6.61 µm (λ = 0.2 mm at 100 mm/s, seed 0), the figure docs/estimators.md quotes. Not a
/// specification: a change of the noise model or the loop moves it; re-measure and update the
/// docs' figure with it. With the 32-sample line it was 10.2 µm.
const SNAPSHOT_STEADY_WORST_UM: f64 = 6.61;
const SNAPSHOT_STEADY_WORST_CASE: &str = "λ 200 µm, 100 mm/s, seed 0";

struct Score {
    steady_abs_um: Vec<f64>,
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
        steady_abs_um: steady.iter().map(|e| e.abs()).collect(),
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

/// One steady-stroke run: its case, its score and the ridges the renderer skipped.
struct SteadyRun {
    case: String,
    score: Score,
    ridges_skipped: u32,
}

/// The steady strokes: λ = 0.2 and 1 mm, 20/50/100/200 mm/s there and back, [`SEEDS`] each. Run
/// once per test binary and shared by the specification test and the snapshot.
fn steady_runs() -> &'static [SteadyRun] {
    static RUNS: std::sync::OnceLock<Vec<SteadyRun>> = std::sync::OnceLock::new();
    RUNS.get_or_init(|| {
        let mut runs = Vec::new();
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
                    runs.push(SteadyRun {
                        case: format!("λ {wavelength_um} µm, {mm_s} mm/s, seed {seed}"),
                        score: score(&r, wavelength_um, v),
                        ridges_skipped: r.telemetry.ridges_skipped,
                    });
                }
            }
        }
        runs
    })
}

#[test]
fn hybrid_bursts_land_within_ten_microns_on_a_steady_stroke() {
    let mut all_um = Vec::new();
    for run in steady_runs() {
        let (case, s) = (&run.case, &run.score);
        eprintln!(
            "{case}: {} bursts / {} ridges, {} delayed; steady RMS {:.1} worst {:.1} µm; within {SETTLE_S} s of a turn worst {:.1} µm",
            s.bursts, s.ridges, s.delayed, s.steady_rms_um, s.steady_worst_um, s.settling_worst_um
        );
        assert_eq!(s.bursts as u64, s.ridges, "{case}: one burst per ridge");
        assert!(
            s.steady_worst_um <= SPEC_STEADY_WORST_UM,
            "{case}: worst {} µm, the specification is {SPEC_STEADY_WORST_UM} µm",
            s.steady_worst_um
        );
        // Most bursts are delayed into the period by the prediction (the others are fired at
        // once where the line had just passed the ridge, or by position phase within a window
        // of a turn).
        assert!(s.delayed * 2 >= s.bursts, "{case}: {} delayed", s.delayed);
        assert_eq!(run.ridges_skipped, 0, "{case}");
        all_um.extend_from_slice(&s.steady_abs_um);
    }
    all_um.sort_by(f64::total_cmp);
    assert!(all_um.len() > 1_000, "{} steady bursts", all_um.len());
    let p95 = all_um[all_um.len() * 95 / 100];
    eprintln!(
        "steady bursts: {}, 95th percentile {p95:.2} µm, worst {:.2} µm",
        all_um.len(),
        all_um[all_um.len() - 1]
    );
    assert!(
        p95 <= STEADY_P95_UM,
        "95th percentile of the steady bursts {p95:.2} µm, above {STEADY_P95_UM} µm"
    );
}

/// Snapshot, not a specification: the worst steady placement over [`SEEDS`] on today's noise
/// stream is the figure docs/estimators.md quotes. A failure here means the figure moved (a
/// change of the noise model, the estimator or the renderer): re-measure, update the docs and
/// this snapshot, and judge the change by the specification test above.
#[test]
fn snapshot_hybrid_steady_worst_over_seeds_0_to_5() {
    let worst = steady_runs()
        .iter()
        .max_by(|a, b| a.score.steady_worst_um.total_cmp(&b.score.steady_worst_um))
        .unwrap();
    eprintln!(
        "hybrid steady worst {:.3} µm ({})",
        worst.score.steady_worst_um, worst.case
    );
    assert!(
        (worst.score.steady_worst_um - SNAPSHOT_STEADY_WORST_UM).abs() < 0.005
            && worst.case == SNAPSHOT_STEADY_WORST_CASE,
        "snapshot moved: worst {:.3} µm ({}), was {SNAPSHOT_STEADY_WORST_UM} µm ({SNAPSHOT_STEADY_WORST_CASE})",
        worst.score.steady_worst_um,
        worst.case
    );
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
