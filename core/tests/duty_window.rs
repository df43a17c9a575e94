//! Property test of the gate's windowed duty cap (issue #17): random pulse trains and random
//! mixes of Start / Update / Off / pulse / end_pulse / force_off requests at random times,
//! under random caps and starting anywhere on the wrapping µs clock. What the gate emitted is
//! replayed into the line a timer would drive (tests/common, written from the timer's manual,
//! not from the gate), and on that line every window of the stated length holds at most
//! cap × window of on-time (a window inside one periodic run: plus the partial period the
//! timer's per-period cap allows), and every continuous on-time is at most the on-time cap.

use proptest::prelude::*;
use saw_core::burst::{BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::Gate;

mod common;
use common::LineModel;

const T: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 5_000,
};

#[derive(Clone, Copy, Debug)]
enum Op {
    /// Periodic bursts: period (clocks), duty ‰ (above the cap: refused, line off).
    Burst(u32, u16),
    Off,
    /// One pulse: delay and on-time, clocks.
    Pulse(u64, u64),
    EndPulse,
    ForceOff,
}

fn op(max_on_clocks: u64) -> impl Strategy<Value = Op> {
    prop_oneof![
        3 => (18_000u32..=9_000_000, 1u16..=1000).prop_map(|(p, d)| Op::Burst(p, d)),
        1 => Just(Op::Off),
        // Delays inside a 100 µs sample period (the hybrid renderer's), or up to 20 ms.
        4 => (0u64..=9_000, 90..=max_on_clocks + max_on_clocks / 5)
            .prop_map(|(d, on)| Op::Pulse(d, on)),
        2 => (0u64..=1_800_000, 90..=max_on_clocks + max_on_clocks / 5)
            .prop_map(|(d, on)| Op::Pulse(d, on)),
        2 => Just(Op::EndPulse),
        1 => Just(Op::ForceOff),
    ]
}

/// Gaps between requests, µs: mostly a sample or a few, sometimes a pulse's length or more.
fn gap() -> impl Strategy<Value = u64> {
    prop_oneof![
        4 => 0u64..=300,
        4 => 0u64..=20_000,
        1 => 0u64..=400_000,
    ]
}

fn case() -> impl Strategy<Value = (u16, u32, u32, Vec<(u64, Op)>)> {
    (
        prop_oneof![100u16..=1000, 1u16..=100],
        1_000u32..=60_000,
        any::<u32>(),
    )
        .prop_flat_map(|(duty, on_us, t0)| {
            let max_on_clocks = on_us as u64 * 90;
            (
                Just(duty),
                Just(on_us),
                Just(t0),
                prop::collection::vec((gap(), op(max_on_clocks)), 1..400),
            )
        })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn every_window_keeps_the_cap((duty, on_us, t0, ops) in case()) {
        let limits = SafetyLimits {
            max_duty_permille: duty,
            max_on_time_us: on_us,
            ..SafetyLimits::default()
        };
        let mut g = Gate::default();
        let mut line = LineModel::new(&T);
        let mut t = 0u64;
        for (dt, op) in ops {
            t += dt;
            let now = t0.wrapping_add(t as u32);
            let action = match op {
                Op::Burst(period, d) => {
                    let ccr = (period as u64 * d as u64 / 1000).max(1) as u32;
                    let s = TimerSettings { psc: 0, arr: period - 1, ccr: ccr.min(period - 1) };
                    g.request(Some(s), now, &T, &limits)
                }
                Op::Off => g.request(None, now, &T, &limits),
                Op::Pulse(delay, on) => {
                    let p = if delay == 0 {
                        T.one_pulse(on)
                    } else {
                        T.delayed_pulse(delay, on)
                    };
                    g.pulse(p.unwrap(), now, &T, &limits)
                }
                Op::EndPulse => g.end_pulse(now, &limits),
                Op::ForceOff => g.force_off(now, &T, &limits),
            };
            if let Some(a) = action {
                line.apply(t, a);
            }
        }
        // Whatever still runs is stopped a window later.
        let end = t + 2 * common::stated_window_us(duty as u64, on_us as u64);
        line.advance(line.clocks(end));
        line.apply(end, saw_core::gate::GateAction::Off);
        prop_assert_eq!(line.protocol_errors, 0);
        let window = line.clocks(common::stated_window_us(duty as u64, on_us as u64));
        let max_on = limits.max_on_time_clocks(&T);
        if let Err(e) = common::check_caps(&line.on, duty as u64, max_on, window) {
            prop_assert!(false, "{} (cap {} ‰, on-time cap {} µs, {} on-intervals)", e, duty, on_us, line.on.len());
        }
    }
}

/// The check itself catches what it must: the per-pulse rule (each pulse followed by its rest)
/// breaks a 300 ms window at 50 % — 2.5 ms pulses every 5 ms from 0 to 277.5 ms, then a 20 ms
/// pulse right after the last one's rest: 140 + 20 = 160 ms in [0, 300 ms) — and a window
/// inside one 50 % burst run may hold half an on-time more, no more.
#[test]
fn the_check_catches_the_per_pulse_rule() {
    let ms = 90_000u64;
    let pulse = |rise: u64, len: u64, source: u32| common::On {
        rise,
        fall: rise + len,
        source,
        periodic: false,
    };
    let mut on: Vec<common::On> = (0..56)
        .map(|k| pulse(k * 5 * ms, 5 * ms / 2, k as u32))
        .collect();
    on.push(pulse(280 * ms, 20 * ms, 56));
    let window = 300 * ms;
    assert!(common::check_caps(&on, 500, 50 * ms, window).is_err());
    // Without the long pulse it holds (140 ms).
    assert!(common::check_caps(&on[..56], 500, 50 * ms, window).is_ok());
    // A 50 % burst of 25 ms on per 50 ms period: a window from a rise to the end of a pulse
    // holds 150 + 12.5 ms at most; allowed inside one run, not across two sources.
    let run: Vec<common::On> = (0..20)
        .map(|k| common::On {
            rise: k * 50 * ms,
            fall: k * 50 * ms + 25 * ms,
            source: 7,
            periodic: true,
        })
        .collect();
    assert!(common::check_caps(&run, 500, 50 * ms, 290 * ms).is_ok());
    let mut split = run.clone();
    for o in split.iter_mut().skip(10) {
        o.source = 8;
    }
    assert!(common::check_caps(&split, 500, 50 * ms, 290 * ms).is_err());
    // Two touching pulses are one on-time.
    let touching = [pulse(0, 30 * ms, 0), pulse(30 * ms, 30 * ms, 1)];
    assert!(common::check_caps(&touching, 1000, 50 * ms, window).is_err());
}
