//! Virtual gratings through the whole closed loop (rheostat/ADC model, default estimator, gate,
//! timer model): the default position-phase renderer puts its bursts within λ/20 of the ridges at
//! 20–200 mm/s both ways, velocity synthesis does not; neither fires at rest; and where they
//! fail — ridges faster than the board or than half the sample rate, a rail mid-stroke — the
//! line stays inside its caps and goes off.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::bench::renderers::grating_config;
use host_sim::metrics;
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::trajectory::Trajectory;
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
