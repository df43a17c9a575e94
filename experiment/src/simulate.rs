//! The simulated participant in a session: answers a trial from what the board produced (the
//! f_b of each interval's exploration) or, for an object handed over, from the f_b its
//! projections stand for — through the same runner as a person. The observer model itself is
//! [`crate::observer`].

use crate::observer::{Observer, ObserverError, ObserverSpec};
use crate::runner::Trial;
use crate::session::Shown;

/// The f_b an external object's projections stand for, Hz: the spacing of a burst explored at
/// speed U is U/f_b, and the projections' spacing is taken in proportion to their radius β
/// (the same hypothesis as [`crate::observer::Percept::StickSlip`]), anchored where the seed
/// paper's table 1 puts sandpaper #60 (β = 180 µm) and 20 Hz on the same scale value
/// (−1.125 both): f_b = 3600 µm·Hz / β. #120 (80 µm) → 45 Hz, #240 (48 µm) → 75 Hz, #320
/// (34 µm) → 106 Hz. A planning hypothesis for simulations only, stated in docs/experiment.md.
pub fn external_fb_hz(beta_um: f64) -> f64 {
    3600.0 / beta_um
}

/// A simulated participant.
#[derive(Clone, Debug)]
pub struct Participant {
    observer: Observer,
}

impl Participant {
    /// From an observer's spec (its seed drives every draw).
    pub fn new(spec: ObserverSpec) -> Result<Self, ObserverError> {
        Ok(Participant {
            observer: Observer::try_new(spec)?,
        })
    }

    /// What the participant felt in interval `k`, as an f_b, Hz (0: nothing felt).
    pub fn felt_hz(trial: &Trial, k: usize, shown: &[Shown]) -> f64 {
        if let Some(beta) = trial.intervals.get(k).and_then(|i| i.beta_um) {
            return external_fb_hz(beta);
        }
        shown
            .get(k)
            .and_then(|s| s.exploration.as_ref())
            .map_or(0.0, |e| e.f_b_hz)
    }

    /// The answer to `trial` having felt `shown`: a grade for a paired comparison (from the
    /// f_b each interval produced), the interval chosen for a two-interval trial (detected
    /// at the trial's level by the observer's psychometric function).
    pub fn respond(&mut self, trial: &Trial, shown: &[Shown]) -> i32 {
        match trial.target {
            None => {
                let a = Self::felt_hz(trial, 0, shown);
                let b = Self::felt_hz(trial, 1, shown);
                self.observer.compare(a, b, trial.words.len() as u32)
            }
            Some(target) => {
                if self.observer.detect(trial.level.unwrap_or(0.0)) {
                    target as i32
                } else {
                    3 - target as i32
                }
            }
        }
    }
}
