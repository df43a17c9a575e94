//! The exact edge of the carrier caps (issue #33): for each board's burst timer (saw-boards'
//! F446 and G474 definitions), `SafetyLimits::allows` accepts the last compare value the duty
//! cap, the on-time cap and the fall-every-period rule let through, and refuses the next one,
//! one timer tick more. Every expected CCR is worked out by hand below from the cap and the
//! timer's clock (not by `max_ccr` or any code under test); if a board's clock changes, the
//! first assertion of its case says so and the arithmetic must be redone.
//!
//! Periodic bursts (RM0390 §18.3.9 / RM0440 §29.3.16, PWM mode 1): the line is high while
//! CNT < CCR, CNT counting 0 … ARR at clock / (PSC + 1), so the on-time is CCR ticks of a period
//! of ARR + 1 ticks: duty = CCR / (ARR + 1), on-time = (PSC + 1) · CCR clocks.

use saw_boards::{BoardDef, NUCLEO_F446RE, NUCLEO_G474RE};
use saw_core::burst::{BurstTimer, SafetyLimits, TimerSettings};

fn timer(b: &BoardDef) -> BurstTimer {
    BurstTimer {
        clock_hz: b.burst_timer_clk_hz,
        counter_bits: b.burst_timer_bits,
        max_burst_hz: b.max_burst_hz,
    }
}

/// One boundary: under `limits`, with this prescaler and period, `last_ok` is allowed and
/// `last_ok + 1` is not.
struct Edge {
    what: &'static str,
    limits: SafetyLimits,
    psc: u16,
    arr: u32,
    last_ok: u32,
}

fn caps(duty_permille: u16, on_time_us: u32) -> SafetyLimits {
    SafetyLimits {
        max_duty_permille: duty_permille,
        max_on_time_us: on_time_us,
        ..SafetyLimits::default()
    }
}

fn check(board: &BoardDef, edges: &[Edge]) {
    let t = timer(board);
    for e in edges {
        let at = |ccr| TimerSettings {
            psc: e.psc,
            arr: e.arr,
            ccr,
        };
        assert!(
            e.limits.allows(&t, &at(e.last_ok)),
            "{}: {}: CCR {} (the last inside the cap) refused",
            board.name,
            e.what,
            e.last_ok
        );
        assert!(
            !e.limits.allows(&t, &at(e.last_ok + 1)),
            "{}: {}: CCR {} (one tick past the cap) allowed",
            board.name,
            e.what,
            e.last_ok + 1
        );
    }
}

#[test]
fn f446_burst_timer_allows_up_to_the_cap_and_not_a_tick_more() {
    let b = &NUCLEO_F446RE;
    // The arithmetic below is for TIM2 on a 90 MHz timer clock, 32 bits.
    assert_eq!((b.burst_timer_clk_hz, b.burst_timer_bits), (90_000_000, 32));
    check(
        b,
        &[
            // 2 kHz (the board's top f_b): 90 MHz / 2 kHz = 45 000 clocks, ARR 44 999.
            // 50 % of 45 000 = 22 500 exactly: equality is allowed.
            Edge {
                what: "duty cap 50 % at 2 kHz",
                limits: caps(500, 50_000),
                psc: 0,
                arr: 44_999,
                last_ok: 22_500,
            },
            // 700 Hz: 90e6 / 700 = 128 571.4, period 128 571 clocks, ARR 128 570.
            // 33.3 % of 128 571 = 42 814.14: 42 814 is under, 42 815 over.
            Edge {
                what: "duty cap 33.3 % at 700 Hz",
                limits: caps(333, 50_000),
                psc: 0,
                arr: 128_570,
                last_ok: 42_814,
            },
            // ARR 45 000 (a period of 45 001 clocks, just under 2 kHz) under a 99.9 % cap:
            // 45 001 × 0.999 = 44 955.999, so 44 955 is the last; a period counted one clock
            // long (45 002 × 0.999 = 44 956.998) would let 44 956 through.
            Edge {
                what: "duty cap 99.9 % at ARR 45 000",
                limits: caps(999, 50_000),
                psc: 0,
                arr: 45_000,
                last_ok: 44_955,
            },
            // 5 Hz: 18 000 000 clocks, ARR 17 999 999; 50 % would be 9 000 000 clocks (100 ms),
            // the on-time cap 50 ms × 90 MHz = 4 500 000 clocks binds.
            Edge {
                what: "on-time cap 50 ms at 5 Hz",
                limits: caps(500, 50_000),
                psc: 0,
                arr: 17_999_999,
                last_ok: 4_500_000,
            },
            // Prescaler 7 (PSC 6), ARR 9 999 (a 5 000-tick duty allowance): the on-time cap
            // 37 µs × 90 MHz = 3 330 clocks = 475.7 ticks of 7 clocks: 475 (3 325 clocks) is
            // under, 476 (3 332) over.
            Edge {
                what: "on-time cap 37 µs, prescaler 7",
                limits: caps(500, 37),
                psc: 6,
                arr: 9_999,
                last_ok: 475,
            },
            // A 100 % duty cap at 2 kHz: CCR 44 999 falls one tick before the period ends;
            // CCR 45 000 = ARR + 1 never falls (the line would stay high for good).
            Edge {
                what: "the line falls every period (100 % cap)",
                limits: caps(1000, 50_000),
                psc: 0,
                arr: 44_999,
                last_ok: 44_999,
            },
        ],
    );
}

#[test]
fn g474_burst_timer_allows_up_to_the_cap_and_not_a_tick_more() {
    let b = &NUCLEO_G474RE;
    // The arithmetic below is for TIM2 on a 150 MHz timer clock, 32 bits.
    assert_eq!(
        (b.burst_timer_clk_hz, b.burst_timer_bits),
        (150_000_000, 32)
    );
    check(
        b,
        &[
            // 2 kHz: 150 MHz / 2 kHz = 75 000 clocks, ARR 74 999; 50 % = 37 500 exactly.
            Edge {
                what: "duty cap 50 % at 2 kHz",
                limits: caps(500, 50_000),
                psc: 0,
                arr: 74_999,
                last_ok: 37_500,
            },
            // 700 Hz: 150e6 / 700 = 214 285.7, period 214 286 clocks, ARR 214 285.
            // 33.3 % of 214 286 = 71 357.24: 71 357 is under, 71 358 over.
            Edge {
                what: "duty cap 33.3 % at 700 Hz",
                limits: caps(333, 50_000),
                psc: 0,
                arr: 214_285,
                last_ok: 71_357,
            },
            // ARR 75 000 (75 001 clocks) under a 99.9 % cap: 75 001 × 0.999 = 74 925.999, so
            // 74 925 is the last (75 002 × 0.999 = 74 926.998 would pass 74 926).
            Edge {
                what: "duty cap 99.9 % at ARR 75 000",
                limits: caps(999, 50_000),
                psc: 0,
                arr: 75_000,
                last_ok: 74_925,
            },
            // 5 Hz: 30 000 000 clocks, ARR 29 999 999; the on-time cap 50 ms × 150 MHz =
            // 7 500 000 clocks binds (50 % would be 15 000 000).
            Edge {
                what: "on-time cap 50 ms at 5 Hz",
                limits: caps(500, 50_000),
                psc: 0,
                arr: 29_999_999,
                last_ok: 7_500_000,
            },
            // PSC 6, ARR 9 999: 37 µs × 150 MHz = 5 550 clocks = 792.9 ticks of 7 clocks:
            // 792 (5 544 clocks) under, 793 (5 551) over.
            Edge {
                what: "on-time cap 37 µs, prescaler 7",
                limits: caps(500, 37),
                psc: 6,
                arr: 9_999,
                last_ok: 792,
            },
            // 100 % cap at 2 kHz: CCR 74 999 falls, 75 000 = ARR + 1 never does.
            Edge {
                what: "the line falls every period (100 % cap)",
                limits: caps(1000, 50_000),
                psc: 0,
                arr: 74_999,
                last_ok: 74_999,
            },
        ],
    );
}
