//! The runner: the state machine that owns a session's order and progress. It hands out the
//! next trial (what to present, in which order, what to ask), takes the response, and resumes
//! from a log by replaying the responses given — the front ends (`saw experiment run`, the
//! panel, the Python module) present and ask, nothing more.
//!
//! Orders derive from the protocol's seed and the subject's id, so a resumed session gets the
//! same trials in the same order; counterbalancing across subjects uses the subject's index.

use std::fmt;

use crc::{Crc, CRC_64_ECMA_182};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::protocol::{Design, PairedVariant, Protocol, StimulusSource};
use crate::staircase::Interleaved;

/// One interval of a trial: a stimulus to present.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Interval {
    /// The stimulus' name (a two-interval comparison is `standard+level`, e.g. `80 Hz+4`).
    pub stimulus: String,
    /// The scene to load on the board (None: an external object, the board runs RF off).
    #[serde(skip)]
    pub scene: Option<String>,
    /// What the experimenter is told to hand over (external stimuli).
    pub prompt: Option<String>,
    /// For the simulated participant: an external object's projection radius, µm.
    pub beta_um: Option<f64>,
}

/// A trial: what to present and what to ask.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Trial {
    /// 0-based, over the whole session.
    pub number: u32,
    /// The block's name.
    pub block: String,
    /// The block's position in this subject's order, 0-based.
    pub block_number: u32,
    /// `paired`, `constant` or `staircase`.
    pub design: &'static str,
    /// The intervals, presented in this order.
    pub intervals: Vec<Interval>,
    /// The question.
    pub question: String,
    /// The response words, in the order of `values`.
    pub words: Vec<String>,
    /// The responses allowed: grades −g..=g for paired comparisons (positive: the first
    /// judged more), 1 or 2 (the interval chosen) for two-interval designs.
    pub values: Vec<i32>,
    /// The staircase track (staircase blocks).
    pub track: Option<String>,
    /// The level added to the standard (two-interval designs), in the varied key's unit.
    pub level: Option<f64>,
    /// The interval (1 or 2) holding the comparison (two-interval designs).
    pub target: Option<u8>,
    /// A break comes before this trial (a new block, or `break_every` reached).
    pub break_before: bool,
}

/// What a response did.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Outcome {
    /// The trial answered.
    pub trial: Trial,
    /// The response value.
    pub response: i32,
    /// Its word.
    pub word: String,
    /// Two-interval designs: whether the comparison's interval was chosen.
    pub correct: Option<bool>,
    /// Staircases: whether this trial's level was a reversal.
    pub reversal: Option<bool>,
}

/// A response or a resume refused.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum RunnerError {
    /// The session is over.
    Finished,
    /// The response is not one the trial allows.
    Response {
        /// The value given.
        value: i32,
        /// The values allowed.
        allowed: Vec<i32>,
    },
    /// A log replayed does not match the order this protocol and subject give.
    Diverged {
        /// The trial number.
        number: u32,
        /// What the log says was presented.
        logged: String,
        /// What the protocol gives now.
        planned: String,
    },
    /// The staircase could not be built from its spec.
    Staircase(String),
}

impl fmt::Display for RunnerError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RunnerError::Finished => write!(f, "the session is over: every trial has a response"),
            RunnerError::Response { value, allowed } => write!(
                f,
                "response {value} is not one this trial allows (it takes {})",
                allowed
                    .iter()
                    .map(|v| v.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            RunnerError::Diverged {
                number,
                logged,
                planned,
            } => write!(
                f,
                "trial {number} of the log presented {} but this protocol and subject give {}: the protocol changed since the session began, so it cannot resume",
                crate::protocol::one_line(logged),
                crate::protocol::one_line(planned)
            ),
            RunnerError::Staircase(e) => write!(f, "staircase: {e}"),
        }
    }
}

impl std::error::Error for RunnerError {}

/// A subject's order seed: the protocol's seed with a checksum of the subject's id (stable
/// across builds and machines, unlike std's hasher).
pub fn subject_seed(protocol_seed: u64, subject: &str) -> u64 {
    protocol_seed ^ Crc::<u64>::new(&CRC_64_ECMA_182).checksum(subject.as_bytes())
}

/// A block's fixed trials (paired and constant designs), or its staircase.
#[derive(Clone, Debug)]
enum Plan {
    Fixed(Vec<Trial>),
    Stairs {
        tracks: Interleaved,
        rng: ChaCha8Rng,
    },
}

/// The session's state machine.
#[derive(Clone, Debug)]
pub struct Runner {
    protocol: Protocol,
    subject: String,
    subject_index: u32,
    seed: u64,
    /// Block indices into the protocol, in this subject's order.
    order: Vec<usize>,
    /// Position in `order`.
    block_pos: usize,
    /// The current block's plan and the position in it.
    plan: Plan,
    trial_in_block: u32,
    /// Trials answered.
    answered: u32,
    /// The trial awaiting a response.
    pending: Option<Trial>,
    outcomes: Vec<Outcome>,
}

impl Runner {
    /// A session of `protocol` for `subject`, whose index (0 for the first subject of a study,
    /// 1 for the next, …) counterbalances block orders and, in the one-pair-per-subject
    /// variants, which pair the subject judges.
    pub fn new(protocol: Protocol, subject: &str, subject_index: u32) -> Result<Self, RunnerError> {
        let seed = subject_seed(protocol.seed, subject);
        let n = protocol.blocks.len();
        let first = if protocol.counterbalance_blocks {
            subject_index as usize % n
        } else {
            0
        };
        let order: Vec<usize> = (0..n).map(|k| (first + k) % n).collect();
        let mut r = Runner {
            plan: Plan::Fixed(Vec::new()),
            protocol,
            subject: subject.to_string(),
            subject_index,
            seed,
            order,
            block_pos: 0,
            trial_in_block: 0,
            answered: 0,
            pending: None,
            outcomes: Vec::new(),
        };
        r.enter_block()?;
        Ok(r)
    }

    /// Replays `responses` (the values of a log's trials, in order, each with what the log
    /// says was presented): the session continues at the first trial without a response. A
    /// log that does not match this protocol's order is refused.
    pub fn resume(
        protocol: Protocol,
        subject: &str,
        subject_index: u32,
        responses: &[(u32, Vec<String>, i32)],
    ) -> Result<Self, RunnerError> {
        let mut r = Runner::new(protocol, subject, subject_index)?;
        for (number, logged, value) in responses {
            let t = r.next_trial().ok_or(RunnerError::Finished)?;
            let planned: Vec<String> = t.intervals.iter().map(|i| i.stimulus.clone()).collect();
            if t.number != *number || &planned != logged {
                return Err(RunnerError::Diverged {
                    number: *number,
                    logged: logged.join(" then "),
                    planned: format!("trial {}: {}", t.number, planned.join(" then ")),
                });
            }
            r.respond(*value)?;
        }
        Ok(r)
    }

    /// The protocol run.
    pub fn protocol(&self) -> &Protocol {
        &self.protocol
    }

    /// The subject's id.
    pub fn subject(&self) -> &str {
        &self.subject
    }

    /// The subject's index.
    pub fn subject_index(&self) -> u32 {
        self.subject_index
    }

    /// The order seed (the protocol's with the subject's id).
    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// The blocks' names in this subject's order.
    pub fn block_order(&self) -> Vec<String> {
        self.order
            .iter()
            .map(|&b| self.protocol.blocks[b].name.clone())
            .collect()
    }

    /// The trial awaiting a response (the same until it is answered); None when the session
    /// is over.
    pub fn next_trial(&self) -> Option<&Trial> {
        self.pending.as_ref()
    }

    /// Trials answered.
    pub fn answered(&self) -> u32 {
        self.answered
    }

    /// Every outcome so far.
    pub fn outcomes(&self) -> &[Outcome] {
        &self.outcomes
    }

    /// The number of trials of the session when every block is fixed; staircases count their
    /// tracks' trial limits (an upper bound when they stop on reversals).
    pub fn planned_trials(&self) -> u32 {
        self.protocol
            .blocks
            .iter()
            .map(|b| match &b.design {
                Design::Paired {
                    variant,
                    stimuli,
                    repeats,
                } => {
                    let t = stimuli.len() as u32;
                    repeats
                        * match variant {
                            PairedVariant::Ura => t * (t - 1),
                            PairedVariant::Nakaya => t * (t - 1) / 2,
                            PairedVariant::Scheffe | PairedVariant::Haga => 1,
                        }
                }
                Design::Constant {
                    levels, repeats, ..
                } => levels.len() as u32 * repeats,
                Design::Staircase { tracks, .. } => {
                    tracks.iter().map(|t| t.max_trials.unwrap_or(0)).sum()
                }
            })
            .sum()
    }

    /// Answers the pending trial with `value`; the next trial is ready after it.
    pub fn respond(&mut self, value: i32) -> Result<Outcome, RunnerError> {
        let trial = self.pending.clone().ok_or(RunnerError::Finished)?;
        let Some(k) = trial.values.iter().position(|v| *v == value) else {
            return Err(RunnerError::Response {
                value,
                allowed: trial.values.clone(),
            });
        };
        let correct = trial.target.map(|t| value == t as i32);
        let mut reversal = None;
        match &mut self.plan {
            Plan::Stairs { tracks, .. } => {
                let track = trial
                    .track
                    .as_ref()
                    .and_then(|name| tracks.tracks().iter().position(|t| &t.spec().name == name))
                    .unwrap_or(0);
                let step = tracks
                    .respond(track, correct.unwrap_or(false))
                    .map_err(|e| RunnerError::Staircase(e.to_string()))?;
                reversal = Some(step.reversal);
            }
            Plan::Fixed(_) => {}
        }
        let outcome = Outcome {
            word: trial.words[k].clone(),
            trial,
            response: value,
            correct,
            reversal,
        };
        self.outcomes.push(outcome.clone());
        self.answered += 1;
        self.trial_in_block += 1;
        self.advance()?;
        Ok(outcome)
    }

    /// The staircases of the current block, for their thresholds.
    pub fn staircases(&self) -> Option<&Interleaved> {
        match &self.plan {
            Plan::Stairs { tracks, .. } => Some(tracks),
            Plan::Fixed(_) => None,
        }
    }

    fn enter_block(&mut self) -> Result<(), RunnerError> {
        self.trial_in_block = 0;
        if let Some(&b) = self.order.get(self.block_pos) {
            self.plan = self.plan_of(b)?;
        }
        self.advance()
    }

    /// Block `b`'s plan for this subject: its fixed trials, or its tracks with the stream
    /// that draws each trial's target interval (both from the block's own seed, so a resume
    /// replays them).
    fn plan_of(&self, b: usize) -> Result<Plan, RunnerError> {
        let block_seed = self.seed ^ (b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        let mut rng = ChaCha8Rng::seed_from_u64(block_seed);
        Ok(match &self.protocol.blocks[b].design {
            Design::Staircase { tracks, .. } => Plan::Stairs {
                tracks: Interleaved::new(tracks.clone(), rng.random())
                    .map_err(|e| RunnerError::Staircase(e.to_string()))?,
                rng,
            },
            _ => Plan::Fixed(self.fixed_trials(b, &mut rng)),
        })
    }

    fn advance(&mut self) -> Result<(), RunnerError> {
        self.advance_to_pending()
    }

    /// Sets `pending` to the next trial of this block, or enters the next block.
    fn advance_to_pending(&mut self) -> Result<(), RunnerError> {
        loop {
            let Some(&b) = self.order.get(self.block_pos) else {
                self.pending = None;
                return Ok(());
            };
            let next = match &mut self.plan {
                Plan::Fixed(trials) => trials.get(self.trial_in_block as usize).cloned(),
                Plan::Stairs { tracks, rng } => match tracks.next() {
                    None => None,
                    Some(k) => {
                        let level = tracks.tracks()[k].level();
                        let name = tracks.tracks()[k].spec().name.clone();
                        let target: u8 = if rng.random::<bool>() { 1 } else { 2 };
                        Some(self.two_interval(b, level, target, Some(name)))
                    }
                },
            };
            match next {
                Some(mut t) => {
                    t.number = self.answered;
                    t.block_number = self.block_pos as u32;
                    let every = self.protocol.break_every;
                    t.break_before = (self.trial_in_block == 0 && self.answered > 0)
                        || (every > 0 && self.answered > 0 && self.answered % every == 0);
                    self.pending = Some(t);
                    return Ok(());
                }
                None => {
                    self.block_pos += 1;
                    if self.block_pos >= self.order.len() {
                        self.pending = None;
                        return Ok(());
                    }
                    self.trial_in_block = 0;
                    self.plan = self.plan_of(self.order[self.block_pos])?;
                }
            }
        }
    }

    fn interval(&self, stimulus: usize) -> Interval {
        let s = &self.protocol.stimuli[stimulus];
        match &s.source {
            StimulusSource::Scene { text, .. } => Interval {
                stimulus: s.name.clone(),
                scene: Some(text.clone()),
                prompt: None,
                beta_um: None,
            },
            StimulusSource::External { prompt, beta_um } => Interval {
                stimulus: s.name.clone(),
                scene: None,
                prompt: Some(prompt.clone()),
                beta_um: *beta_um,
            },
        }
    }

    fn base_trial(&self, b: usize, intervals: Vec<Interval>) -> Trial {
        let block = &self.protocol.blocks[b];
        let values: Vec<i32> = match block.design {
            Design::Paired { .. } => {
                let g = (block.words.len() / 2) as i32;
                (-g..=g).collect()
            }
            _ => vec![1, 2],
        };
        Trial {
            number: 0,
            block: block.name.clone(),
            block_number: 0,
            design: block.design.name(),
            intervals,
            question: block.question.clone(),
            words: block.words.clone(),
            values,
            track: None,
            level: None,
            target: None,
            break_before: false,
        }
    }

    /// A two-interval trial of block `b` at `level`, the comparison in interval `target`.
    fn two_interval(&self, b: usize, level: f64, target: u8, track: Option<String>) -> Trial {
        let (standard, vary) = match &self.protocol.blocks[b].design {
            Design::Constant { standard, vary, .. } | Design::Staircase { standard, vary, .. } => {
                (*standard, vary.as_str())
            }
            Design::Paired { .. } => unreachable!("paired blocks have no levels"),
        };
        let std_iv = self.interval(standard);
        let cmp_iv = Interval {
            stimulus: format!("{}{:+}", std_iv.stimulus, level),
            scene: self.protocol.comparison_scene(standard, vary, level),
            prompt: None,
            beta_um: None,
        };
        let intervals = if target == 1 {
            vec![cmp_iv, std_iv]
        } else {
            vec![std_iv, cmp_iv]
        };
        let mut t = self.base_trial(b, intervals);
        t.level = Some(level);
        t.target = Some(target);
        t.track = track;
        t
    }

    /// The fixed trials of block `b` for this subject, in presentation order.
    fn fixed_trials(&self, b: usize, rng: &mut ChaCha8Rng) -> Vec<Trial> {
        let s = self.subject_index as usize;
        // The one-pair-per-subject variants pick the pair from the subject's index; when the
        // block order rotates with that index too, the pair is picked from the rotation's
        // cycle count, so that every pair is judged in every block position (otherwise, with
        // two blocks, even pairs would always come first and odd ones second).
        let pair_s = if self.protocol.counterbalance_blocks {
            s / self.protocol.blocks.len().max(1)
        } else {
            s
        };
        match &self.protocol.blocks[b].design {
            Design::Paired {
                variant,
                stimuli,
                repeats,
            } => {
                let t = stimuli.len();
                let ordered: Vec<(usize, usize)> = (0..t)
                    .flat_map(|i| (0..t).filter(move |&j| j != i).map(move |j| (i, j)))
                    .collect();
                let unordered: Vec<(usize, usize)> = (0..t)
                    .flat_map(|i| (i + 1..t).map(move |j| (i, j)))
                    .collect();
                let mut pairs: Vec<(usize, usize)> = Vec::new();
                for rep in 0..*repeats as usize {
                    match variant {
                        PairedVariant::Ura => pairs.extend(ordered.iter().copied()),
                        // Each unordered pair once; its order alternates across subjects and
                        // repeats, so the orders balance over a study.
                        PairedVariant::Nakaya => {
                            pairs.extend(unordered.iter().enumerate().map(|(k, &(i, j))| {
                                if (s + k + rep) % 2 == 0 {
                                    (i, j)
                                } else {
                                    (j, i)
                                }
                            }))
                        }
                        // One ordered pair per subject: subject n judges the n-th (mod t(t−1)),
                        // so a study of t(t−1)·r subjects covers each ordered pair r times.
                        PairedVariant::Scheffe => pairs.push(ordered[pair_s % ordered.len()]),
                        // One pair per subject in one order: the pair cycles with the subject,
                        // the order flips every full cycle.
                        PairedVariant::Haga => {
                            let (i, j) = unordered[pair_s % unordered.len()];
                            pairs.push(if (pair_s / unordered.len()) % 2 == 0 {
                                (i, j)
                            } else {
                                (j, i)
                            })
                        }
                    }
                }
                pairs.shuffle(rng);
                pairs
                    .into_iter()
                    .map(|(i, j)| {
                        let ivs = vec![self.interval(stimuli[i]), self.interval(stimuli[j])];
                        self.base_trial(b, ivs)
                    })
                    .collect()
            }
            Design::Constant {
                levels, repeats, ..
            } => {
                // Every level `repeats` times, the comparison first in half of them (the last
                // of an odd number at random), then the whole list shuffled.
                let mut plan: Vec<(f64, u8)> = Vec::new();
                for &l in levels {
                    for rep in 0..*repeats {
                        let target = if repeats % 2 == 1 && rep + 1 == *repeats {
                            if rng.random::<bool>() {
                                1
                            } else {
                                2
                            }
                        } else if rep % 2 == 0 {
                            1
                        } else {
                            2
                        };
                        plan.push((l, target));
                    }
                }
                plan.shuffle(rng);
                plan.into_iter()
                    .map(|(l, target)| self.two_interval(b, l, target, None))
                    .collect()
            }
            Design::Staircase { .. } => Vec::new(),
        }
    }
}
