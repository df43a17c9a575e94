//! Each board's own acquisition and velocity window in the closed loop (issue #35): the G474's
//! run shows the lag and noise the conversion budget gives its 32 conversions a sample and its
//! 26-sample window, the F446's run is the one every published figure comes from.
//!
//! The lag and noise are measured the way the budget measures them (`host_sim::budget`): the
//! estimator bench's lag probe (0.5 m/s² through 15–25 mm/s, 40 streams per seed) and two
//! 20 mm/s streams per seed, seeds 2026–2028, scored by `bench::measure::errors`; only here
//! the streams go through the whole closed loop (`sim::run`: the ADC model, the controller's
//! position mapper and estimator), not a replay.

use host_sim::adc::AdcParams;
use host_sim::bench::measure::{errors, pool, Errors};
use host_sim::bench::scenario::{self, Input, Obs};
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::trajectory::Trajectory;
use saw_boards::{BoardDef, NUCLEO_F446RE, NUCLEO_G474RE};

/// The budget's base seeds (`docs/conversion-budget.md`: seeds 2026–2028).
const SEEDS: [u64; 3] = [2026, 2027, 2028];
/// Lag-probe streams per seed (as the budget and the bench: 40).
const DELAY_STREAMS: u64 = 40;
/// 20 mm/s streams per seed (as the budget: 2).
const STEADY_STREAMS: u64 = 2;

/// The closed loop's trace as the bench's stream and estimates: true velocity and acceleration
/// per sample, the controller's estimate, scored where `scored` says.
fn scored(
    r: &SimResult,
    trajectory: &Trajectory,
    scored: impl Fn(f64, f64, f64) -> bool,
) -> Errors {
    let dt = r.sample_period_us as f64 * 1e-6;
    let (obs, out): (Vec<Obs>, Vec<Option<i32>>) = r
        .trace
        .iter()
        .map(|p| {
            let t_s = p.t_us as f64 * 1e-6;
            let a_true = (trajectory.state(t_s + dt / 2.0).velocity_um_s
                - trajectory.state((t_s - dt / 2.0).max(0.0)).velocity_um_s)
                / dt;
            let input = match p.meas_um {
                Some(x) => Input::Position(x),
                None if p.sampled => Input::Fault,
                None => Input::Dropped,
            };
            let o = Obs {
                t_us: p.t_us as u32,
                input,
                v_true: p.true_vel_um_s,
                a_true,
                scored: scored(t_s, p.true_vel_um_s, a_true),
            };
            (o, p.est_vel_um_s)
        })
        .unzip();
    errors(&obs, &out)
}

/// One seed's (lag ms, noise mm/s RMS) of `board`'s closed loop, with its ADC model `adc` (the
/// noise seed set per stream as the budget sets it).
fn figures(board: &'static BoardDef, adc: &AdcParams, seed: u64) -> (f64, f64) {
    let run = |trajectory: &Trajectory, d: f64, stream_seed: u64| {
        let mut p = SimParams::new(board, trajectory.clone(), d);
        p.adc = adc.clone().with_noise(adc.noise_lsb_rms, stream_seed);
        sim::run(&p).unwrap()
    };
    let (probe, d) = scenario::delay_probe();
    let delay: Vec<Errors> = (0..DELAY_STREAMS)
        .map(|i| {
            let r = run(&probe, d, seed.wrapping_mul(31).wrapping_add(200 + i));
            scored(&r, &probe, |_, v, a| {
                (15_000.0..=25_000.0).contains(&v) && a > 0.0
            })
        })
        .collect();
    let (steady, d) = scenario::constant(20_000.0);
    let noise: Vec<Errors> = (0..STEADY_STREAMS)
        .map(|i| {
            let r = run(&steady, d, seed.wrapping_mul(31).wrapping_add(640 + i));
            scored(&r, &steady, |t, _, _| t >= 0.05)
        })
        .collect();
    (pool(&delay).lag_us / 1e3, pool(&noise).rms_um_s / 1e3)
}

/// Per seed, then pooled: (mean lag, worst lag, RMS noise, worst noise).
fn over_seeds(board: &'static BoardDef, adc: &AdcParams) -> (Vec<(f64, f64)>, [f64; 4]) {
    let per: Vec<(f64, f64)> = SEEDS.iter().map(|&s| figures(board, adc, s)).collect();
    let n = per.len() as f64;
    let mean_lag = per.iter().map(|s| s.0).sum::<f64>() / n;
    let rms_noise = (per.iter().map(|s| s.1 * s.1).sum::<f64>() / n).sqrt();
    let worst_lag = per.iter().map(|s| s.0).fold(0.0, f64::max);
    let worst_noise = per.iter().map(|s| s.1).fold(0.0, f64::max);
    eprintln!(
        "{}: lag {mean_lag:.3} ms ({worst_lag:.3} worst seed), noise {rms_noise:.3} mm/s \
         ({worst_noise:.3} worst seed); per seed {per:?}",
        board.name
    );
    (per, [mean_lag, worst_lag, rms_noise, worst_noise])
}

/// The G474's closed loop runs its own acquisition (32 conversions a sample, halved to the
/// core's code) and window (26 samples), and shows the figures the conversion budget gives
/// them: `Median3<LsqSlope<26>>` on 32 × 47.5 cycles, lag 1.33 ms (1.34 worst seed), noise
/// 1.54 mm/s (1.58 worst seed) (`docs/conversion-budget.md`, "The pick"). Measured here: lag
/// 1.321 ms (1.331 worst seed), noise 1.538 mm/s (1.561 worst seed). Tolerance: ±0.03 ms of lag
/// and ±0.04 mm/s of noise, pooled and worst seed: the closed loop's ADC model has neither the
/// budget's 51.2 µs conversion window (a 25.6 µs share of its design lag) nor its 0.05 LSB noise
/// floor, as the F446's has neither; both are within these. Every seed stays under the
/// 1.66 mm/s bound with a fifth less lag than the F446's window gives.
#[test]
fn the_g474_closed_loop_shows_the_budgets_lag_and_noise() {
    let g474 = &NUCLEO_G474RE;
    let p = SimParams::new(g474, Trajectory::Rest { at_um: 0.0 }, 0.0);
    assert_eq!(p.adc.oversample, 32);
    assert_eq!(sim::board_estimator(g474).unwrap().window(), 26);
    let (per, [lag, worst_lag, noise, worst_noise]) = over_seeds(g474, &p.adc);
    assert!((lag - 1.33).abs() < 0.03, "lag {lag} ms");
    assert!((worst_lag - 1.34).abs() < 0.03, "worst lag {worst_lag} ms");
    assert!((noise - 1.54).abs() < 0.04, "noise {noise} mm/s");
    assert!(
        (worst_noise - 1.58).abs() < 0.04,
        "worst noise {worst_noise} mm/s"
    );
    for (lag, noise) in per {
        assert!(noise <= 1.66, "noise {noise} mm/s");
        assert!(lag <= 0.82 * 1.63, "lag {lag} ms");
    }
}

/// The G474's window on the F446's acquisition (16 conversions a sample) is too noisy: 2.18
/// mm/s (2.21 worst seed) against the 1.66 mm/s bound. So the figures above need the board's
/// own ADC model, and a run that fell back to the F446's would fail there.
#[test]
fn the_g474_window_needs_the_g474_acquisition() {
    let (_, [_, _, noise, _]) = over_seeds(&NUCLEO_G474RE, &AdcParams::default());
    assert!(noise > 2.1, "noise {noise} mm/s");
}

/// The F446's closed loop is the one before per-board runs: the default ADC model (16
/// conversions) and the core's default estimator (`DEFAULT_WINDOW`, 32), the same trace bit
/// for bit as `run_with` the default estimator, and the budget's F446 figures: lag 1.631 ms,
/// noise 1.625 mm/s (1.664 worst seed) here, 1.63 / 1.59 (1.66 worst seed) in the budget (whose
/// model adds the conversion window and the floor).
#[test]
fn the_f446_closed_loop_is_unchanged() {
    let f446 = &NUCLEO_F446RE;
    let p = SimParams::new(
        f446,
        Trajectory::Triangle {
            a_um: 1_500.0,
            b_um: 61_500.0,
            speed_um_s: 90_000.0,
        },
        0.5,
    )
    .with_noise(3.0, 7);
    assert_eq!(p.adc, AdcParams::default().with_noise(3.0, 7));
    let period_us = sim::sample_period_us(f446);
    let default = saw_core::velocity::Median3::new(
        saw_core::velocity::LsqSlope::<{ saw_core::controller::DEFAULT_WINDOW }>::new(period_us)
            .unwrap(),
        period_us,
    );
    let before = sim::run_with(&p, default).unwrap();
    let now = sim::run(&p).unwrap();
    assert_eq!(now.trace, before.trace);
    assert_eq!(now.waveform, before.waveform);
    let (_, [lag, _, noise, worst_noise]) = over_seeds(f446, &AdcParams::default());
    assert!((lag - 1.631).abs() < 0.0005, "lag {lag} ms");
    assert!((noise - 1.625).abs() < 0.0005, "noise {noise} mm/s");
    assert!(
        (worst_noise - 1.664).abs() < 0.0005,
        "worst noise {worst_noise} mm/s"
    );
}

/// Every board host-sim offers has a window it builds and a code of 16 conversions' scale.
#[test]
fn every_board_runs_its_own_window() {
    for board in saw_boards::ALL {
        let estimator = sim::board_estimator(board).unwrap();
        assert_eq!(estimator.window(), board.velocity_window);
        assert!(sim::BOARD_WINDOWS.contains(&board.velocity_window));
        assert_eq!(board.adc.oversampling.code_conversions(), Some(16));
        assert_eq!(
            AdcParams::for_board(board).oversample,
            board.adc.oversampling.conversions()
        );
    }
    let odd = BoardDef {
        velocity_window: 40,
        ..NUCLEO_G474RE
    };
    let e = sim::board_controller(&odd).err().unwrap();
    assert_eq!(
        e.to_string(),
        "the board's velocity window of 40 samples is not one host-sim builds ([26, 32])"
    );
}
