//! Transformed up-down staircases (Levitt 1971): one state machine per track, and several
//! tracks interleaved in an order drawn from a seed.
//!
//! A track presents a level, takes a correct/wrong answer and moves the level by the
//! transformed rule: `down` correct answers in a row take the level down (harder), `up` wrong
//! answers in a row take it up (easier). The level then converges on the stimulus where a down
//! step and an up step are equally likely, which for the n-down-1-up rule is the level
//! correct with probability p, p^n = 0.5 (Levitt 1971, J. Acoust. Soc. Am. 49, 467–477,
//! table I: 2-down-1-up → 70.7 %, 3-down-1-up → 79.4 %).
//!
//! Conventions, decided here and relied on by the runner:
//! - **Runs.** A correct answer adds to the run of correct answers and ends the run of wrong
//!   ones, and the reverse; a step is taken when a run reaches `down` (or `up`). After any step
//!   both runs restart at zero: every step begins a fresh sequence, as Levitt's groups of
//!   trials do, so the next down step needs `down` new correct answers. This is what makes
//!   [`Staircase::target_probability`] exact (each step is a fresh race between the two runs).
//! - **Reversal.** As Levitt: a step in the direction opposite to the previous step. The
//!   direction is the rule's decision, so a step clamped at `min`/`max` still has its
//!   direction. The reversal's level is the level of the trial whose answer reversed the
//!   track (the peak or the valley).
//! - **Step size.** The step taken on a trial uses `steps[min(r, len − 1)]` with `r` the number
//!   of reversals so far, counting one made on that very trial: the step that turns the track
//!   is already the smaller one (Levitt's suggestion of large steps until the first reversals,
//!   smaller ones for the estimate).
//! - **Stopping.** [`Staircase::done`] reports the stopping rule; answers given after it are
//!   still recorded and still move the track (data is never dropped; the runner decides).

use std::fmt;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::analysis::psychometric::reversal_threshold;

/// How a step changes the level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StepScale {
    /// `level ± step`, the step in stimulus units.
    Linear,
    /// `level × step` or `level ÷ step`, the step a factor greater than 1 (levels > 0).
    Log,
}

/// One track's rule, as a protocol file states it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StaircaseSpec {
    /// The track's name (for messages and results).
    pub name: String,
    /// The first level (higher = easier to detect).
    pub start: f64,
    /// Correct answers in a row that take the level down (harder).
    pub down: u32,
    /// Wrong answers in a row that take the level up (easier).
    pub up: u32,
    /// Step size after r reversals: `steps[min(r, len − 1)]` (stimulus units on
    /// [`StepScale::Linear`], a factor > 1 on [`StepScale::Log`]).
    pub steps: Vec<f64>,
    /// How a step changes the level.
    pub scale: StepScale,
    /// The level is clamped to `[min, max]`.
    pub min: f64,
    /// See `min`.
    pub max: f64,
    /// Stop after this many trials (this and/or `max_reversals` must be set).
    pub max_trials: Option<u32>,
    /// Stop after this many reversals.
    pub max_reversals: Option<u32>,
    /// Threshold = mean of the last N reversal levels (geometric mean on a log scale). Levitt
    /// advises an even N, so that peaks and valleys weigh alike.
    pub threshold_reversals: u32,
}

/// A spec's or a call's refusal: one sentence naming the field, its value and the rule.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum StaircaseError {
    /// A field of a track's spec breaks its rule.
    Field {
        /// The track's name.
        track: String,
        /// The field, e.g. `steps[2]`.
        field: String,
        /// Its value, as written.
        value: String,
        /// The rule it breaks, e.g. "must be a factor greater than 1 on a log scale".
        rule: &'static str,
    },
    /// [`Interleaved::new`] was given no track.
    NoTracks,
    /// [`Interleaved::respond`] named a track that does not exist.
    TrackIndex {
        /// The index given.
        track: usize,
        /// How many tracks there are.
        tracks: usize,
    },
}

impl fmt::Display for StaircaseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StaircaseError::Field {
                track,
                field,
                value,
                rule,
            } => write!(f, "staircase `{track}`: `{field}` is {value}, but it {rule}."),
            StaircaseError::NoTracks => {
                write!(f, "interleaved staircases: `specs` is empty, but at least one track is needed.")
            }
            StaircaseError::TrackIndex { track, tracks } => write!(
                f,
                "interleaved staircases: `track` is {track}, but it must be below the number of tracks, {tracks}."
            ),
        }
    }
}

impl std::error::Error for StaircaseError {}

impl StaircaseSpec {
    fn refuse(
        &self,
        field: impl Into<String>,
        value: impl fmt::Display,
        rule: &'static str,
    ) -> StaircaseError {
        StaircaseError::Field {
            track: self.name.clone(),
            field: field.into(),
            value: value.to_string(),
            rule,
        }
    }

    /// Every rule of a spec; the first one broken is returned.
    pub fn check(&self) -> Result<(), StaircaseError> {
        if self.name.trim().is_empty() {
            return Err(self.refuse("name", format!("{:?}", self.name), "must not be empty"));
        }
        if !self.min.is_finite() {
            return Err(self.refuse("min", self.min, "must be a finite number"));
        }
        if !self.max.is_finite() {
            return Err(self.refuse("max", self.max, "must be a finite number"));
        }
        if self.max <= self.min {
            return Err(self.refuse("max", self.max, "must be greater than `min`"));
        }
        if self.scale == StepScale::Log && self.min <= 0.0 {
            return Err(self.refuse("min", self.min, "must be greater than 0 on a log scale"));
        }
        if !self.start.is_finite() || self.start < self.min || self.start > self.max {
            return Err(self.refuse("start", self.start, "must lie within [`min`, `max`]"));
        }
        if self.down == 0 {
            return Err(self.refuse("down", self.down, "must be at least 1"));
        }
        if self.up == 0 {
            return Err(self.refuse("up", self.up, "must be at least 1"));
        }
        if self.steps.is_empty() {
            return Err(self.refuse("steps", "empty", "must hold at least one step size"));
        }
        for (i, &step) in self.steps.iter().enumerate() {
            match self.scale {
                StepScale::Linear if !(step.is_finite() && step > 0.0) => {
                    return Err(self.refuse(
                        format!("steps[{i}]"),
                        step,
                        "must be a finite size greater than 0 on a linear scale",
                    ));
                }
                StepScale::Log if !(step.is_finite() && step > 1.0) => {
                    return Err(self.refuse(
                        format!("steps[{i}]"),
                        step,
                        "must be a finite factor greater than 1 on a log scale",
                    ));
                }
                _ => {}
            }
        }
        if self.max_trials.is_none() && self.max_reversals.is_none() {
            return Err(self.refuse(
                "max_trials",
                "unset",
                "must be set when `max_reversals` is unset (a track needs a stopping rule)",
            ));
        }
        if self.max_trials == Some(0) {
            return Err(self.refuse("max_trials", 0, "must be at least 1 when set"));
        }
        if self.max_reversals == Some(0) {
            return Err(self.refuse("max_reversals", 0, "must be at least 1 when set"));
        }
        if self.threshold_reversals == 0 {
            return Err(self.refuse("threshold_reversals", 0, "must be at least 1"));
        }
        if let Some(max_reversals) = self.max_reversals {
            if self.max_trials.is_none() && self.threshold_reversals > max_reversals {
                return Err(self.refuse(
                    "threshold_reversals",
                    self.threshold_reversals,
                    "must not exceed `max_reversals` when that is the only stopping rule (the track would stop before it has a threshold)",
                ));
            }
        }
        Ok(())
    }
}

/// One trial of a track.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Step {
    /// The level presented on this trial.
    pub level: f64,
    /// The answer.
    pub correct: bool,
    /// Whether this answer reversed the track's direction (its level is then a reversal level).
    pub reversal: bool,
    /// The level of the track's next trial.
    pub next_level: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
enum Direction {
    Down,
    Up,
}

/// One transformed up-down track (see the module's conventions).
#[derive(Clone, Debug, Serialize)]
pub struct Staircase {
    spec: StaircaseSpec,
    level: f64,
    run_correct: u32,
    run_wrong: u32,
    last_direction: Option<Direction>,
    reversal_levels: Vec<f64>,
    trials: Vec<Step>,
}

impl Staircase {
    /// A track at its start level, or the first rule its spec breaks.
    pub fn new(spec: StaircaseSpec) -> Result<Self, StaircaseError> {
        spec.check()?;
        Ok(Self {
            level: spec.start,
            spec,
            run_correct: 0,
            run_wrong: 0,
            last_direction: None,
            reversal_levels: Vec::new(),
            trials: Vec::new(),
        })
    }

    /// The track's spec.
    pub fn spec(&self) -> &StaircaseSpec {
        &self.spec
    }

    /// The level of the next trial.
    pub fn level(&self) -> f64 {
        self.level
    }

    /// The step size the next step would take (after the reversals so far).
    pub fn step_size(&self) -> f64 {
        self.step_after(self.reversal_levels.len())
    }

    fn step_after(&self, reversals: usize) -> f64 {
        // `check` made `steps` non-empty; the fallback only keeps this total.
        let last = self.spec.steps.len().saturating_sub(1);
        self.spec
            .steps
            .get(reversals.min(last))
            .copied()
            .unwrap_or(1.0)
    }

    /// The final step size (`steps`' last), the resolution the track ends at.
    pub fn final_step(&self) -> f64 {
        self.spec.steps.last().copied().unwrap_or(1.0)
    }

    /// Record the answer to the trial at [`Self::level`] and move the track.
    pub fn respond(&mut self, correct: bool) -> Step {
        let level = self.level;
        if correct {
            self.run_correct = self.run_correct.saturating_add(1);
            self.run_wrong = 0;
        } else {
            self.run_wrong = self.run_wrong.saturating_add(1);
            self.run_correct = 0;
        }
        let direction = if self.run_correct >= self.spec.down {
            Some(Direction::Down)
        } else if self.run_wrong >= self.spec.up {
            Some(Direction::Up)
        } else {
            None
        };
        let mut reversal = false;
        if let Some(direction) = direction {
            // A fresh sequence after every step (Levitt's grouping): see the module docs.
            self.run_correct = 0;
            self.run_wrong = 0;
            if self.last_direction.is_some_and(|last| last != direction) {
                reversal = true;
                self.reversal_levels.push(level);
            }
            self.last_direction = Some(direction);
            let step = self.step_after(self.reversal_levels.len());
            let next = match (self.spec.scale, direction) {
                (StepScale::Linear, Direction::Down) => level - step,
                (StepScale::Linear, Direction::Up) => level + step,
                (StepScale::Log, Direction::Down) => level / step,
                (StepScale::Log, Direction::Up) => level * step,
            };
            self.level = next.clamp(self.spec.min, self.spec.max);
        }
        let trial = Step {
            level,
            correct,
            reversal,
            next_level: self.level,
        };
        self.trials.push(trial);
        trial
    }

    /// Whether the stopping rule (trials and/or reversals, whichever comes first) is met.
    pub fn done(&self) -> bool {
        let trials_done = self
            .spec
            .max_trials
            .is_some_and(|max| self.trials.len() >= max as usize);
        let reversals_done = self
            .spec
            .max_reversals
            .is_some_and(|max| self.reversal_levels.len() >= max as usize);
        trials_done || reversals_done
    }

    /// Every trial so far, in order.
    pub fn trials(&self) -> &[Step] {
        &self.trials
    }

    /// The levels at which the track reversed, in order.
    pub fn reversal_levels(&self) -> Vec<f64> {
        self.reversal_levels.clone()
    }

    /// The mean of the last `threshold_reversals` reversal levels (geometric mean on a log
    /// scale); `None` until there are that many.
    pub fn threshold(&self) -> Option<f64> {
        reversal_threshold(
            &self.reversal_levels,
            self.spec.threshold_reversals as usize,
            self.spec.scale,
        )
    }

    /// The proportion correct the track converges on (Levitt 1971): the p at which a step,
    /// once begun, is as likely to go down as up.
    ///
    /// With the run convention of this module each step is a race between a run of `down`
    /// correct answers and a run of `up` wrong ones. The chance that the correct run comes
    /// first (Feller, *An Introduction to Probability Theory*, vol. 1, ch. VIII, runs of
    /// successes before runs of failures), with q = 1 − p, n = `down`, m = `up`:
    ///
    /// P(down) = p^(n−1)(1 − q^m) / (p^(n−1) + q^(m−1) − p^(n−1) q^(m−1)),
    ///
    /// which is p^n for the n-down-1-up rule (so p^n = 0.5: 0.7071, 0.7937, 0.8409 for n = 2,
    /// 3, 4) and 1 − q^m for 1-down-m-up (0.2929 for m = 2), Levitt's table I entries. Solved
    /// for P(down) = 0.5 by bisection (P(down) rises with p).
    pub fn target_probability(&self) -> f64 {
        target_probability(self.spec.down, self.spec.up)
    }
}

/// The chance that a step of an n-down-m-up track goes down, at proportion correct `p`
/// (see [`Staircase::target_probability`]).
pub fn p_step_down(p: f64, down: u32, up: u32) -> f64 {
    if p.is_nan() {
        return f64::NAN;
    }
    let p = p.clamp(0.0, 1.0);
    let q = 1.0 - p;
    let a = p.powi(down.saturating_sub(1).min(i32::MAX as u32) as i32);
    let b = q.powi(up.saturating_sub(1).min(i32::MAX as u32) as i32);
    let q_m = q.powi(up.min(i32::MAX as u32) as i32);
    // = 1 − (1 − a)(1 − b): zero only if a = b = 0, i.e. p = 0 and q = 0 at once, which
    // cannot be; so the division is safe on [0, 1].
    let denominator = a + b - a * b;
    a * (1.0 - q_m) / denominator
}

/// The proportion correct an n-down-m-up track converges on (see
/// [`Staircase::target_probability`]); `down` or `up` of 0 is read as 1.
pub fn target_probability(down: u32, up: u32) -> f64 {
    let (down, up) = (down.max(1), up.max(1));
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if p_step_down(mid, down, up) < 0.5 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-15 {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// Several tracks presented in a random order drawn from a seed (ChaCha8), so that a
/// participant cannot follow any one track (Levitt 1971, interleaved tracks).
///
/// [`Self::next`] picks uniformly among the tracks not yet done and keeps that pick until it
/// is answered, so asking twice does not change the order.
#[derive(Clone, Debug)]
pub struct Interleaved {
    tracks: Vec<Staircase>,
    rng: ChaCha8Rng,
    pending: Option<usize>,
}

impl Interleaved {
    /// Tracks from their specs (the first broken rule of any is returned), ordered from `seed`.
    pub fn new(specs: Vec<StaircaseSpec>, seed: u64) -> Result<Self, StaircaseError> {
        if specs.is_empty() {
            return Err(StaircaseError::NoTracks);
        }
        let tracks = specs
            .into_iter()
            .map(Staircase::new)
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            tracks,
            rng: ChaCha8Rng::seed_from_u64(seed),
            pending: None,
        })
    }

    /// The track of the next trial (its level is `tracks()[i].level()`), or `None` when every
    /// track is done.
    // Not `Iterator::next`: the pick stays until answered, and the answer comes back through
    // `respond`, so a `for` loop over it would be wrong.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Option<usize> {
        if let Some(track) = self.pending {
            if self.tracks.get(track).is_some_and(|t| !t.done()) {
                return Some(track);
            }
        }
        let open: Vec<usize> = (0..self.tracks.len())
            .filter(|&i| !self.tracks[i].done())
            .collect();
        if open.is_empty() {
            self.pending = None;
            return None;
        }
        let pick = open[self.rng.random_range(0..open.len())];
        self.pending = Some(pick);
        Some(pick)
    }

    /// Record the answer to a trial of `track`.
    pub fn respond(&mut self, track: usize, correct: bool) -> Result<Step, StaircaseError> {
        let tracks = self.tracks.len();
        let staircase = self
            .tracks
            .get_mut(track)
            .ok_or(StaircaseError::TrackIndex { track, tracks })?;
        if self.pending == Some(track) {
            self.pending = None;
        }
        Ok(staircase.respond(correct))
    }

    /// Whether every track is done.
    pub fn done(&self) -> bool {
        self.tracks.iter().all(Staircase::done)
    }

    /// The tracks, in the order of their specs.
    pub fn tracks(&self) -> &[Staircase] {
        &self.tracks
    }
}
