//! System tests live in `tests/tests/`; this crate holds what they share: a `log` capture (so a
//! test can assert on the core's log lines), [`feed`] (a controller and timer model driven one
//! sample at a time) and small builders.

use std::sync::{Mutex, Once};
use std::thread::ThreadId;

use host_sim::timer::TimerModel;
use saw_core::burst::BurstTimer;
use saw_core::sample::Sample;
use saw_core::{Controller, Output};

/// One captured log record.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Line {
    /// Level.
    pub level: log::Level,
    /// Formatted message.
    pub message: String,
}

struct Capture {
    lines: Mutex<Vec<(ThreadId, Line)>>,
}

impl log::Log for Capture {
    fn enabled(&self, _: &log::Metadata) -> bool {
        true
    }
    fn log(&self, r: &log::Record) {
        let line = Line {
            level: r.level(),
            message: r.args().to_string(),
        };
        self.lines
            .lock()
            .unwrap()
            .push((std::thread::current().id(), line));
    }
    fn flush(&self) {}
}

static CAPTURE: Capture = Capture {
    lines: Mutex::new(Vec::new()),
};
static INIT: Once = Once::new();

/// Installs the capturing logger (once per test binary). Records are kept per thread, so tests
/// running in parallel only see their own.
pub fn capture_logs() {
    INIT.call_once(|| {
        log::set_logger(&CAPTURE).expect("another logger is installed");
        log::set_max_level(log::LevelFilter::Trace);
    });
}

/// Takes (and clears) the records logged so far by the calling thread.
pub fn take_logs() -> Vec<Line> {
    let me = std::thread::current().id();
    let mut all = CAPTURE.lines.lock().unwrap();
    let (mine, rest): (Vec<_>, Vec<_>) = all.drain(..).partition(|(id, _)| *id == me);
    *all = rest;
    mine.into_iter().map(|(_, l)| l).collect()
}

/// One sample by hand: `code` at `t_us` into `ctrl`, and its gate action, if any, applied to `tm`
/// at that time (`sim::run`'s loop without a trajectory, an ADC or a latency). Returns the
/// controller's output.
pub fn feed(ctrl: &mut Controller, tm: &mut TimerModel, code: u16, t_us: u64) -> Output {
    let out = ctrl.on_sample(Sample {
        code,
        t_us: t_us as u32,
    });
    if let Some(a) = out.action {
        tm.apply(t_us * tm.clock_hz() as u64 / 1_000_000, a);
    }
    out
}

/// A 16-bit burst timer at 180 MHz (an APB2 timer on the F446 at full clock), for the prescaler
/// path: both boards' burst timers are 32-bit.
pub const TIMER_16BIT_180MHZ: BurstTimer = BurstTimer {
    clock_hz: 180_000_000,
    counter_bits: 16,
    max_burst_hz: saw_boards::MAX_BURST_HZ,
};

/// The burst timers to test: both boards' plus the 16-bit one.
pub fn timers() -> Vec<(&'static str, BurstTimer)> {
    let mut v: Vec<(&'static str, BurstTimer)> = saw_boards::ALL
        .iter()
        .map(|b| (b.name, host_sim::sim::burst_timer(b)))
        .collect();
    v.push(("16-bit 180 MHz", TIMER_16BIT_180MHZ));
    v
}

/// `n` burst frequencies log-spaced from 1 Hz to 2 kHz inclusive, mHz.
pub fn log_sweep_millihz(n: usize) -> Vec<u32> {
    (0..n)
        .map(|i| {
            let hz = 2000f64.powf(i as f64 / (n - 1) as f64);
            (hz * 1000.0).round() as u32
        })
        .collect()
}

/// The duty window docs/duty-window.md states for caps `duty_permille` and `on_us`, µs: 300 ms,
/// or on-time cap / duty cap when longer, at most 2^30 µs (written from the statement, not
/// taken from the gate).
pub fn stated_window_us(duty_permille: u64, on_us: u64) -> u64 {
    (on_us * 1000)
        .div_ceil(duty_permille.max(1))
        .clamp(300_000, 1 << 30)
}

/// One on-time of a recorded line, kernel clocks, with the Start or Pulse it came from.
#[derive(Clone, Copy, Debug)]
pub struct OnTime {
    /// Rise.
    pub rise: u64,
    /// Fall.
    pub fall: u64,
    /// Index of the Start or Pulse that raised it (the latest one at or before the rise).
    pub source: usize,
    /// Raised by a Start (a periodic run), not a Pulse.
    pub periodic: bool,
}

/// The line's on-times from `pulses` (rise, fall; time order), each given the latest Start or
/// Pulse in `starts` (kernel clocks, is-a-Start; time order) at or before its rise.
pub fn on_times(pulses: &[(u64, u64)], starts: &[(u64, bool)]) -> Vec<OnTime> {
    pulses
        .iter()
        .map(|&(rise, fall)| {
            let k = starts.partition_point(|&(t, _)| t <= rise);
            let (source, periodic) = match k.checked_sub(1) {
                Some(i) => (i, starts[i].1),
                None => (usize::MAX, true),
            };
            OnTime {
                rise,
                fall,
                source,
                periodic,
            }
        })
        .collect()
}

/// The windowed duty rule (docs/duty-window.md) over `on` (time order): in every window of
/// `window` clocks the on-time is at most cap × window, except a window whose on-time all comes
/// from one periodic run, which may hold (1 − cap) × that run's longest on-time more. Windows
/// ending at every fall and starting at every rise are checked (a window's on-time is largest
/// with an end there). Returns the highest on-time / (cap × window) seen, or the first window
/// above the rule.
pub fn windowed_duty(on: &[OnTime], duty_permille: u64, window: u64) -> Result<f64, String> {
    let mut prefix = vec![0u64; on.len() + 1];
    for (k, o) in on.iter().enumerate() {
        prefix[k + 1] = prefix[k] + (o.fall - o.rise);
    }
    let mut longest = std::collections::HashMap::new();
    for o in on.iter().filter(|o| o.periodic) {
        let l = longest.entry(o.source).or_insert(0u64);
        *l = (*l).max(o.fall - o.rise);
    }
    let mut worst = 0.0f64;
    for o in on {
        for (a, b) in [
            (o.fall.saturating_sub(window), o.fall),
            (o.rise, o.rise + window),
        ] {
            let first = on.partition_point(|x| x.fall <= a);
            let end = on.partition_point(|x| x.rise < b);
            let (f, l) = (on[first], on[end - 1]);
            let mut sum = prefix[end] - prefix[first];
            sum -= a.saturating_sub(f.rise).min(f.fall - f.rise);
            sum -= l.fall.saturating_sub(b).min(l.fall - l.rise);
            let one_run = f.periodic && f.source == l.source;
            let allowance = if one_run {
                (1000 - duty_permille.min(1000)) * longest[&f.source]
            } else {
                0
            };
            if sum * 1000 > duty_permille * window + allowance {
                return Err(format!(
                    "{sum} clocks on in the window {a}..{b} clocks ({} ‰{}) above the cap of \
                     {duty_permille} ‰",
                    sum * 1000 / window,
                    if one_run { ", one periodic run" } else { "" }
                ));
            }
            worst = worst.max(sum as f64 * 1000.0 / (duty_permille * window) as f64);
        }
    }
    Ok(worst)
}
