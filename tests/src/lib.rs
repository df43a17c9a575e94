//! System tests live in `tests/tests/`; this crate holds what they share: a `log` capture (so a
//! test can assert on the core's log lines) and small builders.

use std::sync::{Mutex, Once};
use std::thread::ThreadId;

use saw_core::burst::BurstTimer;

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
