//! Burst-timer model: turns the core's [`GateAction`]s into gate edges the way an STM32
//! general-purpose timer in PWM mode 1 (line high while CNT < CCR, up-counting) does.
//!
//! Times are kernel-clock cycles (u64). The counter ticks every `psc + 1` clocks; a period is
//! `arr + 1` ticks and ends with an update event (UEV), where the shadow registers are loaded
//! from the preload registers.
//!
//! - `Start(s)`: load the registers, generate an update (UG) and count from 0: the line rises at
//!   once (if `ccr > 0`) and the first period is whole.
//! - `Update(s)`: with preload (ARPE = 1, OCxPE = 1, the core's assumption) the values go to the
//!   preload registers and take effect at the next UEV; without preload (`preload: false`) ARR
//!   and CCR take effect immediately — a CCR above the count re-raises the line (a doubled
//!   pulse), an ARR below the count makes the counter run on to 2^bits before wrapping. PSC is
//!   always buffered by the hardware, in both modes.
//! - `Off`: line low now, counter stopped.
//!
//! The RF level (`docs/rf-level.md`) rides on the same events, as the DAC triggered by TIM8,
//! TIM8 slaved to this timer, does on the boards: a level asked for while a burst runs is latched
//! at the next update event (never inside a period); `Start` and a rectangular `Pulse` latch it
//! at their first edge; a triangular `Pulse` plays the board's envelope table, one entry per
//! envelope-timer step while the counter runs; `Off` latches level 0 at once. The DAC codes go
//! through the board's calibration table ([`saw_boards::rf_level::LevelTable`]); the RF the
//! finger gets is the reference circuit's answer to them ([`crate::rf::permille_at_code`]).

use saw_boards::rf_level::{self, LevelTable, MAX_ENVELOPE_ENTRIES};
use saw_core::burst::TimerSettings;
use saw_core::gate::{Envelope, GateAction};

/// One level change of the enable line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    /// Kernel-clock time.
    pub t: u64,
    /// The level after the edge.
    pub high: bool,
}

/// One pulse of the enable line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pulse {
    /// Rising edge, kernel clocks.
    pub rise: u64,
    /// Falling edge, kernel clocks.
    pub fall: u64,
    /// The next rising edge, if any (its distance is the pulse's period).
    pub next_rise: Option<u64>,
}

impl Pulse {
    /// On-time, kernel clocks.
    pub fn on(&self) -> u64 {
        self.fall - self.rise
    }

    /// Rise-to-next-rise, kernel clocks.
    pub fn period(&self) -> Option<u64> {
        self.next_rise.map(|n| n - self.rise)
    }
}

/// One change of the DAC's output (DOR), kernel clocks of the burst timer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelEdge {
    pub t: u64,
    /// The DAC code from then on.
    pub code: u16,
}

/// The recorded waveform of the enable line.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Waveform {
    /// Level changes in time order; the line starts low.
    pub edges: Vec<Edge>,
    /// DAC output changes in time order; the DAC starts at code 0.
    pub levels: Vec<LevelEdge>,
    /// Kernel clock, Hz.
    pub clock_hz: u32,
    /// End of the recording, kernel clocks.
    pub end: u64,
}

impl Waveform {
    /// Complete pulses (a rise followed by a fall), each with the following rise when there is
    /// one. A pulse still high at the end of the recording is left out.
    pub fn pulses(&self) -> Vec<Pulse> {
        let mut out: Vec<Pulse> = Vec::new();
        let mut rise = None;
        for e in &self.edges {
            if e.high {
                if let Some(last) = out.last_mut() {
                    if last.next_rise.is_none() {
                        last.next_rise = Some(e.t);
                    }
                }
                rise = Some(e.t);
            } else if let Some(r) = rise.take() {
                out.push(Pulse {
                    rise: r,
                    fall: e.t,
                    next_rise: None,
                });
            }
        }
        out
    }

    /// Rising edges with time in `[from, to)`.
    pub fn rises_in(&self, from: u64, to: u64) -> Vec<u64> {
        self.edges
            .iter()
            .filter(|e| e.high && e.t >= from && e.t < to)
            .map(|e| e.t)
            .collect()
    }

    /// Burst frequency measured from the rising edges in `[from, to)`: clock / mean interval
    /// (first to last rise over the number of intervals). None with fewer than two rises.
    pub fn measured_hz(&self, from: u64, to: u64) -> Option<f64> {
        let r = self.rises_in(from, to);
        if r.len() < 2 {
            return None;
        }
        let span = (r[r.len() - 1] - r[0]) as f64 / (r.len() - 1) as f64;
        Some(self.clock_hz as f64 / span)
    }

    /// Level at kernel-clock time `t` (after any edge at exactly `t`).
    pub fn level_at(&self, t: u64) -> bool {
        match self.edges.partition_point(|e| e.t <= t) {
            0 => false,
            i => self.edges[i - 1].high,
        }
    }

    /// True when the line is high anywhere in `[from, to)`.
    pub fn high_within(&self, from: u64, to: u64) -> bool {
        if self.level_at(from) {
            return true;
        }
        self.edges.iter().any(|e| e.high && e.t >= from && e.t < to)
    }

    /// DAC code at time `t` (after any change at exactly `t`).
    pub fn code_at(&self, t: u64) -> u16 {
        match self.levels.partition_point(|e| e.t <= t) {
            0 => 0,
            i => self.levels[i - 1].code,
        }
    }

    /// The RF drive the finger gets at `t`, ‰ of full amplitude: enable × the reference
    /// circuit's amplitude for the DAC code (0 while the line is low).
    pub fn drive_at(&self, t: u64) -> f64 {
        if self.level_at(t) {
            crate::rf::permille_at_code(self.code_at(t))
        } else {
            0.0
        }
    }

    /// DAC codes latched in `[from, to)`, with the code in force at `from` first.
    pub fn codes_within(&self, from: u64, to: u64) -> Vec<LevelEdge> {
        let mut out = vec![LevelEdge {
            t: from,
            code: self.code_at(from),
        }];
        out.extend(
            self.levels
                .iter()
                .filter(|e| e.t > from && e.t < to)
                .copied(),
        );
        out
    }

    /// Converts µs to kernel clocks.
    pub fn us_to_clocks(&self, us: f64) -> u64 {
        (us * self.clock_hz as f64 / 1e6).round() as u64
    }

    /// Converts kernel clocks to seconds.
    pub fn clocks_to_s(&self, t: u64) -> f64 {
        t as f64 / self.clock_hz as f64
    }
}

/// The counter while running.
#[derive(Clone, Copy, Debug)]
struct Running {
    /// Start of the current period (counter = 0), kernel clocks.
    t0: u64,
    /// Active (shadow) registers.
    psc: u16,
    ccr: u32,
    /// Ticks until the update event ending this period (arr + 1, or 2^bits after an ARR written
    /// below the count without preload).
    end_ticks: u64,
    /// What the next update event loads.
    pending: Option<TimerSettings>,
    /// One-pulse mode (OPM): the update event ending this period stops the counter, and the
    /// line follows PWM mode 2 (low while CNT < arr + 1 − ccr, high from there to the end).
    one_pulse: bool,
    /// A one-pulse's line has risen.
    risen: bool,
}

impl Running {
    /// The tick at which a one-pulse's line rises (PWM mode 2: CNT = CCR = arr + 1 − ccr).
    fn rise_ticks(&self) -> u64 {
        self.end_ticks.saturating_sub(self.ccr as u64)
    }
}

/// A triangle being played: the DMA's table and the envelope timer's steps.
#[derive(Clone, Debug)]
struct Playing {
    /// The pulse's start (TIM2 CEN), kernel clocks.
    start: u64,
    /// One envelope step, kernel clocks (fractional: TIM8 may run at another clock).
    step: f64,
    codes: Vec<u16>,
    /// Entries latched so far.
    next: usize,
}

/// The RF level port: what the board's DAC, TIM8 and DMA do (`docs/rf-level.md`).
#[derive(Clone, Debug)]
pub struct LevelPort {
    table: LevelTable,
    /// Envelope timer (TIM8) clock, Hz.
    envelope_clk_hz: u32,
    /// The level the core asked for, ‰.
    requested_permille: u16,
    /// The next one-pulse's envelope.
    envelope: Envelope,
    /// DHR: latched at the next trigger.
    held: u16,
    /// DOR: the output.
    out: u16,
    playing: Option<Playing>,
}

impl LevelPort {
    /// The port of a board: its calibration table and envelope-timer clock.
    pub fn new(table: LevelTable, envelope_clk_hz: u32) -> Self {
        Self {
            table,
            envelope_clk_hz,
            // Full drive until the core asks for a level, as the firmware's port.
            requested_permille: 1000,
            envelope: Envelope::Rectangular,
            held: 0,
            out: 0,
            playing: None,
        }
    }
}

/// The burst timer.
#[derive(Clone, Debug)]
pub struct TimerModel {
    clock_hz: u32,
    counter_bits: u8,
    preload: bool,
    running: Option<Running>,
    high: bool,
    /// Time up to which the waveform has been generated.
    now: u64,
    /// The earliest time anything can happen on its own (an edge, an update event, an envelope
    /// step) in the state after the last [`TimerModel::advance_to`]; 0 after an action, which
    /// may change it. Most periods of a run end before it, and advancing to them only moves
    /// `now`.
    quiet_until: u64,
    edges: Vec<Edge>,
    /// Actions that made no sense in the state they arrived in (Update while off).
    pub protocol_errors: u32,
    /// Every action applied, with its time.
    pub actions: Vec<(u64, GateAction)>,
    level: LevelPort,
    levels: Vec<LevelEdge>,
    /// The code of the last level change handed out by [`TimerModel::take_settled`].
    drained_code: Option<u16>,
}

impl TimerModel {
    /// A stopped timer. `preload` = ARPE/OCxPE set (the firmware's configuration).
    pub fn new(clock_hz: u32, counter_bits: u8, preload: bool) -> Self {
        Self {
            clock_hz,
            counter_bits,
            preload,
            running: None,
            high: false,
            now: 0,
            quiet_until: 0,
            edges: Vec::new(),
            protocol_errors: 0,
            actions: Vec::new(),
            // The reference table, its envelope timer at this clock: boards set theirs with
            // [`TimerModel::with_level`].
            level: LevelPort::new(rf_level::REFERENCE_TABLE, clock_hz),
            levels: Vec::new(),
            drained_code: None,
        }
    }

    /// The same timer with a board's RF level port.
    pub fn with_level(mut self, level: LevelPort) -> Self {
        self.level = level;
        self
    }

    /// The DAC code on the output now.
    pub fn level_code(&self) -> u16 {
        self.level.out
    }

    /// The core asks for a level, ‰ (see `BurstOutput::set_amplitude`): while a burst runs it
    /// is latched at the next update event; while off it waits for the next start.
    pub fn set_amplitude(&mut self, t: u64, permille: u16) {
        self.advance_to(t);
        self.level.requested_permille = permille;
        if self.running.is_some_and(|r| !r.one_pulse) {
            self.level.held = self.level.table.code(permille);
        }
    }

    /// The next one-pulse's envelope (see `BurstOutput::set_envelope`).
    pub fn set_envelope(&mut self, envelope: Envelope) {
        self.level.envelope = envelope;
    }

    /// The DAC latches DHR at `t`.
    fn latch(&mut self, t: u64, code: u16) {
        self.level.out = code;
        if self.levels.last().is_some_and(|e| e.t == t) {
            self.levels.pop();
        }
        // Against the last change recorded, drained ones included: a latch of the code
        // already out is no change, whether or not `take_settled` has taken the edge that set
        // it (a one-pulse latches its level a tick before its rise, so a drain can fall
        // between them).
        let last = self.levels.last().map(|e| e.code).or(self.drained_code);
        if last != Some(code) {
            self.levels.push(LevelEdge { t, code });
        }
    }

    /// Envelope entries due up to `t` (inclusive), but not past the pulse's end `until`.
    fn play_to(&mut self, t: u64, until: u64) {
        let Some(mut p) = self.level.playing.take() else {
            return;
        };
        while p.next < p.codes.len() {
            let at = p.start + ((p.next + 1) as f64 * p.step).round() as u64;
            if at > t || at > until {
                break;
            }
            let code = p.codes[p.next];
            p.next += 1;
            self.latch(at, code);
        }
        self.level.playing = Some(p);
    }

    /// Kernel clock, Hz.
    pub fn clock_hz(&self) -> u32 {
        self.clock_hz
    }

    /// The line's level at the last processed time.
    pub fn is_high(&self) -> bool {
        self.high
    }

    /// True while the counter runs.
    pub fn is_running(&self) -> bool {
        self.running.is_some()
    }

    fn set_level(&mut self, t: u64, high: bool) {
        if self.high != high {
            self.high = high;
            // A level change at the very instant of the previous one (an update event and an
            // Off on the same clock) is no pulse at all: the two edges cancel.
            if self.edges.last().is_some_and(|e| e.t == t) {
                self.edges.pop();
            } else {
                self.edges.push(Edge { t, high });
            }
        }
    }

    /// Generates the waveform up to time `t` (events at exactly `t` included).
    #[inline]
    pub fn advance_to(&mut self, t: u64) {
        assert!(t >= self.now, "time runs backwards: {t} < {}", self.now);
        if t < self.quiet_until {
            self.now = t;
        } else {
            self.advance_events(t);
        }
    }

    /// [`Self::advance_to`] where something may happen by `t`.
    fn advance_events(&mut self, t: u64) {
        while let Some(mut r) = self.running {
            let tick = r.psc as u64 + 1;
            let end = r.t0 + r.end_ticks * tick;
            // TIM8 counts (gated) while this counter runs: the envelope's entries up to here.
            self.play_to(t, end);
            if r.one_pulse {
                // PWM mode 2 in OPM: one rise at CNT = CCR; the line falls with the update
                // event that stops the counter (below).
                let rise = r.t0 + r.rise_ticks() * tick;
                if !r.risen && r.ccr > 0 && rise < end && rise <= t {
                    r.risen = true;
                    self.running = Some(r);
                    self.set_level(rise, true);
                    continue;
                }
            }
            let fall = r.t0 + r.ccr as u64 * tick;
            if !r.one_pulse && self.high && fall < end && fall <= t {
                self.set_level(fall, false);
                continue;
            }
            if end > t {
                break;
            }
            if r.one_pulse {
                // OPM: the update event clears CEN; the line stays low, and TIM8 (gated by
                // CEN) stops: the envelope is over.
                self.running = None;
                self.set_level(end, false);
                self.level.playing = None;
                break;
            }
            // Update event: load the preloaded values, restart the period.
            if let Some(p) = r.pending.take() {
                r.psc = p.psc;
                r.ccr = p.ccr;
                r.end_ticks = p.arr as u64 + 1;
            }
            r.t0 = end;
            self.running = Some(r);
            self.set_level(end, r.ccr > 0);
            // TRGO (update) → TIM8 reset → its TRGO → the DAC latches DHR.
            let held = self.level.held;
            self.latch(end, held);
        }
        self.now = t;
        self.quiet_until = self.next_event();
    }

    /// The earliest time `advance_events` would act at in the present state: the next envelope
    /// step, a one-pulse's rise, a period's fall or its update event (never, stopped).
    fn next_event(&self) -> u64 {
        let Some(r) = self.running else {
            return u64::MAX;
        };
        let tick = r.psc as u64 + 1;
        let end = r.t0 + r.end_ticks * tick;
        let mut next = end;
        if let Some(p) = &self.level.playing {
            if p.next < p.codes.len() {
                next = next.min(p.start + ((p.next + 1) as f64 * p.step).round() as u64);
            }
        }
        if r.one_pulse {
            let rise = r.t0 + r.rise_ticks() * tick;
            if !r.risen && r.ccr > 0 && rise < end {
                next = next.min(rise);
            }
        } else {
            let fall = r.t0 + r.ccr as u64 * tick;
            if self.high && fall < end {
                next = next.min(fall);
            }
        }
        next
    }

    /// Latches `s` and counts from 0 at `t` (UG + CEN); `one_pulse` stops at the update event.
    /// The level: a periodic start and a rectangular pulse latch the requested level now; a
    /// triangular pulse keeps the output (0 after an off) and plays its table.
    fn start(&mut self, t: u64, s: TimerSettings, one_pulse: bool) {
        self.level.playing = None;
        if one_pulse && self.level.envelope == Envelope::Triangular {
            // The pulse is high for the last `ccr` ticks of the count (firmware: PWM mode 2,
            // CCR = arr + 1 − ccr, one tick for a line's pulse); TIM2 is enabled for the whole
            // count, and TIM8 steps through it from CEN: the core never delays a triangle.
            let tick = s.psc as u64 + 1;
            let pulse_clocks = s.ccr as u64 * tick;
            let env_clocks =
                pulse_clocks * self.level.envelope_clk_hz as u64 / self.clock_hz as u64;
            let plan = rf_level::triangle_plan(env_clocks, self.level.envelope_clk_hz);
            let mut codes = [0u16; MAX_ENVELOPE_ENTRIES];
            rf_level::triangle(
                &self.level.table,
                self.level.requested_permille,
                &plan,
                &mut codes,
            );
            self.level.held = 0;
            self.level.playing = Some(Playing {
                start: t,
                step: plan.step_clocks as f64 * self.clock_hz as f64
                    / self.level.envelope_clk_hz as f64,
                codes: codes[..plan.entries].to_vec(),
                next: 0,
            });
        } else {
            let code = self.level.table.code(self.level.requested_permille);
            self.level.held = code;
            self.latch(t, code);
        }
        self.running = Some(Running {
            t0: t,
            psc: s.psc,
            ccr: s.ccr,
            end_ticks: s.arr as u64 + 1,
            pending: None,
            one_pulse,
            risen: false,
        });
        // A one-pulse starts low and rises at CNT = arr + 1 − ccr (`advance_to`).
        self.set_level(t, !one_pulse && s.ccr > 0);
    }

    /// Applies `action` at kernel-clock time `t`.
    pub fn apply(&mut self, t: u64, action: GateAction) {
        self.advance_to(t);
        // The action may start, stop or reshape the period: the next advance looks again.
        self.quiet_until = 0;
        self.actions.push((t, action));
        #[allow(unreachable_patterns)]
        match action {
            GateAction::Off => {
                self.running = None;
                self.set_level(t, false);
                // DMA stopped, DHR = 0, TIM8 UG: the DAC latches 0 now.
                self.level.playing = None;
                self.level.held = 0;
                self.latch(t, 0);
            }
            GateAction::Start(s) => self.start(t, s, false),
            // One-pulse mode from a stopped counter: high for ccr ticks, then low and stopped.
            GateAction::Pulse(s) => self.start(t, s, true),
            GateAction::Update(s) => {
                let Some(mut r) = self.running else {
                    self.protocol_errors += 1;
                    return;
                };
                r.pending = Some(s);
                if !self.preload {
                    let tick = r.psc as u64 + 1;
                    let cnt = (t - r.t0) / tick;
                    r.ccr = s.ccr;
                    r.end_ticks = if s.arr as u64 >= cnt {
                        s.arr as u64 + 1
                    } else {
                        1u64 << self.counter_bits
                    };
                    self.running = Some(r);
                    self.set_level(t, cnt < s.ccr as u64);
                } else {
                    self.running = Some(r);
                }
            }
            _ => {
                // An action this model does not know (a newer core): safe side, line off.
                self.protocol_errors += 1;
                self.running = None;
                self.set_level(t, false);
                self.level.playing = None;
                self.level.held = 0;
                self.latch(t, 0);
            }
        }
    }

    /// Drops the recorded edges and actions (the level and the running period stay): a run
    /// that never ends (the virtual board) keeps constant memory.
    pub fn forget_history(&mut self) {
        if let Some(l) = self.levels.last() {
            self.drained_code = Some(l.code);
        }
        self.edges.clear();
        self.actions.clear();
        self.levels.clear();
    }

    /// Moves the recorded edges and DAC changes into `edges` and `levels` (cleared first) and
    /// drops the recorded actions: what a streamed run (`sim::stream`) and the soak consume
    /// after every step, so they keep constant memory however long they run. Call it only
    /// between steps, when every later action comes after the model's time, so no recorded
    /// edge can still be cancelled by one at the same instant.
    pub fn take_settled(&mut self, edges: &mut Vec<Edge>, levels: &mut Vec<LevelEdge>) {
        if self.edges.is_empty() && self.levels.is_empty() {
            // Most periods settle nothing.
            edges.clear();
            levels.clear();
            self.actions.clear();
            return;
        }
        if let Some(l) = self.levels.last() {
            self.drained_code = Some(l.code);
        }
        edges.clear();
        levels.clear();
        std::mem::swap(edges, &mut self.edges);
        std::mem::swap(levels, &mut self.levels);
        self.actions.clear();
    }

    /// The time up to which the waveform has been generated, kernel clocks.
    pub fn now(&self) -> u64 {
        self.now
    }

    /// Finishes the recording at `t` and returns the waveform.
    pub fn finish(mut self, t: u64) -> Waveform {
        self.advance_to(t);
        Waveform {
            edges: self.edges,
            levels: self.levels,
            clock_hz: self.clock_hz,
            end: t,
        }
    }

    /// The waveform recorded so far (up to the last processed time).
    pub fn waveform(&self) -> Waveform {
        Waveform {
            edges: self.edges.clone(),
            levels: self.levels.clone(),
            clock_hz: self.clock_hz,
            end: self.now,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(arr: u32, ccr: u32) -> TimerSettings {
        TimerSettings { psc: 0, arr, ccr }
    }

    /// PWM mode 2 in one-pulse mode (RM0390 §17.3.10): low while CNT < CCR = arr + 1 − ccr,
    /// high to the update event at arr + 1, which stops the counter.
    #[test]
    fn one_pulses_rise_at_their_compare_and_fall_at_the_update() {
        let edges = |settings: TimerSettings| {
            let mut t = TimerModel::new(1_000, 32, true);
            t.apply(10, GateAction::Pulse(settings));
            let w = t.finish(10 + 1_000);
            w.edges.iter().map(|e| (e.t, e.high)).collect::<Vec<_>>()
        };
        // A line's pulse: one tick low, then 40 ticks high.
        assert_eq!(edges(s(40, 40)), vec![(11, true), (51, false)]);
        // A delayed ridge pulse: 25 ticks low, 40 high.
        assert_eq!(edges(s(64, 40)), vec![(35, true), (75, false)]);
        // With a prescaler the ticks are psc + 1 clocks.
        let mut p = s(64, 40);
        p.psc = 2;
        assert_eq!(edges(p), vec![(10 + 75, true), (10 + 195, false)]);
    }

    #[test]
    fn start_runs_whole_periods() {
        let mut t = TimerModel::new(1_000, 32, true);
        t.apply(10, GateAction::Start(s(99, 40)));
        let w = t.finish(10 + 350);
        let p = w.pulses();
        assert_eq!(p.len(), 4);
        assert_eq!(p[0].rise, 10);
        assert_eq!(p[0].on(), 40);
        assert_eq!(p[0].period(), Some(100));
        assert_eq!(w.measured_hz(0, 1_000), Some(10.0));
    }

    #[test]
    fn preload_waits_for_the_update_event() {
        let mut t = TimerModel::new(1_000, 32, true);
        t.apply(0, GateAction::Start(s(99, 40)));
        t.apply(50, GateAction::Update(s(49, 20)));
        let w = t.finish(300);
        let p = w.pulses();
        assert_eq!((p[0].on(), p[0].period()), (40, Some(100)));
        assert_eq!((p[1].on(), p[1].period()), (20, Some(50)));
    }

    #[test]
    fn without_preload_a_short_arr_runs_on_and_a_late_ccr_doubles() {
        // ARR written below the count: the counter runs to 2^16 before wrapping.
        let mut t = TimerModel::new(1_000, 16, false);
        t.apply(0, GateAction::Start(s(99, 40)));
        t.apply(60, GateAction::Update(s(49, 20)));
        let w = t.finish(70_000);
        let p = w.pulses();
        assert_eq!(p[0].period(), Some(65_536));
        // CCR written above the count while low: the line rises again in the same period.
        let mut t = TimerModel::new(1_000, 32, false);
        t.apply(0, GateAction::Start(s(99, 40)));
        t.apply(60, GateAction::Update(s(199, 80)));
        let w = t.finish(400);
        let p = w.pulses();
        assert_eq!((p[0].on(), p[0].period()), (40, Some(60)));
        assert_eq!(p[1].on(), 20);
    }

    /// Advancing in many small steps, most inside a quiet stretch that only moves the clock,
    /// gives the waveform and DAC codes of advancing straight from action to action, and the
    /// line and code after every step are the waveform's there: periodic bursts, an update
    /// with and without preload, one-pulses with a triangular envelope, an off.
    #[test]
    fn small_steps_give_the_waveform_of_large_ones() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = |below: u64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x % below
        };
        let mut p = s(1_799, 900);
        p.psc = 1;
        let actions = [
            (1_000, GateAction::Start(s(8_999, 3_600))),
            (40_000, GateAction::Update(s(4_499, 1_800))),
            (90_000, GateAction::Update(p)),
            (150_000, GateAction::Off),
            (160_000, GateAction::Pulse(s(2_000, 2_000))),
            (175_000, GateAction::Pulse(s(3_000, 1_000))),
            (190_000, GateAction::Start(s(999, 0))),
            (200_000, GateAction::Off),
        ];
        for preload in [true, false] {
            let model = || {
                let mut t = TimerModel::new(90_000_000, 32, preload);
                t.set_envelope(Envelope::Triangular);
                t
            };
            let (mut small, mut large) = (model(), model());
            let mut seen = Vec::new();
            for &(at, a) in &actions {
                while small.now() + 1 < at {
                    let t = (small.now() + 1 + next(700)).min(at - 1);
                    small.advance_to(t);
                    seen.push((t, small.is_high(), small.level_code()));
                }
                small.apply(at, a);
                large.apply(at, a);
            }
            let (small, large) = (small.finish(230_000), large.finish(230_000));
            assert_eq!(small.edges, large.edges, "preload {preload}");
            assert_eq!(small.levels, large.levels, "preload {preload}");
            assert!(large.edges.len() > 20, "{}", large.edges.len());
            assert!(large.levels.len() > 5, "{}", large.levels.len());
            for (t, high, code) in seen {
                assert_eq!(high, large.level_at(t), "preload {preload}, t {t}");
                assert_eq!(code, large.code_at(t), "preload {preload}, t {t}");
            }
        }
    }

    #[test]
    fn off_is_immediate() {
        let mut t = TimerModel::new(1_000, 32, true);
        t.apply(0, GateAction::Start(s(99, 40)));
        t.apply(20, GateAction::Off);
        let w = t.finish(1_000);
        assert_eq!(
            w.edges,
            vec![Edge { t: 0, high: true }, Edge { t: 20, high: false }]
        );
    }
}
