//! The f_b telemetry reports (`Telemetry::burst_millihz`, issue #33) where the line fires one
//! pulse per crossing rather than running a periodic burst: over a grating rendered by position
//! or hybrid it is the ridge rate V/λ, over lines the line rate V/spacing, and 0 once the finger
//! rests. The finger is fed noise-free at a known constant speed; expected rates are worked by
//! hand from the speed and the scene's spacing.

use saw_core::burst::BurstTimer;
use saw_core::controller::Controller;
use saw_core::sample::Sample;
use saw_core::scene_file::load_for_board;

/// The F446's burst timer (90 MHz, 32 bits, 2 kHz top f_b); samples every 100 µs (10 kHz).
const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 2_000,
};
const PERIOD_US: u32 = 100;

/// A 1 % margin on the expected rate: at 40 mm/s a 1 mm ridge comes every 25 ms, and a
/// crossing lands on a sample, ±100 µs (0.4 %).
const MARGIN: f64 = 0.01;

/// What `telemetry().burst_millihz` read on each sample of a run, with the sample's time.
struct Run {
    ctrl: Controller,
    t_us: u32,
}

impl Run {
    fn new(scene: &str) -> Self {
        let config = load_for_board("fb.toml", scene, TIMER, PERIOD_US).unwrap();
        let mut ctrl = Controller::new(TIMER, PERIOD_US).unwrap();
        ctrl.load(&config).unwrap();
        Run { ctrl, t_us: 0 }
    }

    /// One sample with the finger at `um`; the f_b then reported, mHz.
    fn sample(&mut self, um: f64) -> u32 {
        self.sample_line(um).1
    }

    /// One sample with the finger at `um`: the line it fired, if any, and the f_b then
    /// reported, mHz.
    fn sample_line(&mut self, um: f64) -> (Option<u8>, u32) {
        let code = self.ctrl.mapper().unwrap().code_at_um(um as f32) as u16;
        let out = self.ctrl.on_sample(Sample {
            code,
            t_us: self.t_us,
        });
        self.t_us += PERIOD_US;
        (out.line, self.ctrl.telemetry().burst_millihz)
    }

    /// Slides from `from_mm` to `to_mm` at `speed_mm_s`; the f_b reported at each sample.
    fn slide(&mut self, from_mm: f64, to_mm: f64, speed_mm_s: f64) -> Vec<(f64, u32)> {
        let step_mm = speed_mm_s * PERIOD_US as f64 * 1e-6 * (to_mm - from_mm).signum();
        let n = ((to_mm - from_mm) / step_mm).round() as usize;
        (0..=n)
            .map(|k| {
                let mm = from_mm + k as f64 * step_mm;
                (mm, self.sample(mm * 1000.0))
            })
            .collect()
    }

    /// Holds the finger at `mm` for `ms`; the f_b reported at each sample.
    fn rest(&mut self, mm: f64, ms: u32) -> Vec<u32> {
        (0..ms * 1000 / PERIOD_US)
            .map(|_| self.sample(mm * 1000.0))
            .collect()
    }
}

/// Every f_b reported while the finger is between `settled_mm` and the end of the slide is
/// within [`MARGIN`] of `expected_mhz`.
fn assert_rate(what: &str, trace: &[(f64, u32)], settled_mm: f64, expected_mhz: f64) {
    let mut checked = 0;
    for &(mm, f_b) in trace {
        if (mm - settled_mm) * (trace[trace.len() - 1].0 - settled_mm) < 0.0 {
            continue;
        }
        assert!(
            (f_b as f64 - expected_mhz).abs() <= MARGIN * expected_mhz,
            "{what}: at {mm:.3} mm the f_b reported is {f_b} mHz, expected {expected_mhz} mHz ± {} %",
            MARGIN * 100.0
        );
        checked += 1;
    }
    assert!(checked > 1000, "{what}: {checked} samples checked");
}

fn grating(render: &str) -> String {
    format!("[[region]]\nkind = \"grating\"\nwavelength_mm = 1\nrender = \"{render}\"\n")
}

/// 40 mm/s over a 1 mm grating: a ridge every 25 ms, 40 Hz; both ways; then at rest, 0.
#[test]
fn a_grating_rendered_by_pulses_reports_v_over_lambda_and_0_at_rest() {
    for render in ["position", "hybrid"] {
        let mut run = Run::new(&grating(render));
        // Start the estimator's window at rest before the slide.
        let _ = run.rest(10.0, 10);
        // The ridges crossed at 11 and 12 mm give the first interval (the one at 12 mm fires
        // on the sample after: 12.004 mm): from 12.1 mm on, 40 Hz.
        let out = run.slide(10.0, 40.0, 40.0);
        assert_rate(&format!("{render}, out"), &out, 12.1, 40_000.0);
        // Back at 25 mm/s: 25 Hz from the second ridge past the turn (39 and 38 mm).
        let back = run.slide(40.0, 15.0, 25.0);
        assert_rate(&format!("{render}, back"), &back, 37.9, 25_000.0);
        // At rest: 0 from 10 ms after the stop, once the velocity estimate (a 3.2 ms window)
        // reads 0 — before 1.5 ridge intervals (60 ms) have gone by without a ridge.
        let still = run.rest(15.0, 200);
        assert!(
            still[100..].iter().all(|&f| f == 0),
            "{render}: at rest, f_b {:?} mHz",
            &still[100..110]
        );
    }
}

/// Lines every 2 mm crossed at 40 mm/s: a line every 50 ms, 20 Hz; past the last line, 0.
#[test]
fn lines_report_their_crossing_rate_and_0_once_past() {
    let positions: Vec<String> = (0..16).map(|k| (10 + 2 * k).to_string()).collect();
    let scene = format!(
        "[[region]]\nkind = \"off\"\n\n[lines]\npositions_mm = [{}]\n",
        positions.join(", ")
    );
    let mut run = Run::new(&scene);
    let _ = run.rest(8.0, 10);
    // Lines at 10, 12, …, 40 mm: from the second (12 mm) to the last (40 mm), 20 Hz.
    let out = run.slide(8.0, 40.0, 40.0);
    assert_rate("lines", &out, 12.0, 20_000.0);
    // Sliding on past the last line: 0 once 75 ms (1.5 intervals, 3 mm) have gone by without
    // one, from 43 mm on.
    let past = run.slide(40.0, 55.0, 40.0);
    assert!(
        past.iter()
            .filter(|(mm, _)| *mm > 43.1)
            .all(|&(_, f)| f == 0),
        "past the last line: {:?}",
        past.iter()
            .filter(|(mm, _)| *mm > 43.1)
            .take(5)
            .collect::<Vec<_>>()
    );
}

/// The edge of "the pulses have stopped": two lines 2 mm apart crossed at 40 mm/s, then the
/// finger slides on past them. The rate 1 / interval is still reported 1.5 intervals after the
/// last pulse, and is 0 one sample later. The pulses' times are read from the outputs (the
/// sample that fired each line); the rest is worked by hand from them.
#[test]
fn the_rate_holds_for_one_and_a_half_intervals_after_the_last_pulse() {
    let mut run = Run::new("[[region]]\nkind = \"off\"\n\n[lines]\npositions_mm = [10, 12]\n");
    let _ = run.rest(9.0, 10);
    let step_mm = 40.0 * PERIOD_US as f64 * 1e-6;
    let mut fired = Vec::new();
    let mut reported = Vec::new();
    for k in 0..=2_500 {
        let t_us = run.t_us;
        let (line, f_b) = run.sample_line((9.0 + k as f64 * step_mm) * 1000.0);
        if line.is_some() {
            fired.push(t_us);
        }
        reported.push((t_us, f_b));
    }
    let [first, last] = fired[..] else {
        panic!("lines fired at {fired:?} µs");
    };
    let interval = last - first;
    // 2 mm at 40 mm/s: 50 ms, give or take the sample the crossing lands on.
    assert!((interval as i64 - 50_000).abs() <= 200, "{interval} µs");
    let expected = 1_000_000_000 / interval;
    let at = |t: u32| reported.iter().find(|(tr, _)| *tr == t).unwrap().1;
    assert_eq!(at(last), expected, "at the last pulse");
    assert_eq!(
        at(last + interval * 3 / 2),
        expected,
        "1.5 intervals after it"
    );
    assert_eq!(at(last + interval * 3 / 2 + PERIOD_US), 0, "a sample later");
}
