//! The enable line as the hardware would drive it from the gate's actions alone, and the caps
//! checked on it — written here from the timer's reference manual and the duty rule's statement
//! (docs/duty-window.md), not from the gate's code, so the tests that use it judge the gate.
#![allow(dead_code)]

use saw_core::burst::{BurstTimer, TimerSettings};
use saw_core::gate::GateAction;

/// The duty window the docs state: 300 ms, or on-time cap / duty cap when longer (so the
/// longest pulse fits one window), at most 2^30 µs.
pub fn stated_window_us(duty_permille: u64, on_us: u64) -> u64 {
    (on_us * 1000)
        .div_ceil(duty_permille.max(1))
        .clamp(300_000, 1 << 30)
}

/// One on-interval of the line: kernel clocks `[rise, fall)`, the Start or Pulse that raised it
/// (`source` counts them), and whether that was a periodic burst.
#[derive(Clone, Copy, Debug)]
pub struct On {
    pub rise: u64,
    pub fall: u64,
    pub source: u32,
    pub periodic: bool,
}

/// A burst timer in PWM mode 1 with preload (periodic: high for the first ccr ticks of each
/// period; an Update waits for the period's end) and one-pulse mode (high for the last ccr
/// ticks of one count 0..=arr), from the gate actions alone.
pub struct LineModel {
    pub clock_hz: u64,
    /// (start of the current period, active settings, settings for the next update, one-pulse).
    run: Option<(u64, TimerSettings, Option<TimerSettings>, bool)>,
    /// On-intervals in time order.
    pub on: Vec<On>,
    sources: u32,
    pub protocol_errors: u32,
}

impl LineModel {
    pub fn new(timer: &BurstTimer) -> Self {
        Self {
            clock_hz: timer.clock_hz as u64,
            run: None,
            on: Vec::new(),
            sources: 0,
            protocol_errors: 0,
        }
    }

    pub fn clocks(&self, t_us: u64) -> u64 {
        t_us * self.clock_hz / 1_000_000
    }

    fn open(&mut self, t0: u64, s: &TimerSettings, one: bool) {
        let tick = s.psc as u64 + 1;
        let rise = if one {
            // High for the last ccr ticks of 0..=arr.
            t0 + tick * (s.arr as u64 + 1).saturating_sub(s.ccr as u64)
        } else {
            t0
        };
        let fall = rise + tick * s.ccr as u64;
        if fall > rise {
            self.on.push(On {
                rise,
                fall,
                source: self.sources,
                periodic: !one,
            });
        }
    }

    /// Runs whole periods up to `t`: each update event loads the preloaded settings.
    pub fn advance(&mut self, t: u64) {
        while let Some((t0, s, pending, one)) = self.run {
            let end = t0 + (s.psc as u64 + 1) * (s.arr as u64 + 1);
            if end > t {
                break;
            }
            if one {
                self.run = None;
                break;
            }
            let s = pending.unwrap_or(s);
            self.run = Some((end, s, None, false));
            self.open(end, &s, false);
        }
    }

    /// Line low now: cuts the interval in progress (or one not yet risen).
    fn cut(&mut self, t: u64) {
        if let Some(last) = self.on.last_mut() {
            if last.fall > t {
                last.fall = t;
            }
            if last.fall <= last.rise {
                self.on.pop();
            }
        }
    }

    pub fn apply(&mut self, t_us: u64, a: GateAction) {
        let t = self.clocks(t_us);
        self.advance(t);
        match a {
            GateAction::Off => {
                self.cut(t);
                self.run = None;
            }
            GateAction::Start(s) | GateAction::Pulse(s) => {
                let one = matches!(a, GateAction::Pulse(_));
                self.cut(t);
                self.sources += 1;
                self.run = Some((t, s, None, one));
                self.open(t, &s, one);
            }
            GateAction::Update(s) => match &mut self.run {
                Some((_, _, pending, false)) => *pending = Some(s),
                _ => self.protocol_errors += 1,
            },
        }
    }

    pub fn high_within(&self, from: u64, to: u64) -> bool {
        self.on.iter().any(|o| o.rise < to && o.fall > from)
    }
}

/// Checks `on` (time order) against the caps: every continuous on-time (touching intervals are
/// one) ≤ `max_on_clocks`; and in every window of `window_clocks` the on-time ≤ cap × window —
/// except a window whose on-time all comes from one periodic burst run, which the timer's
/// per-period cap bounds by cap × window + (1 − cap) × its longest on-time. Windows ending at
/// every fall and starting at every rise are checked (the on-time in a window is largest with
/// one of its ends there).
pub fn check_caps(
    on: &[On],
    duty_permille: u64,
    max_on_clocks: u64,
    window_clocks: u64,
) -> Result<(), String> {
    let mut i = 0;
    while i < on.len() {
        let rise = on[i].rise;
        let mut fall = on[i].fall;
        while i + 1 < on.len() && on[i + 1].rise <= fall {
            i += 1;
            fall = fall.max(on[i].fall);
        }
        if fall - rise > max_on_clocks {
            return Err(format!(
                "on for {} clocks from {rise}: above the on-time cap of {max_on_clocks}",
                fall - rise
            ));
        }
        i += 1;
    }
    // prefix[k]: on-time of on[..k].
    let mut prefix = vec![0u64; on.len() + 1];
    for (k, o) in on.iter().enumerate() {
        prefix[k + 1] = prefix[k] + (o.fall - o.rise);
    }
    // On-time in [a, b), with the index range of the intervals it touches.
    let within = |a: u64, b: u64| {
        let first = on.partition_point(|o| o.fall <= a);
        let end = on.partition_point(|o| o.rise < b);
        if first >= end {
            return (0, first, end);
        }
        let mut sum = prefix[end] - prefix[first];
        sum -= a
            .saturating_sub(on[first].rise)
            .min(on[first].fall - on[first].rise);
        sum -= on[end - 1]
            .fall
            .saturating_sub(b)
            .min(on[end - 1].fall - on[end - 1].rise);
        (sum, first, end)
    };
    let mut run_longest = std::collections::HashMap::new();
    for o in on.iter().filter(|o| o.periodic) {
        let l = run_longest.entry(o.source).or_insert(0u64);
        *l = (*l).max(o.fall - o.rise);
    }
    for o in on {
        for (a, b) in [
            (o.fall.saturating_sub(window_clocks), o.fall),
            (o.rise, o.rise + window_clocks),
        ] {
            let (sum, first, end) = within(a, b);
            let one_run = on[first].periodic && on[first].source == on[end - 1].source;
            let allowance = if one_run {
                (1000 - duty_permille.min(1000)) * run_longest[&on[first].source]
            } else {
                0
            };
            if sum * 1000 > duty_permille * window_clocks + allowance {
                return Err(format!(
                    "{sum} clocks on in the window {a}..{b} ({} ‰ of it{}): above the cap of \
                     {duty_permille} ‰",
                    sum * 1000 / window_clocks,
                    if one_run { ", one burst run" } else { "" }
                ));
            }
        }
    }
    Ok(())
}
