//! The carrier caps hold on the recorded waveform over a seeded random-scene fuzz of the closed
//! loop (host_sim::sim: trajectory → ADC model → Controller → burst-timer model).
//!
//! Scenes: 1–8 regions at random boundaries, each of every texture kind — off, constant, grating
//! rendered by position phase and by velocity synthesis, material, random — random duties up to
//! the cap, random caps, tangible lines with triangle or rectangle envelopes, both drive modes
//! (the mode only picks the IDTs: the enable line recorded here must keep the caps in either).
//! Random trajectories (rest, strokes, sines, reversals, ramps, pieces of them), ADC noise, and
//! sensor faults (open wiper, short to the supply, dropouts long enough to trip the stale
//! watchdog or not).
//!
//! On the enable line the timer model recorded, every pulse is checked against the caps the
//! scene was given: on-time ≤ the on-time cap, and the on-time in every duty window (300 ms, or
//! on-time cap / duty cap when longer: docs/duty-window.md) ≤ the duty cap × the window (a window
//! inside one periodic run: plus the timer's partial period), in kernel clocks, whatever produced
//! the pulses (burst periods, restarts after an Off, ridge or line one-pulses). The line must be low from the first sample at a rail (or from a
//! sample period after the stale limit of silence) until the 16th good sample after it: the
//! fault windows the harness injected are the reference, not the core's own fault report.
//! Each seed also counts pulses per texture kind and asserts every kind produced some, so the
//! fuzz cannot quietly shrink back to the easy cases. The generators live in
//! `host_sim::soak::gen`, shared with `host-sim soak`, which runs the same rules online for
//! hours of simulated use.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::soak::gen::{random_config, random_faults, random_trajectory};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::controller::RECOVERY_SAMPLES;
use saw_core::gate::GateAction;
use saw_core::texture::{GratingRender, Texture};
use saw_core::Config;

/// Texture kinds as counted in the coverage tally.
const KINDS: [&str; 6] = [
    "constant",
    "grating-position",
    "grating-velocity",
    "material",
    "random",
    "lines",
];

fn kind_of(t: &Texture) -> Option<usize> {
    Some(match t {
        Texture::Constant(_) => 0,
        Texture::Grating(g) if g.render == GratingRender::PositionPhase => 1,
        Texture::Grating(_) => 2,
        Texture::Material(_) => 3,
        Texture::Random(_) => 4,
        _ => return None,
    })
}

/// Sample periods `[k·P, (k+1)·P)` in which the line must be low, from the injected faults as
/// the README states the rules: a sample at either rail turns the carrier off on that sample;
/// silence longer than the stale limit turns it off (by the watchdog tick, so at the latest one
/// sample period after the limit); it comes back only on the 16th good sample after.
fn must_be_off(r: &SimResult, faults: &[FaultWindow], stale_after_us: u32) -> Vec<(u64, u64)> {
    let p = r.sample_period_us as u64;
    let n = r.trace.len() as u64;
    let mut spans: Vec<(u64, u64)> = Vec::new();
    let mut last_sample: Option<u64> = None;
    // Good samples still owed before the line may go on again; None when no fault is in force.
    let mut recovering: Option<u16> = None;
    for k in 0..n {
        let t = k * p;
        // The first listed window wins in the ADC model: a dropout listed after a rail window
        // that also covers t is not a dropout.
        let first = faults.iter().find(|f| f.contains(t)).map(|f| f.kind);
        let off = match first {
            Some(FaultKind::Open | FaultKind::Short) => {
                last_sample = Some(t);
                recovering = Some(RECOVERY_SAMPLES - 1);
                true
            }
            Some(FaultKind::Dropout) => {
                // Silent past the stale limit: the watchdog has fired. (Left alone when a fault
                // is already in force: whether the core restarts its count then is not a rule.)
                if recovering.is_none()
                    && last_sample.is_some_and(|l| t >= l + stale_after_us as u64 + p)
                {
                    recovering = Some(RECOVERY_SAMPLES - 1);
                }
                recovering.is_some()
            }
            // The fuzz injects no offsets; were one here, it would read as a good sample.
            None | Some(FaultKind::Spike { .. } | FaultKind::Drift { .. }) => {
                last_sample = Some(t);
                match recovering {
                    Some(0) | None => {
                        recovering = None;
                        false
                    }
                    Some(m) => {
                        // The (16 − m)-th good sample: still off.
                        recovering = Some(m - 1);
                        true
                    }
                }
            }
        };
        if off {
            match spans.last_mut() {
                Some(s) if s.1 == t => s.1 = t + p,
                _ => spans.push((t, t + p)),
            }
        }
    }
    spans
}

#[derive(Default)]
struct Tally {
    loaded: usize,
    rejected: usize,
    pulses: usize,
    /// Pulses by [`KINDS`]: bursts by the region under the finger at the rise, ridge and line
    /// one-pulses from the controller's counters.
    by_kind: [usize; 6],
    /// Fault spans checked, and the sample periods they cover.
    off_spans: usize,
    off_periods: u64,
    /// Off spans that began while the line was running or pulsing (the fault had to cut it).
    cut: usize,
    worst_duty: f64,
    worst_on: f64,
}

fn check_run(case: usize, cfg: &Config, faults: &[FaultWindow], r: &SimResult, tally: &mut Tally) {
    assert_eq!(r.timer_protocol_errors, 0, "case {case}");
    let clock = r.timer.clock_hz as u64;
    let max_on = cfg.limits.max_on_time_us as u64 * clock / 1_000_000;
    let cap = cfg.limits.max_duty_permille as u64;
    for pl in r.waveform.pulses() {
        tally.pulses += 1;
        assert!(
            pl.on() <= max_on,
            "case {case}: pulse at {} clocks on for {} clocks > on-time cap {max_on}",
            pl.rise,
            pl.on()
        );
        tally.worst_on = tally.worst_on.max(pl.on() as f64 / max_on as f64);
        // Bursts by the region under the finger; ridge and line one-pulses are counted below,
        // from the controller.
        let at = r.trace_at_clock(pl.rise);
        if at.is_some_and(|t| matches!(t.action, Some(GateAction::Pulse(_)))) {
            continue;
        }
        if let Some(k) = at
            .and_then(|t| t.region)
            .and_then(|i| cfg.scene.textures.get(i as usize))
            .and_then(kind_of)
        {
            tally.by_kind[k] += 1;
        }
    }
    let starts: Vec<(u64, bool)> = r
        .trace
        .iter()
        .filter_map(|t| match t.action {
            Some(GateAction::Start(_)) => Some((r.clocks(t.t_us), true)),
            Some(GateAction::Pulse(_)) => Some((r.clocks(t.t_us), false)),
            _ => None,
        })
        .collect();
    let pulses: Vec<(u64, u64)> = r
        .waveform
        .pulses()
        .iter()
        .map(|p| (p.rise, p.fall))
        .collect();
    let window = r.clocks(saw_tests::stated_window_us(
        cap,
        cfg.limits.max_on_time_us as u64,
    ));
    match saw_tests::windowed_duty(&saw_tests::on_times(&pulses, &starts), cap, window) {
        Ok(worst) => tally.worst_duty = tally.worst_duty.max(worst),
        Err(e) => panic!("case {case}: {e}"),
    }
    tally.by_kind[1] += r.telemetry.ridge_pulses as usize;
    tally.by_kind[5] += r.telemetry.line_pulses as usize;

    for (from, to) in must_be_off(r, faults, cfg.stale_after_us) {
        let (a, b) = (r.clocks(from), r.clocks(to));
        assert!(
            !r.waveform.high_within(a, b),
            "case {case}: line high during a sensor fault, {from}..{to} µs ({faults:?})"
        );
        tally.off_spans += 1;
        tally.off_periods += (to - from) / r.sample_period_us as u64;
        if a > 0 && r.waveform.high_within(a.saturating_sub(clock / 1_000), a) {
            tally.cut += 1;
        }
    }
    // The core's own report agrees: no sample period ends with a fault and the line high.
    for t in &r.trace {
        assert!(
            !(t.fault.is_some() && t.gate),
            "case {case}: line high at {} µs with fault {:?}",
            t.t_us,
            t.fault
        );
    }
}

fn fuzz(seed: u64, cases: usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut tally = Tally::default();
    let duration_s = 0.4;
    for case in 0..cases {
        let board = &saw_boards::ALL[case % saw_boards::ALL.len()];
        let cfg = random_config(&mut rng, board.max_burst_hz);
        // The draws keep their order (scene, trajectory, faults, noise, its seed): a seed's cases
        // stay the same.
        let trajectory = random_trajectory(&mut rng);
        let faults = random_faults(&mut rng, (duration_s * 1e6) as u64);
        let p = SimParams::new(board, trajectory, duration_s)
            .with_config(cfg.clone())
            .with_faults(faults.clone())
            .with_noise(rng.random_range(0.0..4.0), rng.random());
        let r = match sim::run(&p) {
            Ok(r) => r,
            Err(sim::SimError::Config(_)) => {
                tally.rejected += 1;
                continue;
            }
            Err(e) => panic!("seed {seed:#x} case {case}: {e}"),
        };
        tally.loaded += 1;
        check_run(case, &cfg, &faults, &r, &mut tally);
    }
    let t = &tally;
    eprintln!(
        "seed {seed:#x}: {} scenes run, {} rejected at load, {} pulses \
         (constant, ridge, velocity grating, material, random, line: {:?}); \
         worst on-time {:.4} of cap, worst duty {:.4} of cap; \
         {} fault spans ({} sample periods, {} cutting a live line) kept low",
        t.loaded,
        t.rejected,
        t.pulses,
        t.by_kind,
        t.worst_on,
        t.worst_duty,
        t.off_spans,
        t.off_periods,
        t.cut
    );
    assert!(
        t.loaded >= cases / 2 && t.pulses > 500,
        "{} scenes, {} pulses",
        t.loaded,
        t.pulses
    );
    for (k, name) in KINDS.iter().enumerate() {
        assert!(
            t.by_kind[k] >= 15,
            "seed {seed:#x}: only {} pulses from {name} regions: the fuzz no longer covers it",
            t.by_kind[k]
        );
    }
    assert!(
        t.off_spans >= 10 && t.cut >= 2,
        "seed {seed:#x}: {} fault spans, {} cutting a live line",
        t.off_spans,
        t.cut
    );
    // Caps reached, not merely respected from afar. (A duty window fills less than a single
    // period did: seed 1's fullest window holds 86 % of its cap, the others 97 and 101 % — above
    // 100 % only inside one periodic run, the timer's partial period.)
    assert!(
        t.worst_duty > 0.85 && t.worst_on > 0.9,
        "{} {}",
        t.worst_duty,
        t.worst_on
    );
}

#[test]
fn caps_hold_on_the_waveform_seed_1() {
    fuzz(0xCA95, 60);
}

#[test]
fn caps_hold_on_the_waveform_seed_2() {
    fuzz(0x5A3D_0002, 60);
}

#[test]
fn caps_hold_on_the_waveform_seed_3() {
    fuzz(0x5A3D_0003, 60);
}

/// Core issue found by the fuzz above: after an Off (sensor fault, or a region with texture Off)
/// the next Start restarts the counter at once, so a pulse that had already delivered its full
/// on-time is followed by a new one less than a period later: on-time / rise-to-rise exceeds the
/// duty cap (fuzz case: 24.85 ms on, next rise 29.1 ms later = 85 % against an 80.8 % cap, after
/// a 2.6 ms rail fault). The core needs a hold-off before a Start (e.g. not before the previous
/// period would have ended). Fixed in saw-core's gate: after an Off the line rested
/// on × (1000 − cap)/cap before it could start again; since issue #17 a Start waits until every
/// duty window holding the cut run and the new one fits the cap (docs/duty-window.md), which is
/// what is checked here.
#[test]
fn restart_after_off_respects_the_duty_cap() {
    let board = &saw_boards::NUCLEO_F446RE;
    let timer = sim::burst_timer(board);
    let mut ctrl = saw_core::Controller::new(timer, 100).unwrap();
    let cfg = saw_core::default_config();
    ctrl.load(&cfg).unwrap();
    let code = ctrl.mapper().unwrap().code_at_um(5_000.0) as u16;
    let mut tm = host_sim::timer::TimerModel::new(timer.clock_hz, timer.counter_bits, true);
    let clk = |t: u64| t * timer.clock_hz as u64 / 1_000_000;
    let mut t = 0u64;
    // 20 Hz, 40 %: 20 ms on, 30 ms off. A 1 ms rail blip right after the pulse, then good
    // samples: the restart comes ~3 ms after the fall instead of 30 ms.
    for k in 0..1_000u64 {
        let c = if (210..220).contains(&k) { 0 } else { code };
        saw_tests::feed(&mut ctrl, &mut tm, c, t);
        t += 100;
    }
    let w = tm.finish(clk(t));
    let cap = cfg.limits.max_duty_permille as u64;
    let pulses: Vec<(u64, u64)> = w.pulses().iter().map(|p| (p.rise, p.fall)).collect();
    let window = clk(saw_tests::stated_window_us(
        cap,
        cfg.limits.max_on_time_us as u64,
    ));
    // Start actions are not recorded here: every on-time counts as from its own source, so no
    // window gets the one-run allowance (stricter than the rule).
    let starts: Vec<(u64, bool)> = pulses.iter().map(|&(r, _)| (r, false)).collect();
    let on = saw_tests::on_times(&pulses, &starts);
    assert!(pulses.len() > 1);
    if let Err(e) = saw_tests::windowed_duty(&on, cap, window) {
        panic!("{e}");
    }
}
