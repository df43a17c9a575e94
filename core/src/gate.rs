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
}

/// Port: the burst timer driving the RF enable line(s).
pub trait BurstOutput {
    /// Carries out one action.
    fn apply(&mut self, action: GateAction);
}

/// The gate's state: what the enable line is doing now.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Gate {
    running: Option<TimerSettings>,
}

impl Gate {
    /// The settings the line is running, if any.
    pub fn running(&self) -> Option<TimerSettings> {
        self.running
    }

    /// Moves towards `desired` (None = off); returns the action to apply, if anything changes.
    /// Settings outside the caps are refused (line off): the planner never makes them, so this
    /// only fires on a bug, and then on the safe side.
    pub fn request(
        &mut self,
        desired: Option<TimerSettings>,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Option<GateAction> {
        let desired = desired.filter(|s| limits.allows(timer, s));
        match (self.running, desired) {
            (None, None) => None,
            (Some(_), None) => {
                self.running = None;
                Some(GateAction::Off)
            }
            (None, Some(s)) => {
                self.running = Some(s);
                Some(GateAction::Start(s))
            }
            (Some(r), Some(s)) if r == s => None,
            (Some(_), Some(s)) => {
                self.running = Some(s);
                Some(GateAction::Update(s))
            }
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
