//! No runt or doubled pulse across 1000 random f_b changes at random times: every pulse's
//! (period, on-time) is exactly the settings in force when it started. The same changes without
//! timer preload do produce malformed pulses — the check can fail.

use host_sim::timer::{TimerModel, Waveform};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use saw_core::burst::{self, BurstCommand, BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::GateAction;
use saw_tests::timers;

/// Start, then 1000 updates at random gaps (0–30 ms) to random f_b (log-uniform 10 Hz – 2 kHz).
/// Returns the waveform and the writes (time, settings).
fn random_changes(
    timer: &BurstTimer,
    preload: bool,
    seed: u64,
) -> (Waveform, Vec<(u64, TimerSettings)>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let limits = SafetyLimits::default();
    let plan = |rng: &mut ChaCha8Rng| {
        let hz = 10f64 * 200f64.powf(rng.random::<f64>());
        let cmd = BurstCommand {
            burst_millihz: (hz * 1000.0) as u32,
            duty_permille: rng.random_range(100..=500),
        };
        burst::plan(timer, &limits, &cmd).unwrap().0
    };
    let mut tm = TimerModel::new(timer.clock_hz, timer.counter_bits, preload);
    let mut writes = Vec::new();
    let mut t = 1_000u64;
    let s = plan(&mut rng);
    tm.apply(t, GateAction::Start(s));
    writes.push((t, s));
    for _ in 0..1000 {
        t += rng.random_range(0..timer.clock_hz as u64 * 30 / 1000);
        let s = plan(&mut rng);
        tm.apply(t, GateAction::Update(s));
        writes.push((t, s));
    }
    let end = t + timer.clock_hz as u64 / 5;
    (tm.finish(end), writes)
}

/// Pulses whose (on, period) differ from the settings latched at their rise: the last write
/// strictly before the rise (a write takes effect at the next update event).
fn malformed(w: &Waveform, writes: &[(u64, TimerSettings)]) -> (usize, usize) {
    let pulses = w.pulses();
    let mut bad = 0;
    for p in &pulses {
        let i = writes.partition_point(|(t, _)| *t < p.rise);
        let s = writes[i.max(1) - 1].1;
        let ok_on = p.on() == s.on_clocks();
        let ok_period = p.period().is_none_or(|per| per == s.period_clocks());
        if !(ok_on && ok_period) {
            bad += 1;
        }
    }
    (bad, pulses.len())
}

#[test]
fn preload_makes_every_pulse_whole() {
    for (name, timer) in timers() {
        let (w, writes) = random_changes(&timer, true, 0x5a5_0001);
        let (bad, n) = malformed(&w, &writes);
        assert!(n > 1000, "{name}: only {n} pulses");
        assert_eq!(bad, 0, "{name}: {bad} of {n} pulses malformed with preload");
        // Every pulse equals one of the commanded settings (not merely "close").
        let set: std::collections::HashSet<(u64, u64)> = writes
            .iter()
            .map(|(_, s)| (s.on_clocks(), s.period_clocks()))
            .collect();
        for p in w.pulses().iter().filter(|p| p.next_rise.is_some()) {
            assert!(
                set.contains(&(p.on(), p.period().unwrap())),
                "{name}: {p:?}"
            );
        }
        eprintln!("{name}: {n} pulses, 1000 changes, 0 malformed with preload");
    }
}

#[test]
fn without_preload_the_same_changes_make_runts() {
    for (name, timer) in timers() {
        let (w, writes) = random_changes(&timer, false, 0x5a5_0001);
        let (bad, n) = malformed(&w, &writes);
        eprintln!("{name}: without preload {bad} of {n} pulses malformed");
        assert!(
            bad > 0,
            "{name}: no runt without preload — the check is blind"
        );
    }
}
