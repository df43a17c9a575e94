//! Gate stage: the last word on the RF enable line — faults force it off, caps are re-checked,
//! and only changes reach the hardware port.

use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};
pub use crate::texture::Envelope;

/// What the burst-timer port must do.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GateAction {
    /// Force the enable line inactive now and stop the burst timer.
    Off,
    /// From off: load the settings, latch them with an update event, start counting from 0, so
    /// the first pulse is whole.
    Start(TimerSettings),
    /// While running: write the settings to the preload registers; they take effect at the next
    /// update event, so the current period finishes untouched (no runt, no doubled pulse).
    Update(TimerSettings),
    /// One pulse (a tangible line, a ridge): one-pulse mode from a stopped counter, which
    /// counts 0..=arr once and stops at the update event. The line is high for the last `ccr`
    /// ticks of the count, CNT = arr + 1 − ccr ..= arr, and low before and after: PWM mode 2
    /// with CCR = arr + 1 − ccr. [`BurstTimer::one_pulse`] rises one tick after the start
    /// (arr = ccr); [`BurstTimer::delayed_pulse`] later, inside the sample period (the hybrid
    /// renderer's predicted crossing).
    Pulse(TimerSettings),
}

/// Which IDTs are driven (SAW display paper: standing waves need 2–3 W, progressive ~100 W).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum DriveMode {
    /// Both IDTs driven: a standing wave (both enable outputs follow the burst).
    #[default]
    Standing,
    /// One IDT driven, the other acting as reflector-free absorber: a progressive wave (only the
    /// first enable output follows the burst).
    Progressive,
}

/// Port: the burst timer driving the RF enable line(s).
pub trait BurstOutput {
    /// Carries out one action.
    fn apply(&mut self, action: GateAction);

    /// Sets the RF drive level, ‰ of full scale (a DAC into the amplifier's gain input), for
    /// the bursts that follow. A `Start` or `Pulse` applied after it takes it from its first
    /// edge; while a burst runs it takes effect at the next update event — the next period's
    /// start, like the timer's preloaded settings — so a burst never changes level inside
    /// itself. An `Off` drops the output to level 0 and keeps the request for the next start.
    /// The default drops the request: a board without amplitude control keeps it and says so
    /// at boot, so random amplitude and triangle envelopes degrade to full-amplitude bursts.
    fn set_amplitude(&mut self, _permille: u16) {}

    /// Shape of the level over the next one-pulse: flat at the set level, or a triangle rising
    /// from 0 to it at the pulse's middle and back to 0 at its end, played by the port in
    /// hardware time (not in steps of the sample loop). Sent with every `Pulse`. The default
    /// ignores it: the pulse is flat.
    fn set_envelope(&mut self, _envelope: Envelope) {}

    /// Selects the IDTs to drive. The default ignores it: a board with one enable output is
    /// always progressive.
    fn set_drive(&mut self, _mode: DriveMode) {}
}

/// What the enable line is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
enum State {
    #[default]
    Off,
    Running(TimerSettings),
    /// A one-pulse was fired at `start_us`; the hardware ends it by itself at `end_us`
    /// (wrapping). Until then only a fault ([`Gate::force_off`]) or its texture
    /// ([`Gate::end_pulse`]) may cut it.
    Pulse {
        start_us: u32,
        end_us: u32,
    },
}

/// The gate's state machine: emits only the actions that change the line, and keeps the duty
/// cap across transitions.
///
/// The timer keeps the cap within a burst by itself (each period is long enough for its
/// on-time). Across an Off or a one-pulse it cannot: a restart would begin a new on-time at
/// once. So on leaving a running burst at `t` the gate assumes the worst — that burst's last
/// pulse ran its whole on-time up to `t` — and lets the line on again only after
/// `t + on × (1000 − cap)/cap`; after a one-pulse, only after `start + on × 1000/cap`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Gate {
    state: State,
    /// The line may go on again from this time (µs, wrapping), if set.
    earliest_on_us: Option<u32>,
    /// Longest on-time issued since the last Start, clocks. An Update only takes effect at the
    /// next update event, so the hardware may still be running an earlier, longer on-time.
    max_on_clocks: u64,
}

/// True while `t_us` is before `deadline_us` (both wrapping µs).
fn before(t_us: u32, deadline_us: u32) -> bool {
    (t_us.wrapping_sub(deadline_us) as i32) < 0
}

/// µs the line must stay off after an on-time of `on_clocks`, so on/(on + rest) ≤ cap.
fn rest_us(on_clocks: u64, timer: &BurstTimer, limits: &SafetyLimits) -> u32 {
    rest_after_us(timer.clocks_to_us_ceil(on_clocks), limits)
}

/// µs the line must stay off after an on-time of `on_us`, so on/(on + rest) ≤ cap.
fn rest_after_us(on_us: u64, limits: &SafetyLimits) -> u32 {
    let cap = limits.max_duty_permille.max(1) as u64;
    (on_us * (1000 - cap.min(1000)))
        .div_ceil(cap)
        .min(u32::MAX as u64 / 2) as u32
}

impl Gate {
    /// The periodic settings the line is running, if any.
    pub fn running(&self) -> Option<TimerSettings> {
        match self.state {
            State::Running(s) => Some(s),
            _ => None,
        }
    }

    /// True when `desired` is what the line already does: the same burst running, or off and
    /// staying off. [`Gate::request`] returns at once then; callers may skip it (and the caps).
    pub fn steady(&self, desired: Option<TimerSettings>) -> bool {
        match (self.state, desired) {
            (State::Running(r), Some(s)) => r == s,
            (State::Off, None) => true,
            _ => false,
        }
    }

    fn may_go_on(&self, t_us: u32) -> bool {
        self.earliest_on_us.is_none_or(|e| !before(t_us, e))
    }

    /// Leaving a running burst at `t_us`: the worst-case rest before the line may go on again.
    fn leave_running(
        &mut self,
        s: &TimerSettings,
        t_us: u32,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) {
        let on = self.max_on_clocks.max(s.on_clocks());
        self.earliest_on_us = Some(t_us.wrapping_add(rest_us(on, timer, limits)));
    }

    /// Moves towards `desired` (None = off) at time `t_us`; returns the action to apply, if
    /// anything changes. Unchanged settings return at once (this runs every sample). Settings
    /// outside the caps are refused (line off): the planner never makes them, so this only fires
    /// on a bug, and then on the safe side. A start inside the rest after an Off or a pulse is
    /// held back (None) and happens on the first request after the rest.
    pub fn request(
        &mut self,
        desired: Option<TimerSettings>,
        t_us: u32,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        if self.steady(desired) {
            return None;
        }
        let desired = desired.filter(|s| limits.allows(timer, s));
        match (self.state, desired) {
            (State::Pulse { end_us, .. }, None) if before(t_us, end_us) => None,
            (State::Off | State::Pulse { .. }, None) => {
                self.state = State::Off;
                None
            }
            (State::Running(r), None) => {
                self.leave_running(&r, t_us, timer, limits);
                self.state = State::Off;
                Some(GateAction::Off)
            }
            (State::Off | State::Pulse { .. }, Some(s)) => {
                if !self.may_go_on(t_us) {
                    return None;
                }
                self.state = State::Running(s);
                self.max_on_clocks = s.on_clocks();
                Some(GateAction::Start(s))
            }
            (State::Running(_), Some(s)) => {
                self.state = State::Running(s);
                self.max_on_clocks = self.max_on_clocks.max(s.on_clocks());
                Some(GateAction::Update(s))
            }
        }
    }

    /// Turns the line off now, whatever it does (faults): also cuts a pulse short.
    pub fn force_off(
        &mut self,
        t_us: u32,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        let was = self.state;
        if let State::Running(r) = was {
            self.leave_running(&r, t_us, timer, limits);
        }
        self.state = State::Off;
        (was != State::Off).then_some(GateAction::Off)
    }

    /// Ends a running one-pulse early at `t_us` (its texture says the finger has left the
    /// ridge); the rest then follows the on-time actually spent. Nothing when no pulse is on.
    pub fn end_pulse(&mut self, t_us: u32, limits: &SafetyLimits) -> Option<GateAction> {
        let State::Pulse { start_us, end_us } = self.state else {
            return None;
        };
        if !before(t_us, end_us) {
            return None;
        }
        let on = t_us.wrapping_sub(start_us);
        self.state = State::Off;
        self.earliest_on_us = Some(t_us.wrapping_add(rest_after_us(on as u64, limits)));
        Some(GateAction::Off)
    }

    /// Fires one pulse of `settings` (a line) at `t_us`. Refused (None, nothing changes) while a
    /// burst runs or inside the rest after one, since the pulse would add its on-time to an
    /// on-time already spent; refused (line off) above the on-time cap.
    pub fn pulse(
        &mut self,
        settings: TimerSettings,
        t_us: u32,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        if settings.on_clocks() > limits.max_on_time_clocks(timer) {
            return self.force_off(t_us, timer, limits);
        }
        if matches!(self.state, State::Running(_)) || !self.may_go_on(t_us) {
            return None;
        }
        let end_us = t_us.wrapping_add(timer.clocks_to_us_ceil(settings.on_clocks()) as u32);
        self.state = State::Pulse {
            start_us: t_us,
            end_us,
        };
        self.earliest_on_us =
            Some(end_us.wrapping_add(rest_us(settings.on_clocks(), timer, limits)));
        Some(GateAction::Pulse(settings))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: BurstTimer = BurstTimer {
        clock_hz: 90_000_000,
        counter_bits: 32,
        max_burst_hz: 5_000,
    };

    #[test]
    fn transitions() {
        let l = SafetyLimits::default();
        let a = TimerSettings {
            psc: 0,
            arr: 999,
            ccr: 400,
        };
        let b = TimerSettings {
            psc: 0,
            arr: 499,
            ccr: 200,
        };
        let mut g = Gate::default();
        assert_eq!(g.request(None, 0, &T, &l), None);
        assert_eq!(g.request(Some(a), 0, &T, &l), Some(GateAction::Start(a)));
        assert_eq!(g.request(Some(a), 100, &T, &l), None);
        assert_eq!(g.request(Some(b), 200, &T, &l), Some(GateAction::Update(b)));
        assert_eq!(g.request(None, 300, &T, &l), Some(GateAction::Off));
        assert_eq!(g.force_off(400, &T, &l), None);
    }

    #[test]
    fn over_cap_is_refused() {
        let l = SafetyLimits::default();
        let too_long = TimerSettings {
            psc: 0,
            arr: 999,
            ccr: 600,
        };
        let mut g = Gate::default();
        assert_eq!(g.request(Some(too_long), 0, &T, &l), None);
        assert_eq!(g.running(), None);
    }

    /// 20 Hz at 40 %: 20 ms on. After an Off the line stays off for 20 ms (cap 50 %).
    #[test]
    fn restart_after_off_waits_out_the_rest() {
        let l = SafetyLimits::default();
        let s = TimerSettings {
            psc: 0,
            arr: 4_499_999,
            ccr: 1_800_000,
        };
        let mut g = Gate::default();
        g.request(Some(s), 0, &T, &l);
        assert_eq!(g.force_off(30_000, &T, &l), Some(GateAction::Off));
        assert_eq!(g.request(Some(s), 31_000, &T, &l), None);
        assert_eq!(g.request(Some(s), 49_999, &T, &l), None);
        assert_eq!(
            g.request(Some(s), 50_000, &T, &l),
            Some(GateAction::Start(s))
        );
        // An Update to a short on-time just before the Off: the hardware may still run the long
        // one until its update event, so the rest is still the long one's.
        let short = TimerSettings {
            psc: 0,
            arr: 89_999,
            ccr: 36_000,
        };
        g.request(Some(short), 60_000, &T, &l);
        g.force_off(60_100, &T, &l);
        assert_eq!(g.request(Some(short), 79_999, &T, &l), None);
        assert!(g.request(Some(short), 80_100, &T, &l).is_some());
    }

    /// The gate keeps time as wrapping µs, so a deadline can be at most 2^31 − 1 µs (35.8 min)
    /// ahead. Limits a scene file accepts never come near it (1 s on at a 0.1 % cap rests
    /// 999 s), but `SafetyLimits` built in code can: a 3 s pulse at 1 ‰ would rest 50 min. The
    /// rest is clamped to 2^31 − 1 µs rather than wrapping into the past, which would let the
    /// line on again at once.
    #[test]
    fn rest_beyond_the_clock_range_is_clamped_not_wrapped() {
        let l = SafetyLimits {
            max_duty_permille: 1,
            max_on_time_us: 10_000_000,
            ..SafetyLimits::default()
        };
        // 3 s at 90 MHz.
        let p = TimerSettings {
            psc: 0,
            arr: 270_000_000,
            ccr: 270_000_000,
        };
        let small = TimerSettings {
            psc: 0,
            arr: 89_999,
            ccr: 80,
        };
        let mut g = Gate::default();
        assert_eq!(g.pulse(p, 0, &T, &l), Some(GateAction::Pulse(p)));
        let end_us = 3_000_000u32;
        assert_eq!(g.request(Some(small), end_us + 1_000, &T, &l), None);
        assert_eq!(g.request(Some(small), 1_000_000_000, &T, &l), None);
        let clamp_us = (1u32 << 31) - 1;
        assert_eq!(g.request(Some(small), end_us + clamp_us - 1, &T, &l), None);
        assert_eq!(
            g.request(Some(small), end_us + clamp_us, &T, &l),
            Some(GateAction::Start(small))
        );
    }

    #[test]
    fn pulses_end_by_themselves_but_faults_cut_them() {
        let l = SafetyLimits::default();
        let p = TimerSettings {
            psc: 0,
            arr: 900_000,
            ccr: 900_000,
        };
        let mut g = Gate::default();
        assert_eq!(g.pulse(p, 0, &T, &l), Some(GateAction::Pulse(p)));
        // A texture asking for nothing during the pulse does not make the gate forget it: a
        // fault must still cut it.
        assert_eq!(g.request(None, 50, &T, &l), None);
        assert_eq!(g.force_off(100, &T, &l), Some(GateAction::Off));
        // 10 ms pulse at a 50 % cap: nothing on again before 20 ms.
        assert_eq!(g.pulse(p, 19_999, &T, &l), None);
        assert_eq!(g.pulse(p, 20_000, &T, &l), Some(GateAction::Pulse(p)));
        // After the pulse nothing is left to switch off.
        assert_eq!(g.request(None, 45_000, &T, &l), None);
        assert_eq!(g.end_pulse(45_000, &l), None);
        // Ended early after 4 ms: the rest is 4 ms, not the 10 ms pulse's.
        assert_eq!(g.pulse(p, 50_000, &T, &l), Some(GateAction::Pulse(p)));
        assert_eq!(g.end_pulse(54_000, &l), Some(GateAction::Off));
        assert_eq!(g.pulse(p, 57_999, &T, &l), None);
        assert_eq!(g.pulse(p, 58_000, &T, &l), Some(GateAction::Pulse(p)));
        assert_eq!(g.end_pulse(68_000, &l), None, "ended by itself");
        assert_eq!(g.request(None, 80_000, &T, &l), None);
        let too_long = TimerSettings {
            psc: 0,
            arr: 9_000_000,
            ccr: 9_000_000,
        };
        assert_eq!(g.pulse(too_long, 90_000, &T, &l), None);
        // A running burst is never topped up by a pulse.
        let s = TimerSettings {
            psc: 0,
            arr: 999,
            ccr: 400,
        };
        g.request(Some(s), 100_000, &T, &l);
        assert_eq!(g.pulse(p, 100_100, &T, &l), None);
        assert_eq!(g.running(), Some(s));
        assert_eq!(
            g.end_pulse(100_200, &l),
            None,
            "a running burst is not a pulse"
        );
    }
}
