//! The soak's online checks of the enable line: every edge the timer model records is judged as
//! it arrives against the caps, the sensor faults injected and the actions the core issued, in
//! constant memory (nothing here grows with the run).
//!
//! The rules, in kernel clocks of the burst timer (see `docs/soak.md`):
//! - **on-time**: a pulse (rise to fall, or to the end of the episode while still high) lasts at
//!   most the on-time cap ([`SafetyLimits::max_on_time_clocks`]);
//! - **duty**: the on-time in every duty window (300 ms, or on-time cap / duty cap when longer:
//!   docs/duty-window.md) is at most the duty cap × the window, judged for the windows ending at
//!   every fall and starting at every rise (a window's on-time is largest with an end there); a
//!   window whose on-time all comes from one periodic run may hold (1 − cap) × its longest
//!   on-time more (the timer's partial period). Windows holding a scene change are not judged
//!   (on-time spent under the old caps cannot be undone);
//! - **fault**: the line is low in every sample period the injected faults say must be off
//!   (from the first sample at a rail, or a sample period after the stale limit of silence,
//!   until the 16th good sample after), the rule of `tests/tests/safety_fuzz.rs`;
//! - **runt**: a pulse ended by the timer (not by an `Off`) lasts exactly the on-time of the
//!   settings that raised it; one ended by an `Off` at most that;
//! - **doubled**: a rise that no `Start` or `Pulse` caused comes exactly one period (of the
//!   settings running) after the previous rise, and never after an `Off`.
//!
//! A scene reload changes the caps mid-pulse; a pulse is judged against the most generous caps
//! of the scenes in force between its rise and the moment judged (the pulse in flight at a
//! reload was planned under the old ones).

use std::collections::VecDeque;

/// The duty window the docs state (docs/duty-window.md), µs: 300 ms, or on-time cap / duty cap
/// when longer, at most 2^30 µs. Written from the statement, not taken from the gate.
fn stated_window_us(limits: &SafetyLimits) -> u64 {
    (limits.max_on_time_us as u64 * 1000)
        .div_ceil(limits.max_duty_permille.max(1) as u64)
        .clamp(300_000, 1 << 30)
}

use saw_core::burst::{BurstTimer, SafetyLimits, TimerSettings};
use saw_core::gate::GateAction;

use crate::timer::Edge;

/// What a violation broke.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Rule {
    /// A pulse longer than the on-time cap.
    OnTime,
    /// On-time in a duty window above the duty cap.
    Duty,
    /// The line high where an injected fault says it must be off.
    OnDuringFault,
    /// The line high at the end of a sample period the core itself reports faulted.
    OnWhileReportedFault,
    /// A pulse that ended (by the timer) at another on-time than planned.
    Runt,
    /// A rise no start caused, at another time than one period after the previous rise.
    Doubled,
    /// A refused scene changed what the controller does.
    RefusalChangedScene,
    /// A scene broken on purpose was accepted.
    BrokenSceneAccepted,
    /// The timer model got an action it could not make sense of.
    TimerProtocol,
    /// 2D: the line high while the finger is off the plate, or landing (fewer than 16 pressed
    /// frames since it touched down).
    OnWhileLifted,
    /// 2D: an edge fired again without the finger clear of its line by the re-arm distance in
    /// between (two pulses for one crossing).
    EdgeRepeat,
}

impl Rule {
    /// Every rule, in the order the summary lists them.
    pub const ALL: [Rule; 11] = [
        Rule::OnTime,
        Rule::Duty,
        Rule::OnDuringFault,
        Rule::OnWhileReportedFault,
        Rule::Runt,
        Rule::Doubled,
        Rule::RefusalChangedScene,
        Rule::BrokenSceneAccepted,
        Rule::TimerProtocol,
        Rule::OnWhileLifted,
        Rule::EdgeRepeat,
    ];

    /// Its place in [`Rule::ALL`].
    pub fn index(self) -> usize {
        Rule::ALL.iter().position(|r| *r == self).unwrap_or(0)
    }

    /// The rule's name as printed.
    pub fn name(self) -> &'static str {
        match self {
            Rule::OnTime => "on-time above the cap",
            Rule::Duty => "duty above the cap",
            Rule::OnDuringFault => "line high during a sensor fault",
            Rule::OnWhileReportedFault => "line high while the core reports a fault",
            Rule::Runt => "runt or stretched pulse",
            Rule::Doubled => "doubled pulse",
            Rule::RefusalChangedScene => "a refused scene changed the running one",
            Rule::BrokenSceneAccepted => "a broken scene was accepted",
            Rule::TimerProtocol => "timer protocol error",
            Rule::OnWhileLifted => "line high while lifted or landing",
            Rule::EdgeRepeat => "an edge pulsed twice for one crossing",
        }
    }
}

/// One broken rule, where: the global sample index reproduces it (with the run's seed).
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Violation {
    /// The rule.
    pub rule: Rule,
    /// Global sample index (0 = the soak's first sample at seed S) of the sample period in
    /// which the rule broke.
    pub sample: u64,
    /// What was measured, in a sentence.
    pub detail: String,
}

/// The caps of a scene in kernel clocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Caps {
    on_clocks: u64,
    duty_permille: u64,
    window_clocks: u64,
}

impl Caps {
    fn of(limits: &SafetyLimits, timer: &BurstTimer) -> Self {
        Self {
            on_clocks: limits.max_on_time_clocks(timer),
            duty_permille: limits.max_duty_permille as u64,
            window_clocks: stated_window_us(limits) * timer.clock_hz as u64 / 1_000_000,
        }
    }

    fn loosen(&mut self, other: Caps) {
        self.on_clocks = self.on_clocks.max(other.on_clocks);
        self.duty_permille = self.duty_permille.max(other.duty_permille);
        self.window_clocks = self.window_clocks.max(other.window_clocks);
    }
}

/// One on-time of the line, kept while a duty window may still hold it.
#[derive(Clone, Copy, Debug)]
struct OnTime {
    rise: u64,
    fall: u64,
    /// The Start or Pulse that raised it (counted).
    source: u64,
    periodic: bool,
    /// On-time of every on-time before it (a running sum: a window's share in O(log n)).
    before: u64,
    /// Longest on-time of its run up to here.
    run_longest: u64,
}

/// The line high since `rise`.
#[derive(Clone, Copy, Debug)]
struct High {
    rise: u64,
    /// The settings that raised it (None: nothing the checker knows of).
    settings: Option<TimerSettings>,
    caps: Caps,
    /// Raised by a `Pulse`: the timer stops at the end of its one period.
    one_pulse: bool,
    /// The Start or Pulse it belongs to.
    source: u64,
}

/// The last complete pulse, waiting for the next rise (to judge it as doubled or not).
#[derive(Clone, Copy, Debug)]
struct Done {
    rise: u64,
    settings: Option<TimerSettings>,
    /// Ended by an `Off`, or a one-pulse (the timer stopped): no update event may raise the line
    /// after it.
    cut: bool,
}

/// Sample periods `[a, b)` (kernel clocks) in which the line must be low.
#[derive(Clone, Copy, Debug)]
struct Span {
    a: u64,
    b: u64,
    reported: bool,
    /// The rule a high line breaks here.
    rule: Rule,
}

/// Violations kept per episode with their detail (all are counted).
pub const KEPT_PER_EPISODE: usize = 8;

/// True when `s` keeps the line high through its whole period (CCR above ARR: 100 % duty).
fn continuous(s: &TimerSettings) -> bool {
    s.ccr > s.arr
}

/// The online checker of one episode's enable line.
#[derive(Clone, Debug)]
pub struct LineCheck {
    timer: BurstTimer,
    /// One sample period, kernel clocks (clocks / period = the local sample index).
    period_clocks: u64,
    /// Global index of local sample 0.
    global_of_local0: u64,
    caps: Caps,
    /// The caps before the last scene change, and the time the core first saw the new scene.
    before: Caps,
    changed_at: Option<u64>,
    high: Option<High>,
    done: Option<Done>,
    /// What the timer runs and what waits in its preload registers, as the core's actions say.
    active: Option<TimerSettings>,
    pending: Option<TimerSettings>,
    /// A one-pulse's rise: arr + 1 − ccr ticks after its action (PWM mode 2 in one-pulse mode,
    /// `GateAction::Pulse`), which may fall in a later step than the action.
    pulse_rise_at: Option<u64>,
    spans: VecDeque<Span>,
    /// On-times a duty window may still hold, in time order.
    recent: VecDeque<OnTime>,
    /// Rises whose window (starting there) is not yet over, with its length.
    /// The caps the window is judged by are the ones in force at its rise (a window holding a
    /// scene change is not judged, so they hold through it): one judged late, behind a longer
    /// window of an earlier scene in the queue, is not judged by a later scene's caps.
    open_windows: VecDeque<(u64, u64, Caps)>,
    /// Scene changes a window may still hold.
    changes: VecDeque<u64>,
    /// Starts and Pulses seen.
    sources: u64,
    /// Pulses judged.
    pub pulses: u64,
    /// Violations found (all of them).
    pub count: u64,
    /// Violations found, by [`Rule::index`].
    pub by_rule: [u64; Rule::ALL.len()],
    /// The first [`KEPT_PER_EPISODE`] violations.
    pub kept: Vec<Violation>,
}

impl LineCheck {
    /// A checker for `timer`, samples every `period_clocks`, the local sample index 0 being
    /// global sample `global_of_local0`, the first scene's caps `limits`.
    pub fn new(
        timer: BurstTimer,
        period_clocks: u64,
        global_of_local0: u64,
        limits: &SafetyLimits,
    ) -> Self {
        Self {
            timer,
            period_clocks: period_clocks.max(1),
            global_of_local0,
            caps: Caps::of(limits, &timer),
            before: Caps::of(limits, &timer),
            changed_at: None,
            high: None,
            done: None,
            active: None,
            pending: None,
            pulse_rise_at: None,
            spans: VecDeque::new(),
            recent: VecDeque::new(),
            open_windows: VecDeque::new(),
            changes: VecDeque::new(),
            sources: 0,
            pulses: 0,
            count: 0,
            by_rule: [0; Rule::ALL.len()],
            kept: Vec::new(),
        }
    }

    /// The global sample index of the sample period holding kernel-clock time `t`.
    pub fn sample_at(&self, t: u64) -> u64 {
        (t / self.period_clocks).wrapping_add(self.global_of_local0)
    }

    /// Records a violation at global sample `sample`.
    pub fn violate(&mut self, rule: Rule, sample: u64, detail: String) {
        self.count += 1;
        self.by_rule[rule.index()] += 1;
        if self.kept.len() < KEPT_PER_EPISODE {
            self.kept.push(Violation {
                rule,
                sample,
                detail,
            });
        }
    }

    /// A scene with `limits` was loaded, the core seeing it from the sample at kernel-clock time
    /// `at`: its caps from then on, and the pulses in flight judged against the looser of old and
    /// new. The timer model has run only up to the previous sample, so a pulse rising up to `at`
    /// is the old scene's too (an update event loading what the old scene preloaded).
    pub fn scene(&mut self, limits: &SafetyLimits, at: u64) {
        let caps = Caps::of(limits, &self.timer);
        if self.changed_at.is_none_or(|c| at > c) {
            self.before = self.caps;
        } else {
            // Several loads at one sample: all of them were in force.
            self.before.loosen(self.caps);
        }
        self.changed_at = Some(at);
        self.changes.push_back(at);
        self.caps = caps;
        if let Some(h) = self.high.as_mut() {
            h.caps.loosen(caps);
        }
    }

    /// The line must be low over local sample period `k` (pushed before that sample is run):
    /// an injected sensor fault holds it off.
    pub fn must_be_off(&mut self, k: u64) {
        self.must_be_off_for(k, Rule::OnDuringFault);
    }

    /// The line must be low over local sample period `k`, or `rule` is broken.
    pub fn must_be_off_for(&mut self, k: u64, rule: Rule) {
        let (a, b) = (k * self.period_clocks, (k + 1) * self.period_clocks);
        match self.spans.back_mut() {
            Some(s) if s.b == a && s.rule == rule => s.b = b,
            _ => self.spans.push_back(Span {
                a,
                b,
                reported: false,
                rule,
            }),
        }
    }

    /// One step's output: the core's action at `action_t` (if any) and the edges the timer
    /// recorded since the last call, in time order. `now` is the time up to which the timer
    /// has run.
    pub fn step(&mut self, action: Option<(u64, GateAction)>, edges: &[Edge], now: u64) {
        self.step_many(action.as_slice(), edges, now);
    }

    /// [`Self::step`] with any number of actions, in time order (the plane soak's reading and
    /// its watchdog tick may both act in one frame).
    pub fn step_many(&mut self, actions: &[(u64, GateAction)], edges: &[Edge], now: u64) {
        let mut next = 0;
        for e in edges {
            // Edges before an action come first. At its very time, the timer's own edges (an
            // update event's) precede it, except a Start's or Pulse's rise and an Off's fall,
            // which it makes.
            while let Some(&(ta, a)) = actions.get(next) {
                if e.t <= ta {
                    break;
                }
                self.action(ta, a);
                next += 1;
            }
            let at_action = actions
                .get(next)
                .filter(|(ta, _)| *ta == e.t)
                .map(|(_, a)| *a);
            if e.high {
                // A Start rises at its action; a Pulse's rise comes later (`pulse_rise_at`).
                let started = matches!(at_action, Some(GateAction::Start(_)));
                if let (true, Some(&(ta, a))) = (started, actions.get(next)) {
                    self.action(ta, a);
                    next += 1;
                }
                let pulse = self.pulse_rise_at == Some(e.t);
                if pulse {
                    self.pulse_rise_at = None;
                }
                self.rise(e.t, started || pulse, pulse);
            } else {
                self.fall(e.t, matches!(at_action, Some(GateAction::Off)));
            }
        }
        for &(ta, a) in actions.get(next..).unwrap_or(&[]) {
            self.action(ta, a);
        }
        self.prune(now);
    }

    fn action(&mut self, ta: u64, a: GateAction) {
        self.pulse_rise_at = None;
        match a {
            GateAction::Start(s) => {
                self.active = Some(s);
                self.pending = None;
            }
            GateAction::Pulse(s) => {
                self.active = Some(s);
                self.pending = None;
                self.pulse_rise_at = Some(ta + s.pulse_delay_clocks());
            }
            GateAction::Update(s) => self.pending = Some(s),
            GateAction::Off => {
                self.active = None;
                self.pending = None;
            }
        }
    }

    fn rise(&mut self, r: u64, started: bool, one_pulse: bool) {
        let sample = self.sample_at(r);
        let settings = if started {
            self.active
        } else {
            // An update event: the preloaded settings take over.
            let s = self.pending.take().or(self.active);
            self.active = s;
            s
        };
        if let Some(d) = self.done.take() {
            let period = r - d.rise;
            if !started {
                let expected = d.settings.map(|s| s.period_clocks());
                // A line that never falls within its period (100 % duty) merges periods into
                // one pulse: only an Off or a one-pulse before it is wrong then.
                let merged = d.settings.is_some_and(|s| continuous(&s));
                if d.cut || !(merged || expected == Some(period)) {
                    self.violate(
                        Rule::Doubled,
                        sample,
                        format!(
                            "a rise {period} clocks after the previous one with no start, where \
                             {}",
                            match (d.cut, expected) {
                                (true, _) =>
                                    "an Off or a one-pulse had stopped the timer".to_string(),
                                (false, Some(p)) => format!("the period is {p} clocks"),
                                (false, None) => "no settings were running".to_string(),
                            }
                        ),
                    );
                }
            }
        } else if !started {
            self.violate(
                Rule::Doubled,
                sample,
                "a rise with no start and no pulse before it".to_string(),
            );
        }
        let mut caps = self.caps;
        if self.changed_at.is_some_and(|c| r <= c) {
            caps.loosen(self.before);
        }
        if started {
            self.sources += 1;
        }
        self.high = Some(High {
            rise: r,
            settings,
            caps,
            one_pulse,
            source: self.sources,
        });
        self.open_windows
            .push_back((r, self.caps.window_clocks, caps));
    }

    fn fall(&mut self, f: u64, cut: bool) {
        let Some(h) = self.high.take() else {
            return;
        };
        self.pulses += 1;
        let on = f - h.rise;
        self.judge_high(h.rise, f, on, &h.caps);
        let planned = h.settings.map(|s| s.on_clocks());
        // 100 % duty: high across whole periods until an Off or new settings end it; the
        // on-time cap above is its rule.
        let whole = planned == Some(on) || h.settings.is_some_and(|s| continuous(&s));
        let short_by_off = cut && planned.is_some_and(|p| on <= p);
        if !(whole || short_by_off) {
            self.violate(
                Rule::Runt,
                self.sample_at(h.rise),
                format!(
                    "a pulse on for {on} clocks, ended by {}, where {}",
                    if cut { "an Off" } else { "the timer" },
                    match planned {
                        Some(p) => format!("{p} clocks were planned"),
                        None => "no settings were running".to_string(),
                    }
                ),
            );
        }
        self.push_on(h.rise, f, h.source, !h.one_pulse);
        // A window reaching back past the episode's start holds nothing before it (the line
        // was off: a new controller): its budget is the whole window's.
        let w = self.caps.window_clocks;
        self.judge_window_len(f.saturating_sub(w), f, w);
        self.done = Some(Done {
            rise: h.rise,
            settings: h.settings,
            // After a one-pulse, as after an Off, the counter has stopped.
            cut: cut || h.one_pulse,
        });
    }

    /// The line high over `[rise, until)`: the on-time cap and the fault spans.
    fn judge_high(&mut self, rise: u64, until: u64, on: u64, caps: &Caps) {
        if on > caps.on_clocks {
            self.violate(
                Rule::OnTime,
                self.sample_at(rise),
                format!(
                    "the line high for {on} clocks against an on-time cap of {} clocks",
                    caps.on_clocks
                ),
            );
        }
        for i in 0..self.spans.len() {
            let s = self.spans[i];
            if s.reported || s.a >= until || s.b <= rise {
                continue;
            }
            self.spans[i].reported = true;
            let t = s.a.max(rise);
            self.violate(
                s.rule,
                self.sample_at(t),
                format!(
                    "the line high from {} clocks into a sample period the {} keep off",
                    t % self.period_clocks,
                    if s.rule == Rule::OnWhileLifted {
                        "lift and landing"
                    } else {
                        "injected faults"
                    }
                ),
            );
        }
    }

    /// Spans no pulse can reach any more: before the current rise, or before `now`; windows
    /// starting at a rise judged once over; on-times and scene changes no window can hold.
    fn prune(&mut self, now: u64) {
        let horizon = self.high.map_or(now, |h| h.rise);
        while self.spans.front().is_some_and(|s| s.b <= horizon) {
            self.spans.pop_front();
        }
        self.judge_open_windows(now);
        let w = self.caps.window_clocks;
        let keep_from = self
            .open_windows
            .front()
            .map_or(now, |&(r, _, _)| r)
            .min(horizon)
            .saturating_sub(w);
        while self.recent.front().is_some_and(|o| o.fall <= keep_from) {
            self.recent.pop_front();
        }
        while self.changes.front().is_some_and(|&c| c < keep_from) {
            self.changes.pop_front();
        }
    }

    /// Keeps an on-time for the windows that may hold it.
    fn push_on(&mut self, rise: u64, fall: u64, source: u64, periodic: bool) {
        let (before, run_longest) = match self.recent.back() {
            Some(o) => (
                o.before + (o.fall - o.rise),
                if o.source == source { o.run_longest } else { 0 },
            ),
            None => (0, 0),
        };
        self.recent.push_back(OnTime {
            rise,
            fall,
            source,
            periodic,
            before,
            run_longest: run_longest.max(fall - rise),
        });
    }

    /// Judges the windows starting at a rise that are over by `now`.
    fn judge_open_windows(&mut self, now: u64) {
        while let Some(&(r, w, caps)) = self.open_windows.front() {
            if r + w > now {
                break;
            }
            self.open_windows.pop_front();
            self.judge_window_caps(r, r + w, w, Some(caps));
        }
    }

    /// The duty rule over `[a, b)` with the caps in force (a window holding a scene change is
    /// not judged), for a window of length `len` whose part before `a` holds no on-time
    /// (`len` ≥ `b − a`).
    fn judge_window_len(&mut self, a: u64, b: u64, len: u64) {
        self.judge_window_caps(a, b, len, None);
    }

    /// [`Self::judge_window_len`] with the caps of the window's own scene when known (`None`:
    /// the caps in force now, and the previous scene's for a window over by the last change).
    fn judge_window_caps(&mut self, a: u64, b: u64, len: u64, own: Option<Caps>) {
        if self.changes.iter().any(|&c| c > a && c < b) {
            return;
        }
        // The on-times touching [a, b): a run of `recent` (time order), and the one still high.
        let first = self.recent.partition_point(|o| o.fall <= a);
        let end = self.recent.partition_point(|o| o.rise < b);
        let mut on = 0;
        let mut ends: Option<(OnTime, OnTime)> = None;
        if first < end {
            if let (Some(&f), Some(&l)) = (self.recent.get(first), self.recent.get(end - 1)) {
                on = l.before + (l.fall - l.rise) - f.before;
                on -= a.saturating_sub(f.rise).min(f.fall - f.rise);
                on -= l.fall.saturating_sub(b).min(l.fall - l.rise);
                ends = Some((f, l));
            }
        }
        if let Some(h) = self.high.filter(|h| h.rise < b) {
            on += b - h.rise.max(a);
            let still = OnTime {
                rise: h.rise,
                fall: b,
                source: h.source,
                periodic: !h.one_pulse,
                before: 0,
                run_longest: b - h.rise,
            };
            ends = Some((ends.map_or(still, |e| e.0), still));
        }
        let Some((f, l)) = ends else {
            return;
        };
        let all_periodic = f.periodic;
        let sources = (f.source, l.source);
        // The run's longest on-time up to the window's end: the last kept on-time's running
        // maximum, and the one still high.
        let kept_last = if first < end {
            self.recent.get(end - 1).map_or(0, |o| o.run_longest)
        } else {
            0
        };
        let longest = l.run_longest.max(kept_last);
        // A window over by the last change is the old scene's (its on-time was spent under it).
        let mut caps = own.unwrap_or(self.caps);
        let old_scene = own.is_none() && self.changed_at.is_some_and(|c| b <= c);
        if old_scene {
            caps.loosen(self.before);
        }
        let one_run = all_periodic && sources.0 == sources.1;
        let allowance = if one_run {
            (1000 - caps.duty_permille.min(1000)) * longest
        } else {
            0
        };
        // A window the new scene's length cuts out of the old scene's on-time (a reload
        // shortened the window) lies inside one of the old scene's longer windows, whose budget
        // is its cap × its length; any other window is judged over its own span.
        let budget_clocks = if old_scene {
            len.max(caps.window_clocks)
        } else {
            len
        };
        if on * 1000 > caps.duty_permille * budget_clocks + allowance {
            self.violate(
                Rule::Duty,
                self.sample_at(a),
                format!(
                    "{on} clocks on in a duty window of {} clocks: {:.1} ‰ against a cap of {} ‰{}",
                    budget_clocks,
                    on as f64 * 1000.0 / budget_clocks as f64,
                    caps.duty_permille,
                    if one_run { " (one periodic run)" } else { "" }
                ),
            );
        }
    }

    /// The episode ends at `end`: a pulse still high is judged up to there.
    pub fn finish(&mut self, end: u64) {
        if let Some(h) = self.high.take() {
            self.judge_high(h.rise, end, end.saturating_sub(h.rise), &h.caps);
            self.push_on(h.rise, end, h.source, !h.one_pulse);
        }
        // Windows still open are judged up to the end (the line is low after it).
        while let Some((r, w, caps)) = self.open_windows.pop_front() {
            self.judge_window_caps(r, r + w, w, Some(caps));
        }
        self.spans.clear();
        self.recent.clear();
        self.changes.clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 MHz kernel clock: one clock a µs, so the times below read as µs.
    const TIMER: BurstTimer = BurstTimer {
        clock_hz: 1_000_000,
        counter_bits: 32,
        max_burst_hz: 2_000,
    };

    fn limits(max_duty_permille: u16, max_on_time_us: u32) -> SafetyLimits {
        SafetyLimits {
            max_duty_permille,
            max_on_time_us,
            max_level_permille: 1000,
        }
    }

    /// A pulse started at `rise` (settings whose on-time is the pulse's, at 50 % duty) and
    /// stopped by an Off at its `fall`, as it was planned to end.
    fn pulse(c: &mut LineCheck, rise: u64, fall: u64) {
        let on = (fall - rise) as u32;
        let s = TimerSettings {
            psc: 0,
            arr: 2 * on - 1,
            ccr: on,
        };
        c.step(
            Some((rise, GateAction::Start(s))),
            &[Edge {
                t: rise,
                high: true,
            }],
            rise,
        );
        c.step(
            Some((fall, GateAction::Off)),
            &[Edge {
                t: fall,
                high: false,
            }],
            fall,
        );
    }

    /// The first 10^9-frame plane soak's 130 violations (`host-sim soak --plane`, 2026-11-29)
    /// were the checker's: windows opened at rises under a 561 ‰ scene waited in the queue behind
    /// an earlier scene's longer window and were judged after two later loads, by a 1 ‰ scene's
    /// caps. The episode that showed it no longer arises since the touch frame went from 347 to
    /// 280 µs, so the case is built here: every window is judged by the caps in force at its
    /// rise. Seen failing with `judge_open_windows` passing `None` for the window's own caps
    /// (the checker before the fix): duty violations, "160.0 ‰ against a cap of 1 ‰".
    #[test]
    fn a_window_judged_late_keeps_its_own_scenes_caps() {
        // Scene 0: 100 ‰ and 100 ms on, so its duty window is 1 s.
        let mut c = LineCheck::new(TIMER, 100, 0, &limits(100, 100_000));
        // 50 ms on at 0: its window [0, 1 s) holds the load below, so it is never judged, but
        // it heads the queue until 1 s.
        pulse(&mut c, 0, 50_000);
        // Scene A at 100 ms: 561 ‰, 50 ms on, a 300 ms window (the stated window's floor).
        c.scene(&limits(561, 50_000), 100_000);
        // 40 ms on every 80 ms under A: 500 ‰, within A's caps; the window at 200 ms holds
        // four pulses, 160 ms of 300 (533 ‰).
        for k in 0..4 {
            let rise = 200_000 + k * 80_000;
            pulse(&mut c, rise, rise + 40_000);
        }
        // Two loads of a 1 ‰ scene after A's first windows are over, before scene 0's window is.
        c.scene(&limits(1, 1_000), 600_000);
        c.scene(&limits(1, 1_000), 700_000);
        c.step(None, &[], 1_100_000);
        c.finish(1_200_000);
        assert_eq!(c.pulses, 5);
        assert_eq!(c.count, 0, "{:#?}", c.kept);
        // The same on-times under a scene that was in force at their rises and caps them at
        // 400 ‰ are caught: the windows are judged, and judged by their own scene's caps.
        let mut c = LineCheck::new(TIMER, 100, 0, &limits(100, 100_000));
        pulse(&mut c, 0, 50_000);
        c.scene(&limits(400, 50_000), 100_000);
        for k in 0..4 {
            let rise = 200_000 + k * 80_000;
            pulse(&mut c, rise, rise + 40_000);
        }
        c.scene(&limits(1000, 1_000_000), 600_000);
        c.scene(&limits(1000, 1_000_000), 700_000);
        c.step(None, &[], 1_100_000);
        c.finish(1_200_000);
        assert!(c.by_rule[Rule::Duty.index()] >= 1, "{:#?}", c.kept);
    }
}
