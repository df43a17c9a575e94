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
