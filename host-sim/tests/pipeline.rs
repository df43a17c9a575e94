//! The plain run pipelined over two threads (`sim::stream_on` with 2: a feeder thread draws the
//! finger states and ADC samples ahead and feeds the metrics the points behind, the caller's
//! thread runs the controller, the timer model and the chart) against the same run on one
//! thread: the same figures, chart data, telemetry and sample callbacks, bit for bit, across
//! chunk ends, faults, lines, an action latency, the reference noise and a long run's chart.

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::sim::{self, SimParams};
use host_sim::trajectory::Trajectory;
use saw_core::Config;

fn scene(name: &str, board: &'static saw_boards::BoardDef) -> Config {
    let path = format!("{}/../scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    saw_core::scene_file::load_for_board(
        &path,
        &text,
        sim::burst_timer(board),
        sim::sample_period_us(board),
    )
    .unwrap()
}

fn triangle(speed_um_s: f64) -> Trajectory {
    Trajectory::Triangle {
        a_um: 1_500.0,
        b_um: 61_500.0,
        speed_um_s,
    }
}

fn cases() -> Vec<(&'static str, SimParams)> {
    let f446 = &saw_boards::ALL[0];
    let g474 = &saw_boards::ALL[1];
    let faults = vec![
        FaultWindow {
            kind: FaultKind::Open,
            start_us: 400_000,
            end_us: 430_000,
        },
        FaultWindow {
            kind: FaultKind::Dropout,
            start_us: 900_000,
            end_us: 960_000,
        },
        FaultWindow {
            kind: FaultKind::Spike { offset_lsb: 300 },
            start_us: 1_100_000,
            end_us: 1_100_300,
        },
    ];
    let mut latency = SimParams::new(g474, triangle(120_000.0), 1.5)
        .with_config(scene("random", g474))
        .with_noise(3.0, 9);
    latency.action_latency_us = 30;
    let mut no_preload = SimParams::new(f446, triangle(90_000.0), 1.2)
        .with_config(scene("grating", f446))
        .with_noise(5.0, 4);
    no_preload.preload = false;
    vec![
        (
            "default",
            SimParams::new(f446, triangle(60_000.0), 2.0).with_noise(2.0, 1),
        ),
        (
            "lines + faults",
            SimParams::new(f446, triangle(80_000.0), 1.5)
                .with_config(scene("lines", f446))
                .with_faults(faults),
        ),
        ("random, 30 µs latency, G474", latency),
        (
            "grating, G474",
            SimParams::new(g474, triangle(200_000.0), 1.0).with_config(scene("grating", g474)),
        ),
        ("grating, no preload", no_preload),
        (
            "reference noise, sine",
            SimParams::new(
                f446,
                Trajectory::Sine {
                    a_um: 0.0,
                    b_um: 63_000.0,
                    period_s: 0.7,
                },
                1.0,
            )
            .with_reference_noise(),
        ),
        // Not a whole number of chunks, and past a minute: the long run's chart (its detail
        // only) and the minutes' sums.
        (
            "long run",
            SimParams::new(f446, triangle(150_000.0), 61.37).with_noise(2.0, 5),
        ),
    ]
}

/// Two threads give the single thread's figures, chart, telemetry and callbacks exactly.
#[test]
fn two_threads_give_the_single_threads_run_bit_for_bit() {
    for (what, p) in cases() {
        let (mut one_k, mut two_k) = (Vec::new(), Vec::new());
        let one = sim::stream_on(&p, true, 1, |k| one_k.push(k)).unwrap();
        let two = sim::stream_on(&p, true, 2, |k| two_k.push(k)).unwrap();
        assert!(
            one.metrics.pulses > 5,
            "{what}: {} pulses",
            one.metrics.pulses
        );
        // Debug formatting shows every float's bits that differ (and NaNs, which == would not).
        assert_eq!(
            format!("{:?}", one.metrics),
            format!("{:?}", two.metrics),
            "{what}"
        );
        assert_eq!(one.metrics, two.metrics, "{what}");
        assert_eq!(one.chart, two.chart, "{what}");
        assert!(two.chart.is_some(), "{what}");
        assert_eq!(one.header.telemetry, two.header.telemetry, "{what}");
        assert_eq!(
            one.header.timer_protocol_errors, two.header.timer_protocol_errors,
            "{what}"
        );
        assert_eq!(one_k, two_k, "{what}");
        assert_eq!(one_k.len() as u64, sim::samples_in(&p), "{what}");
        assert!(
            one_k.iter().enumerate().all(|(i, &k)| i as u64 == k),
            "{what}"
        );
    }
}

/// Without a chart the pipeline gives the same figures too.
#[test]
fn two_threads_without_a_chart() {
    let (_, p) = cases().swap_remove(1);
    let one = sim::stream_on(&p, false, 1, |_| {}).unwrap();
    let two = sim::stream_on(&p, false, 2, |_| {}).unwrap();
    assert!(one.chart.is_none() && two.chart.is_none());
    assert_eq!(one.metrics, two.metrics);
}

/// The bare core loop timed in slices between the chunks (`sim::stream_timed`, the plain
/// run's speed line) leaves the figures, chart and telemetry as they are, on one thread and on
/// two, and runs one slice every ⌈chunks / `BARE_SLICES_AIMED`⌉ chunks (after each of the
/// short cases' chunks; every third of the 61 s case's 150).
#[test]
fn the_bare_loops_slices_leave_the_run_as_it_is() {
    for (what, p) in cases() {
        let plain = sim::stream_on(&p, true, 1, |_| {}).unwrap();
        let n = sim::samples_in(&p);
        let every = n.div_ceil(4096).div_ceil(sim::BARE_SLICES_AIMED).max(1);
        for threads in [1, 2] {
            let mut bare = sim::BareCore::new(&p, 8_192).unwrap();
            let timed = sim::stream_timed(&p, true, threads, Some(&mut bare), |_| {}).unwrap();
            assert_eq!(plain.metrics, timed.metrics, "{what}, {threads} threads");
            assert_eq!(plain.chart, timed.chart, "{what}, {threads} threads");
            assert_eq!(
                plain.header.telemetry, timed.header.telemetry,
                "{what}, {threads} threads"
            );
            // Two threads slice after every `every`-th chunk handed back, the last (partial)
            // one included; one thread after whole chunks only.
            let chunks = if threads == 2 {
                n.div_ceil(4096)
            } else {
                n / 4096
            };
            assert_eq!(
                bare.slices() as u64,
                chunks / every,
                "{what}, {threads} threads"
            );
            if let Some(ns) = bare.ns_per_sample() {
                assert!(ns > 0.0 && ns.is_finite(), "{what}: {ns} ns a sample");
            }
        }
    }
}
