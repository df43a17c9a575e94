//! Virtual gratings through the whole closed loop (rheostat/ADC model, default estimator, gate,
//! timer model): the default position-phase renderer puts its bursts within λ/20 of the ridges at
//! 20–200 mm/s both ways, velocity synthesis does not; neither fires at rest; and where they
//! fail — ridges faster than the board or than half the sample rate, a rail mid-stroke — the
//! line stays inside its caps and goes off.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::bench::renderers::grating_config;
use host_sim::metrics;
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::trajectory::{Piece, Trajectory};
use saw_boards::NUCLEO_F446RE;
use saw_core::texture::{Grating, GratingRender, Texture};

const LAMBDA_UM: f64 = 1_000.0;

fn run(
    config: saw_core::Config,
    trajectory: Trajectory,
    s: f64,
    noise: f64,
    seed: u64,
) -> SimResult {
    let p = SimParams::new(&NUCLEO_F446RE, trajectory, s)
        .with_config(config)
        .with_noise(noise, seed);
    sim::run(&p).unwrap()
}

/// Forth and back over 20 mm at `speed_um_s`.
fn stroke(speed_um_s: f64) -> (Trajectory, f64) {
    let t = Trajectory::Triangle {
        a_um: 10_500.0,
        b_um: 30_500.0,
        speed_um_s,
    };
    (t, 2.0 * 20_000.0 / speed_um_s)
}

/// Worst |placement error| of the bursts, µm, and (bursts, ridges crossed).
fn placement(r: &SimResult) -> (f64, usize, u64) {
    let hits = metrics::ridge_hits(r, LAMBDA_UM);
    let worst = hits.iter().map(|h| h.error_um.abs()).fold(0.0, f64::max);
    (worst, hits.len(), metrics::ridges_crossed(r, LAMBDA_UM))
}

/// Seeds of the ADC noise each speed is run with. The placement varies with the noise, so the
/// figure README.md and docs/estimators.md state is the worst over these 12 seeds.
const SEEDS: std::ops::Range<u64> = 0..12;
/// Worst |placement error| stated for position phase at 20–200 mm/s, worst of [`SEEDS`], µm,
/// asserted as is (no margin: it is two samples' travel at 200 mm/s, 2 × 20 µm, and the error
/// moves in whole samples' travel there; seeds 10, 18, 22, 33, 36 and 37 of 0..40 reach it,
/// none goes beyond). The requirement is λ/20 = 50 µm. Per speed, worst of 12: 20 µm at
/// 20 mm/s, 15 at 50, 20 at 100, 40 at 200.
const STATED_WORST_UM: f64 = 40.0;

#[test]
fn position_phase_bursts_land_within_a_twentieth_of_the_period() {
    let mut worst_all = (0.0f64, String::new());
    let mut runs = 0;
    for mm_s in [20.0, 50.0, 100.0, 200.0] {
        for seed in SEEDS {
            let (traj, d) = stroke(mm_s * 1_000.0);
            let r = run(
                grating_config(GratingRender::PositionPhase),
                traj,
                d,
                2.0,
                seed,
            );
            let (worst, bursts, ridges) = placement(&r);
            let case = format!("{mm_s} mm/s, seed {seed}");
            eprintln!(
                "position phase {case}: {bursts} bursts / {ridges} ridges, worst {worst:.1} µm"
            );
            assert!(worst <= LAMBDA_UM / 20.0, "{case}: worst {worst} µm");
            assert!(
                worst <= STATED_WORST_UM,
                "{case}: worst {worst} µm, docs say ≤ {STATED_WORST_UM}"
            );
            // 20 mm each way over λ = 1 mm: 40 ridges, every one fired once.
            assert_eq!(ridges, 40, "{case}");
            assert_eq!(bursts as u64, ridges, "{case}: one burst per ridge");
            assert_eq!(r.telemetry.ridges_skipped, 0);
            assert_eq!(r.timer_protocol_errors, 0);
            if worst >= worst_all.0 {
                worst_all = (worst, case);
            }
            runs += 1;
        }

        // The same motion through velocity synthesis: right frequency, free phase.
        let (traj, d) = stroke(mm_s * 1_000.0);
        let r = run(
            grating_config(GratingRender::VelocitySynthesis),
            traj,
            d,
            2.0,
            SEEDS.start,
        );
        let (worst, bursts, ridges) = placement(&r);
        eprintln!(
            "velocity synthesis {mm_s} mm/s: {bursts} / {ridges} ridges, worst {worst:.1} µm"
        );
        assert!(
            worst > LAMBDA_UM / 20.0,
            "{mm_s} mm/s: synthesis placed within λ/20?"
        );
    }
    eprintln!(
        "position phase, {runs} strokes: worst {:.1} µm ({})",
        worst_all.0, worst_all.1
    );
}

/// 0 bursts in 10 s at rest on a ridge with 3 LSB: position phase (the default) on three noise
/// seeds, velocity synthesis (15 mm/s start threshold) on the first.
#[test]
fn ten_seconds_at_rest_on_a_ridge_fire_nothing() {
    for (render, seed) in [
        (GratingRender::PositionPhase, 77),
        (GratingRender::PositionPhase, 78),
        (GratingRender::PositionPhase, 79),
        (GratingRender::VelocitySynthesis, 77),
    ] {
        let rest = Trajectory::Rest { at_um: 30_000.0 };
        let r = run(grating_config(render), rest, 10.0, 3.0, seed);
        // The reading really does cross the ridge back and forth (the test is not vacuous).
        let below = r
            .trace
            .iter()
            .filter(|t| t.meas_um.is_some_and(|m| m < 30_000))
            .count();
        assert!(
            below > 20_000 && below < 80_000,
            "{render:?}, seed {seed}: {below} below"
        );
        assert!(
            r.waveform.edges.is_empty(),
            "{render:?}, seed {seed}: {} edges",
            r.waveform.edges.len()
        );
    }
}

/// λ = 0.1 mm at 0.6 m/s: 6 kHz of ridges, above half the 10 kHz sample rate and three times the
/// F446 board's 2 kHz limit. Position phase pulses at most every 0.5 ms, never shorter than
/// a 2 kHz burst, counts every ridge it could not pulse, and keeps the duty cap between every
/// pair of pulses; velocity synthesis is clamped to 2 kHz.
#[test]
fn ridges_faster_than_the_board_stay_inside_the_caps() {
    let traj = Trajectory::Triangle {
        a_um: 10_000.0,
        b_um: 40_000.0,
        speed_um_s: 600_000.0,
    };
    let mut cfg = grating_config(GratingRender::PositionPhase);
    cfg.scene.textures[0] = Texture::Grating(Grating::new(100));
    let r = run(cfg.clone(), traj.clone(), 0.2, 2.0, 5);
    let clock = r.waveform.clock_hz as f64;
    let cap = cfg.limits.max_duty_permille as f64 / 1000.0;
    let pulses = r.waveform.pulses();
    assert!(pulses.len() > 50, "{}", pulses.len());
    for p in &pulses {
        let on_s = p.on() as f64 / clock;
        assert!(
            on_s >= 0.4 / 2_000.0 - 1e-6,
            "pulse {on_s} s shorter than a 2 kHz burst"
        );
        assert!(on_s * 1e6 <= cfg.limits.max_on_time_us as f64);
        if let Some(period) = p.period() {
            let period_s = period as f64 / clock;
            assert!(
                period_s >= 1.0 / 2_000.0 - 1e-6,
                "pulses {period_s} s apart"
            );
            assert!(
                on_s / period_s <= cap + 1e-9,
                "duty {} over a pulse",
                on_s / period_s
            );
        }
    }
    let t = r.telemetry;
    let ridges = metrics::ridges_crossed(&r, 100.0);
    eprintln!(
        "{} pulses, {} skipped, {ridges} ridges",
        t.ridge_pulses, t.ridges_skipped
    );
    assert_eq!(
        t.ridge_pulses as usize,
        pulses.len() + usize::from(r.waveform.level_at(r.waveform.end))
    );
    // Every ridge pulsed or counted, give or take the few the noise dithers over at the turns.
    let seen = (t.ridge_pulses + t.ridges_skipped) as i64;
    assert!(
        (seen - ridges as i64).abs() <= 10,
        "{seen} seen, {ridges} crossed"
    );
    assert!(t.ridges_skipped as u64 > ridges / 2);
    assert_eq!(r.timer_protocol_errors, 0);

    let mut cfg = grating_config(GratingRender::VelocitySynthesis);
    cfg.scene.textures[0] = Texture::Grating(Grating {
        render: GratingRender::VelocitySynthesis,
        ..Grating::new(100)
    });
    let r = run(cfg, traj, 0.2, 2.0, 5);
    let fastest = r
        .waveform
        .pulses()
        .iter()
        .filter_map(|p| p.period())
        .min()
        .unwrap();
    assert!(fastest as f64 / clock >= 1.0 / 2_000.0 - 1e-6);
    assert!(r.telemetry.clamped > 0);
}

/// A rail in the middle of a stroke: the line is low from the fault's first sample until the
/// sensor has recovered, whatever pulse was running.
#[test]
fn a_rail_mid_stroke_cuts_the_grating() {
    let traj = Trajectory::Constant {
        from_um: 10_500.0,
        speed_um_s: 100_000.0,
    };
    // 20 ms of open wiper starting 0.1 ms after the ridge at 20 mm (t = 95 ms).
    // The rail's timing was chosen on this noise stream (a ridge pulse running at 95.05 ms).
    let p = SimParams::new(&NUCLEO_F446RE, traj, 0.3)
        .with_reference_noise()
        .with_config(grating_config(GratingRender::PositionPhase))
        .with_faults(vec![FaultWindow {
            kind: FaultKind::Open,
            start_us: 95_100,
            end_us: 115_100,
        }]);
    let r = sim::run(&p).unwrap();
    let clk = |us: f64| r.waveform.us_to_clocks(us);
    assert!(
        r.waveform.level_at(clk(95_050.0)),
        "a pulse was running when the rail came"
    );
    assert!(!r.waveform.high_within(clk(95_200.0), clk(115_100.0)));
    assert_eq!(r.telemetry.faults, 1);
    // After the fault the ridges come back.
    assert!(!r
        .waveform
        .rises_in(clk(120_000.0), clk(300_000.0))
        .is_empty());
}

/// The duty window the docs state for the default caps (docs/duty-window.md): 300 ms, in which
/// the line may be on for at most 50 %.
const WINDOW_S: f64 = 0.3;

/// Checks the recorded line against the caps, from its edges alone: every pulse within the
/// on-time cap, and the on-time in every 300 ms window (ending at every fall and starting at
/// every rise: a window's on-time is largest with an end there) within the duty cap. No burst
/// runs here (position phase fires one-pulses), so no window has the timer's allowance.
/// Returns the highest windowed duty seen.
fn windowed_duty(r: &SimResult, cfg: &saw_core::Config, case: &str) -> f64 {
    let clock = r.waveform.clock_hz as f64;
    let pulses = r.waveform.pulses();
    let max_on = cfg.limits.max_on_time_us as u64 * r.waveform.clock_hz as u64 / 1_000_000;
    for p in &pulses {
        assert!(p.on() <= max_on, "{case}: a pulse on for {} clocks", p.on());
    }
    let window = (WINDOW_S * clock) as u64;
    let on_within = |a: u64, b: u64| -> u64 {
        pulses
            .iter()
            .map(|p| p.fall.min(b).saturating_sub(p.rise.max(a)))
            .sum()
    };
    let mut worst = 0.0f64;
    for p in &pulses {
        for (a, b) in [
            (p.fall.saturating_sub(window), p.fall),
            (p.rise, p.rise + window),
        ] {
            let on = on_within(a, b);
            assert!(
                on * 1000 <= window * cfg.limits.max_duty_permille as u64,
                "{case}: {on} clocks on in the window {a}..{b} clocks"
            );
            worst = worst.max(on as f64 / window as f64);
        }
    }
    worst
}

/// 20 mm/s from 10.5 mm to `step_um`, then 200 mm/s to 38.5 mm: the step a slow ridge
/// crossing (20 ms pulse at λ = 1 mm, 40 %) followed by a fast stroke makes, ending half a
/// period past the last ridge so its pulse is whole. Returns the trajectory and its duration.
fn step(step_um: f64) -> (Trajectory, f64) {
    let slow_s = (step_um - 10_500.0) / 20_000.0;
    let fast_s = (38_500.0 - step_um) / 200_000.0;
    let pieces = vec![
        Piece {
            trajectory: Trajectory::Constant {
                from_um: 10_500.0,
                speed_um_s: 20_000.0,
            },
            duration_s: slow_s,
        },
        Piece {
            trajectory: Trajectory::Constant {
                from_um: step_um,
                speed_um_s: 200_000.0,
            },
            duration_s: fast_s,
        },
    ];
    (Trajectory::Piecewise { pieces }, slow_s + fast_s)
}

/// Issue #17: a 20 → 200 mm/s step at λ = 1 mm — 4 ridges at 20 mm/s (20 ms pulses), then 24
/// at 200 mm/s — skips no ridge, over step points across the slow ridge's cell (the worst, the
/// step right after a slow pulse, is 14.4–14.5 mm) and 2 LSB noise seeds; one pulse per ridge
/// crossed, every 300 ms window within 50 %, every pulse within 50 ms. Under the per-pulse rule
/// (main before #17) the 20 ms rest after the last slow pulse skipped the ~3 ridges the fast
/// stroke crosses in it.
#[test]
fn a_slow_to_fast_step_skips_no_ridge() {
    let cfg = grating_config(GratingRender::PositionPhase);
    let mut worst = (0.0f64, String::new());
    for step_um in [14_200.0, 14_400.0, 14_450.0, 14_500.0, 14_700.0] {
        for seed in 0..6 {
            let (traj, d) = step(step_um);
            let r = run(cfg.clone(), traj, d, 2.0, seed);
            let case = format!("step at {step_um} µm, seed {seed}");
            let ridges = metrics::ridges_crossed(&r, LAMBDA_UM);
            let bursts = r.waveform.pulses().len() as u64;
            let duty = windowed_duty(&r, &cfg, &case);
            eprintln!(
                "{case}: {bursts} bursts / {ridges} ridges, {} skipped, windowed duty {:.1} %",
                r.telemetry.ridges_skipped,
                duty * 100.0
            );
            assert_eq!(ridges, 28, "{case}");
            assert_eq!(r.telemetry.ridges_skipped, 0, "{case}");
            assert_eq!(bursts, ridges, "{case}: one burst per ridge");
            assert_eq!(r.timer_protocol_errors, 0);
            if duty > worst.0 {
                worst = (duty, case);
            }
        }
    }
    eprintln!("worst windowed duty {:.1} % ({})", worst.0 * 100.0, worst.1);
}

/// The bench's mixed motion (rest, slow sine to 21 mm/s, fast sine to 300 mm/s; λ = 1 mm):
/// no ridge skipped (the per-pulse rule skipped 2 of 190 on the bench's reference stream),
/// every window within the cap, every pulse within the on-time cap; on the reference stream
/// and on 2 LSB noise seeds.
#[test]
fn the_mixed_motion_skips_no_ridge() {
    let cfg = grating_config(GratingRender::PositionPhase);
    let (traj, d) = host_sim::bench::scenario::mixed();
    let reference = SimParams::new(&NUCLEO_F446RE, traj.clone(), d)
        .with_config(cfg.clone())
        .with_noise(2.0, 0)
        .with_reference_noise();
    let mut runs = vec![(
        "reference stream".to_string(),
        sim::run(&reference).unwrap(),
    )];
    for seed in 0..4 {
        runs.push((
            format!("seed {seed}"),
            run(cfg.clone(), traj.clone(), d, 2.0, seed),
        ));
    }
    for (case, r) in runs {
        let ridges = metrics::ridges_crossed(&r, LAMBDA_UM);
        let bursts = r.waveform.pulses().len() as u64;
        let duty = windowed_duty(&r, &cfg, &case);
        eprintln!(
            "mixed, {case}: {bursts} bursts / {ridges} ridges, {} skipped, windowed duty {:.1} %",
            r.telemetry.ridges_skipped,
            duty * 100.0
        );
        assert_eq!(r.telemetry.ridges_skipped, 0, "{case}");
        assert!(ridges >= 180, "{case}: {ridges} ridges");
        assert_eq!(r.timer_protocol_errors, 0);
    }
}
