//! Gate stage: the last word on the RF enable line — faults force it off, caps are re-checked,
//! and only changes reach the hardware port.

use crate::burst::{BurstTimer, SafetyLimits, TimerSettings};

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
    /// One pulse (a tangible line): one-pulse mode, the line high for the first `ccr` ticks, then
    /// low with the counter stopped at the update event.
    Pulse(TimerSettings),
}

/// Which IDTs are driven (SAW display paper: standing waves need 2–3 W, progressive ~100 W).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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

    /// Sets the RF drive level, ‰ of full scale (a DAC or PWM into the amplifier's gain input).
    /// The default drops the request: a board without amplitude control keeps it and says so at
    /// boot, so random amplitude and triangle envelopes degrade to full-amplitude bursts.
    fn set_amplitude(&mut self, _permille: u16) {}

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
    /// A one-pulse was fired; the hardware ends it by itself.
    Pulse,
}

/// The gate's state machine: emits only the actions that change the line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Gate {
    state: State,
}

impl Gate {
    /// The periodic settings the line is running, if any.
    pub fn running(&self) -> Option<TimerSettings> {
        match self.state {
            State::Running(s) => Some(s),
            _ => None,
        }
    }

    /// Moves towards `desired` (None = off); returns the action to apply, if anything changes.
    /// Settings outside the caps are refused (line off): the planner never makes them, so this
    /// only fires on a bug, and then on the safe side. Called after a pulse has ended, it starts
    /// afresh (the one-pulse stopped the counter by itself).
    pub fn request(
        &mut self,
        desired: Option<TimerSettings>,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        let desired = desired.filter(|s| limits.allows(timer, s));
        let (next, action) = match (self.state, desired) {
            (State::Off | State::Pulse, None) => (State::Off, None),
            (State::Running(_), None) => (State::Off, Some(GateAction::Off)),
            (State::Off | State::Pulse, Some(s)) => (State::Running(s), Some(GateAction::Start(s))),
            (State::Running(r), Some(s)) if r == s => (State::Running(r), None),
            (State::Running(_), Some(s)) => (State::Running(s), Some(GateAction::Update(s))),
        };
        self.state = next;
        action
    }

    /// Turns the line off now, whatever it does (faults): also cuts a pulse short.
    pub fn force_off(&mut self) -> Option<GateAction> {
        let was = self.state;
        self.state = State::Off;
        (was != State::Off).then_some(GateAction::Off)
    }

    /// Fires one pulse of `settings` (a line), replacing whatever runs. Refused (line off) above
    /// the on-time cap; the duty cap is kept by the caller's refractory time after the pulse.
    pub fn pulse(
        &mut self,
        settings: TimerSettings,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        if settings.on_clocks() <= limits.max_on_time_clocks(timer) {
            self.state = State::Pulse;
            Some(GateAction::Pulse(settings))
        } else {
            self.force_off()
        }
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
        assert_eq!(g.request(None, &T, &l), None);
        assert_eq!(g.request(Some(a), &T, &l), Some(GateAction::Start(a)));
        assert_eq!(g.request(Some(a), &T, &l), None);
        assert_eq!(g.request(Some(b), &T, &l), Some(GateAction::Update(b)));
        assert_eq!(g.request(None, &T, &l), Some(GateAction::Off));
        assert_eq!(g.force_off(), None);
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
        assert_eq!(g.pulse(p, &T, &l), Some(GateAction::Pulse(p)));
        assert_eq!(g.force_off(), Some(GateAction::Off));
        g.pulse(p, &T, &l);
        // After the pulse nothing is left to switch off.
        assert_eq!(g.request(None, &T, &l), None);
        let too_long = TimerSettings {
            psc: 0,
            arr: 9_000_000,
            ccr: 9_000_000,
        };
        assert_eq!(g.pulse(too_long, &T, &l), None);
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
        assert_eq!(g.request(Some(too_long), &T, &l), None);
        assert_eq!(g.running(), None);
    }
}
