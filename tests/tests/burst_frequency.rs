//! Produced burst frequency within ±0.1 % of commanded across 1 Hz – 2 kHz, measured from the
//! timer model's edges, on both boards' burst timers and a 16-bit one (prescaler path).
//!
//! README.md states the measured worst error, 7 ppm (7.1 ppm, on the 16-bit timer at
//! 23.737 Hz). It is asserted at ≤ 7.5 ppm: the figure is deterministic (no noise, no seed), and
//! the 0.4 ppm margin only covers the rounding of the stated figure, so a change that makes any
//! frequency coarser fails here.

use host_sim::timer::TimerModel;
use saw_core::burst::{BurstCommand, BurstTimer};
use saw_core::texture::Texture;
use saw_core::Controller;
use saw_tests::{feed, log_sweep_millihz, timers};

/// Runs a one-region scene at `millihz` through the controller at rest for `periods` whole burst
/// periods (at least 20 ms) and returns the frequency measured from the rising edges.
fn produced_hz(timer: BurstTimer, millihz: u32, periods: u32) -> f64 {
    let mut cfg = saw_core::default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    cfg.scene
        .textures
        .push(Texture::Constant(BurstCommand {
            burst_millihz: millihz,
            duty_permille: 400,
        }))
        .unwrap();
    let mut ctrl = Controller::new(timer, 100).unwrap();
    ctrl.load(&cfg).unwrap();
    let code = ctrl.mapper().unwrap().code_at_um(30_000.0) as u16;
    let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, true);
    let duration_us = ((periods as f64 + 0.5) * 1e9 / millihz as f64).max(20_000.0) as u64;
    let clk = |t_us: u64| t_us * timer.clock_hz as u64 / 1_000_000;
    let mut t_us = 0u64;
    while t_us < duration_us {
        feed(&mut ctrl, &mut tm, code, t_us);
        t_us += 100;
    }
    let w = tm.finish(clk(duration_us));
    assert!(
        w.rises_in(0, w.end).len() > periods as usize,
        "{millihz} mHz: too few edges"
    );
    w.measured_hz(0, w.end).unwrap()
}

/// Worst error asserted, ppm (README: "worst error 7 ppm", measured 7.1).
const STATED_WORST_PPM: f64 = 7.5;

#[test]
fn burst_frequency_within_0_1_percent_from_1_hz_to_2_khz() {
    let sweep = log_sweep_millihz(25);
    assert_eq!(sweep.first(), Some(&1_000));
    assert_eq!(sweep.last(), Some(&2_000_000));
    let mut worst = (0.0f64, String::new());
    for (name, timer) in timers() {
        for &mhz in &sweep {
            let want = mhz as f64 / 1000.0;
            // Two periods at 1 Hz, more at higher f_b (≥ 20 ms of edges).
            let got = produced_hz(timer, mhz, 2);
            let err = (got - want) / want * 100.0;
            assert!(
                err.abs() <= 0.1,
                "{name}: {want} Hz commanded, {got} Hz produced ({err:+.4} %)"
            );
            assert!(
                err.abs() * 1e4 <= STATED_WORST_PPM,
                "{name}: {want} Hz commanded, {got} Hz produced ({:+.2} ppm, README states ≤ 7)",
                err * 1e4
            );
            if err.abs() >= worst.0 {
                worst = (err.abs(), format!("{name} at {want} Hz: {got:.6} Hz"));
            }
        }
    }
    eprintln!(
        "worst f_b error over {} frequencies × 3 timers: {:.2} ppm ({})",
        sweep.len(),
        worst.0 * 1e4,
        worst.1
    );
}
