//! The metrics minute by minute (`Metrics::minutes`, what a long run's chart draws) and the
//! tangible lines' pulses kept apart from the regions' bursts, against figures worked out by hand
//! from a run written out sample by sample and edge by edge: no simulator in the way, so every
//! expected number below follows from the scene and the edges the test itself lays down.
//!
//! The run: 120 s sampled every 100 µs (a 1 MHz kernel clock, so clocks are µs). Two constant
//! regions split at 30 mm: 100 Hz, 40 % (on 4 ms of 10) and 50 Hz, 40 % (8 ms of 20); one line at
//! 40 mm. The finger rests at 10 mm (region 0) until 90 s, then at 50 mm (region 1): one switch,
//! 20 mm past its boundary. A rail fault from 61.0 to 61.5 s (5000 samples): no region, no
//! estimate, no bursts. The estimate is 1 mm/s off the (zero) true velocity in the first minute,
//! 2 mm/s in the second. Rises come 50 µs after a sample, so the sample before each is the one
//! whose region it latched. At 100 s the core fires the line: the rise at 100.00005 s is the
//! line's pulse (5 ms) instead of a region-1 burst.

use host_sim::metrics::{Metrics, Online};
use host_sim::sim::{self, SimParams, TracePoint};
use host_sim::timer::Edge;
use host_sim::trajectory::Trajectory;
use saw_core::burst::TimerSettings;
use saw_core::gate::GateAction;
use saw_core::position::SensorFault;

const SCENE: &str = r#"
drive = "standing"
hysteresis_mm = 0.1

[substrate]
length_mm = 63.0
code_at_start = 1310
code_at_end = 64225

[limits]
max_duty_percent = 50
max_on_time_ms = 50
stale_after_ms = 5

[[region]]
kind = "constant"
until_mm = 30
f_b_hz = 100
duty_percent = 40

[[region]]
kind = "constant"
f_b_hz = 50
duty_percent = 40

[lines]
positions_mm = [40]
pulse_ms = 5
envelope = "rectangle"
amplitude_percent = 100
rearm_mm = 0.2
"#;

/// µs of the run's events.
const END_US: u64 = 120_000_000;
const SWITCH_US: u64 = 90_000_000;
const FAULT_US: (u64, u64) = (61_000_000, 61_500_000);
const LINE_US: u64 = 100_000_000;
const PERIOD_US: u64 = 100;

/// The run's figures: every sample and edge fed to the online metrics.
fn run() -> Metrics {
    let board = &saw_boards::NUCLEO_F446RE;
    let config = saw_core::scene_file::load_for_board(
        "minutes.toml",
        SCENE,
        sim::burst_timer(board),
        sim::sample_period_us(board),
    )
    .unwrap();
    let params =
        SimParams::new(board, Trajectory::Rest { at_um: 10_000.0 }, 120.0).with_config(config);
    let mut m = Online::new(&params, 1_000_000, PERIOD_US as u32, &[]);

    // The gate's edges, as the timer would have made them.
    let mut edges = Vec::new();
    let mut burst = |rise: u64, on: u64| {
        edges.push(Edge {
            t: rise,
            high: true,
        });
        edges.push(Edge {
            t: rise + on,
            high: false,
        });
    };
    let mut t = 50;
    while t < SWITCH_US {
        if !(FAULT_US.0..FAULT_US.1).contains(&t) {
            burst(t, 4_000);
        }
        t += 10_000;
    }
    let mut t = SWITCH_US + 50;
    while t < END_US {
        burst(t, if t == LINE_US + 50 { 5_000 } else { 8_000 });
        t += 20_000;
    }
    m.edges(&edges);

    let line_pulse = TimerSettings {
        psc: 0,
        arr: 4_999,
        ccr: 5_000,
    };
    for k in 0..END_US / PERIOD_US {
        let t_us = k * PERIOD_US;
        let fault = (FAULT_US.0..FAULT_US.1).contains(&t_us);
        let here_um = if t_us < SWITCH_US { 10_000.0 } else { 50_000.0 };
        let off_by_um_s = if t_us < 60_000_000 { 1_000 } else { 2_000 };
        let fires = t_us == LINE_US;
        m.point(&TracePoint {
            t_us,
            true_um: here_um,
            true_vel_um_s: 0.0,
            sampled: true,
            code: None,
            meas_um: (!fault).then_some(here_um as i32),
            est_vel_um_s: (!fault).then_some(off_by_um_s),
            region: (!fault).then_some(u8::from(t_us >= SWITCH_US)),
            gate: false,
            fault: fault.then_some(SensorFault::RailLow),
            action: fires.then_some(GateAction::Pulse(line_pulse)),
            line: fires.then_some(0),
        });
    }
    m.finish()
}

fn close(got: Option<f64>, want: f64, tol: f64, what: &str) {
    let g = got.unwrap_or_else(|| panic!("{what}: none, expected {want}"));
    assert!((g - want).abs() <= tol, "{what}: {g}, expected {want}");
}

/// Minute by minute: bursts and f_b per region, the line's pulse on its own, the switch and how
/// far past, the fault, the velocity error.
#[test]
fn minute_figures_by_hand() {
    let m = run();
    assert_eq!(m.minutes.len(), 2);
    let (a, b) = (&m.minutes[0], &m.minutes[1]);

    // Minute 0: region 0 alone, rises at 0.00005 s … 59.99005 s: 6000 of them, every one
    // followed by the next in the same region (the 6000th by the one at 60.00005 s).
    assert_eq!((a.start_s, a.span_s), (0.0, 60.0));
    assert_eq!(a.samples, 600_000);
    assert_eq!(a.regions[0].pulses, 6_000);
    assert_eq!(a.regions[0].intervals, 6_000);
    close(
        a.regions[0].produced_hz,
        100.0,
        1e-9,
        "minute 0, region 0 f_b",
    );
    close(
        Some(a.regions[0].time_s),
        60.0,
        1e-9,
        "minute 0, region 0 time",
    );
    assert_eq!(a.regions[1].pulses, 0);
    assert_eq!(a.regions[1].produced_hz, None);
    assert_eq!((a.switches, a.switch_past_um), (0, None));
    assert_eq!((a.fault_onsets, a.fault_samples), (0, 0));
    assert_eq!(a.line_pulses, 0);
    close(
        a.velocity_rms_um_s,
        1_000.0,
        0.1,
        "minute 0, velocity error",
    );

    // Minute 1: region 0 from 60 to 61 s (100 rises) and from 61.5 to 90 s (2850); region 1
    // from 90 to 120 s at 50 Hz, 1500 rises less the one that was the line's pulse.
    assert_eq!((b.start_s, b.span_s), (60.0, 60.0));
    assert_eq!(b.regions[0].pulses, 100 + 2_850);
    close(
        b.regions[0].produced_hz,
        100.0,
        1e-9,
        "minute 1, region 0 f_b",
    );
    close(
        Some(b.regions[0].time_s),
        29.5,
        1e-9,
        "minute 1, region 0 time",
    );
    assert_eq!(b.regions[1].pulses, 1_499);
    close(
        b.regions[1].produced_hz,
        50.0,
        1e-9,
        "minute 1, region 1 f_b",
    );
    close(
        Some(b.regions[1].time_s),
        30.0,
        1e-9,
        "minute 1, region 1 time",
    );
    assert_eq!(b.line_pulses, 1);
    assert_eq!(b.switches, 1);
    assert_eq!(b.switch_past_um, Some((20_000.0, 20_000.0)));
    assert_eq!((b.fault_onsets, b.fault_samples), (1, 5_000));
    close(
        b.velocity_rms_um_s,
        2_000.0,
        0.2,
        "minute 1, velocity error",
    );
    // The true velocity is zero throughout: every lag fits as well, the first is the delay.
    close(
        b.velocity_rms_at_delay_um_s,
        2_000.0,
        0.2,
        "minute 1, velocity error at the delay",
    );

    // The whole run's figures are the minutes' together.
    assert_eq!(m.regions[0].pulses, 6_000 + 2_950);
    assert_eq!(m.regions[1].pulses, 1_499);
    assert_eq!(m.line_pulses, vec![1]);
    assert_eq!(
        (m.switch_count, m.fault_onsets, m.fault_samples),
        (1, 1, 5_000)
    );
}
