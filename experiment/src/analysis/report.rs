//! The whole analysis of a data set, as data: per paired block Scheffé's scale and ANOVA with
//! Thurstone and Bradley–Terry beside it, the correlation of two blocks' scales (table 1's real
//! against virtual), per staircase track its threshold, per constant-stimuli block its
//! psychometric fits with bootstrap intervals. No I/O: `saw experiment analyze`, the Python
//! module and the charts read what this returns.

use std::collections::BTreeMap;
use std::fmt;

use serde::Serialize;

use super::input::Dataset;
use super::paired::{self, Judgment, PairedAnalysis, Variant};
use super::psychometric::{
    self, BootstrapCi, BootstrapKind, BootstrapOptions, FitOptions, LevelCount, Model,
};
use super::scaling;
use crate::staircase::{self, StepScale};

/// What the analysis is asked.
#[derive(Clone, Debug)]
pub struct Options {
    /// Force a paired-comparison variant on every paired block (None: each block's own).
    pub method: Option<Variant>,
    /// Each paired block's variant as its protocol gave it (the sidecars'); a block without
    /// one is analysed by the variant its data imply.
    pub block_methods: BTreeMap<String, Variant>,
    /// Each block's stimuli in the protocol's order (the sidecars give it): two blocks with
    /// as many stimuli are correlated in that order, as table 1 pairs #60 with 20 Hz.
    pub block_stimuli: BTreeMap<String, Vec<String>>,
    /// The reversals a staircase threshold averages (the last N) when the track's own rule is
    /// not known.
    pub threshold_reversals: usize,
    /// Each track's own rule, by (block, track): the reversals its threshold averages and its
    /// step scale (the protocol's, from the sessions' sidecars).
    pub track_rules: BTreeMap<(String, String), (usize, StepScale)>,
    /// Bootstrap resamples of the psychometric fits (0: none).
    pub bootstrap: u32,
    /// The bootstrap's seed.
    pub seed: u64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            method: None,
            block_methods: BTreeMap::new(),
            block_stimuli: BTreeMap::new(),
            threshold_reversals: 6,
            track_rules: BTreeMap::new(),
            bootstrap: 1000,
            seed: 1,
        }
    }
}

/// A paired block's results.
#[derive(Clone, Debug, Serialize)]
pub struct PairedBlock {
    /// The block.
    pub block: String,
    /// Subjects.
    pub subjects: usize,
    /// Judgments.
    pub judgments: usize,
    /// Scheffé's analysis in the variant used.
    pub scheffe: PairedAnalysis,
    /// Scheffé's scale values keyed by stimulus name.
    pub scale: BTreeMap<String, f64>,
    /// Thurstone case V (from who was judged more), keyed by stimulus.
    pub thurstone: Option<BTreeMap<String, f64>>,
    /// Bradley–Terry log-worths, keyed by stimulus.
    pub bradley_terry: Option<BTreeMap<String, f64>>,
}

/// Two blocks' scales correlated.
#[derive(Clone, Debug, Serialize)]
pub struct Correlation {
    /// The blocks.
    pub blocks: (String, String),
    /// The stimuli paired, in the protocol's order.
    pub pairs: Vec<(String, String)>,
    /// Pearson's r of the Scheffé scale values.
    pub pearson: Option<f64>,
    /// Spearman's ρ.
    pub spearman: Option<f64>,
}

/// A staircase track's results.
#[derive(Clone, Debug, Serialize)]
pub struct Track {
    /// The subject.
    pub subject: String,
    /// The block.
    pub block: String,
    /// The track.
    pub track: String,
    /// Each trial's level, in order.
    pub levels: Vec<f64>,
    /// Each trial's answer.
    pub correct: Vec<bool>,
    /// The levels of the reversals.
    pub reversal_levels: Vec<f64>,
    /// The mean of the last reversals (None: fewer than asked).
    pub threshold: Option<f64>,
    /// The reversals averaged.
    pub threshold_reversals: usize,
}

/// A constant-stimuli block's results (all its subjects pooled).
#[derive(Clone, Debug, Serialize)]
pub struct ConstantBlock {
    /// The block.
    pub block: String,
    /// Trials and correct answers per level.
    pub points: Vec<LevelCount>,
    /// The fits, with their bootstrap intervals, per model.
    pub fits: Vec<ModelFit>,
}

/// One model's fit.
#[derive(Clone, Debug, Serialize)]
pub struct ModelFit {
    /// Weibull or logistic.
    pub model: Model,
    /// The fit and its intervals (or why there is none).
    pub result: Result<BootstrapCi, String>,
}

/// Everything.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// Paired blocks.
    pub paired: Vec<PairedBlock>,
    /// Correlations of blocks' scales.
    pub correlations: Vec<Correlation>,
    /// Staircase tracks.
    pub tracks: Vec<Track>,
    /// Constant-stimuli blocks (subjects pooled: descriptive of the group's trials; a
    /// subject's own fit comes from analysing that subject's CSV alone).
    pub constant: Vec<ConstantBlock>,
    /// Blocks that could not be analysed, each with its sentence (the others are reported).
    pub refused: Vec<ReportError>,
    /// Staircase blocks' trials fitted as constant stimuli are (every level a track visited,
    /// its subjects and tracks pooled).
    pub staircase_fits: Vec<ConstantBlock>,
}

/// An analysis refused: which block, why.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReportError {
    /// The block.
    pub block: String,
    /// The sentence.
    pub message: String,
}

impl fmt::Display for ReportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use crate::protocol::one_line;
        write!(
            f,
            "block \"{}\": {}",
            one_line(&self.block),
            one_line(&self.message)
        )
    }
}

impl std::error::Error for ReportError {}

/// The most stimuli a paired block may have in the analysis.
pub const MAX_STIMULI: usize = 100;

/// Analyses `data`.
pub fn analyze(data: &Dataset, o: &Options) -> Result<Report, ReportError> {
    let mut report = Report {
        paired: Vec::new(),
        correlations: Vec::new(),
        tracks: Vec::new(),
        constant: Vec::new(),
        staircase_fits: Vec::new(),
        refused: Vec::new(),
    };
    // Paired blocks, in order of first appearance.
    let mut blocks: Vec<String> = Vec::new();
    for r in &data.paired {
        if !blocks.contains(&r.block) {
            blocks.push(r.block.clone());
        }
    }
    for b in &blocks {
        let rows: Vec<_> = data.paired.iter().filter(|r| &r.block == b).collect();
        let judgments: Vec<Judgment> = rows
            .iter()
            .map(|r| Judgment {
                subject: r.subject.clone(),
                first: r.first.clone(),
                second: r.second.clone(),
                score: r.score,
            })
            .collect();
        let err = |m: String| ReportError {
            block: b.clone(),
            message: m,
        };
        // Dense per-subject tables of t × t: a file whose stimulus columns hold ids (swapped
        // columns, say) would ask for terabytes. The protocol reader allows 20.
        let mut names: Vec<&str> = rows
            .iter()
            .flat_map(|r| [r.first.as_str(), r.second.as_str()])
            .collect();
        names.sort_unstable();
        names.dedup();
        if names.len() > MAX_STIMULI {
            report.refused.push(err(format!(
                "{} stimuli; a paired analysis takes at most {MAX_STIMULI} (are the first and second columns stimulus names?)",
                names.len()
            )));
            continue;
        }
        let method = o.method.or_else(|| o.block_methods.get(b).copied());
        let scheffe = match paired::analyze(&judgments, method) {
            Ok(a) => a,
            // One block that cannot be analysed (a subject who stopped early) does not take
            // the others down: it is listed with its sentence.
            Err(e) => {
                report.refused.push(err(e.to_string()));
                continue;
            }
        };
        let scale = keyed(&scheffe.stimuli, &scheffe.scale);
        let choices = scaling::choices_from_scores(
            &rows
                .iter()
                .map(|r| (r.first.clone(), r.second.clone(), r.score))
                .collect::<Vec<_>>(),
        );
        let thurstone = scaling::thurstone_from_choices(&choices)
            .ok()
            .map(|t| keyed(&t.items, &t.scale));
        let bradley_terry = scaling::bradley_terry(&choices)
            .ok()
            .map(|t| keyed(&t.items, &t.log_worth));
        let mut subjects: Vec<&str> = rows.iter().map(|r| r.subject.as_str()).collect();
        subjects.sort_unstable();
        subjects.dedup();
        report.paired.push(PairedBlock {
            block: b.clone(),
            subjects: subjects.len(),
            judgments: rows.len(),
            scheffe,
            scale,
            thurstone,
            bradley_terry,
        });
    }
    // Correlations: every two paired blocks whose protocol orders have as many stimuli.
    for i in 0..report.paired.len() {
        for j in i + 1..report.paired.len() {
            let (a, b) = (&report.paired[i], &report.paired[j]);
            let (Some(sa), Some(sb)) =
                (o.block_stimuli.get(&a.block), o.block_stimuli.get(&b.block))
            else {
                continue;
            };
            if sa.len() != sb.len() {
                continue;
            }
            let va: Option<Vec<f64>> = sa.iter().map(|s| a.scale.get(s).copied()).collect();
            let vb: Option<Vec<f64>> = sb.iter().map(|s| b.scale.get(s).copied()).collect();
            let (Some(va), Some(vb)) = (va, vb) else {
                continue;
            };
            report.correlations.push(Correlation {
                blocks: (a.block.clone(), b.block.clone()),
                pairs: sa.iter().cloned().zip(sb.iter().cloned()).collect(),
                pearson: scaling::pearson(&va, &vb),
                spearman: scaling::spearman(&va, &vb),
            });
        }
    }
    // Staircase tracks: per subject, block and track, in trial order.
    let mut keys: Vec<(String, String, String)> = Vec::new();
    for r in &data.intervals {
        if let Some(t) = &r.track {
            let k = (r.subject.clone(), r.block.clone(), t.clone());
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
    }
    for (subject, block, track) in keys {
        let mut rows: Vec<_> = data
            .intervals
            .iter()
            .filter(|r| {
                r.subject == subject && r.block == block && r.track.as_deref() == Some(&track)
            })
            .collect();
        rows.sort_by_key(|r| r.trial);
        let reversal_levels: Vec<f64> = rows
            .iter()
            .filter(|r| r.reversal)
            .map(|r| r.level)
            .collect();
        // The track's own rule when the protocol is known (geometric mean on a log scale),
        // else the last `threshold_reversals` on a linear one.
        let (last, scale) = o
            .track_rules
            .get(&(block.clone(), track.clone()))
            .copied()
            .unwrap_or((o.threshold_reversals, StepScale::Linear));
        let threshold = psychometric::reversal_threshold(&reversal_levels, last, scale);
        report.tracks.push(Track {
            subject,
            block,
            track,
            levels: rows.iter().map(|r| r.level).collect(),
            correct: rows.iter().map(|r| r.correct).collect(),
            reversal_levels,
            threshold,
            threshold_reversals: last,
        });
    }
    // Constant stimuli, and the staircases' trials: a psychometric fit per block, its
    // subjects pooled.
    let mut fit_blocks: Vec<(String, bool)> = Vec::new();
    for r in &data.intervals {
        let k = (r.block.clone(), r.track.is_some());
        if !fit_blocks.contains(&k) {
            fit_blocks.push(k);
        }
    }
    for (b, staircase) in fit_blocks {
        let mut points: Vec<LevelCount> = Vec::new();
        for r in data
            .intervals
            .iter()
            .filter(|r| r.track.is_some() == staircase && r.block == b)
        {
            match points.iter_mut().find(|p| p.level == r.level) {
                Some(p) => {
                    p.n_trials += 1;
                    p.n_correct += u32::from(r.correct);
                }
                None => points.push(LevelCount {
                    level: r.level,
                    n_trials: 1,
                    n_correct: u32::from(r.correct),
                }),
            }
        }
        points.sort_by(|a, b| a.level.total_cmp(&b.level));
        let fits = fit_models(&points, o);
        let block = ConstantBlock {
            block: b,
            points,
            fits,
        };
        if staircase {
            report.staircase_fits.push(block);
        } else {
            report.constant.push(block);
        }
    }
    Ok(report)
}

/// Weibull and logistic fits of `points` (two-interval: guess rate ½; the level at 70.7 %,
/// a 2-down-1-up track's target) with their bootstrap intervals.
fn fit_models(points: &[LevelCount], o: &Options) -> Vec<ModelFit> {
    let opts = FitOptions {
        guess: 0.5,
        lapse: 0.0,
        target: staircase::target_probability(2, 1),
    };
    [Model::Weibull, Model::Logistic]
        .into_iter()
        .map(|model| {
            let result = if o.bootstrap >= 2 {
                psychometric::bootstrap(
                    points,
                    model,
                    &opts,
                    &BootstrapOptions {
                        kind: BootstrapKind::Parametric,
                        n_resamples: o.bootstrap,
                        seed: o.seed,
                        confidence: 0.95,
                    },
                )
                .map_err(|e| e.to_string())
                .and_then(|ci| {
                    // A fit on the edge of its parameter space (every level answered right,
                    // say) has no maximum: its estimates and a zero-width interval would read
                    // as precise. Refused with the reason.
                    if ci.fit.degenerate {
                        Err(format!(
                            "the data have no maximum-likelihood fit (proportions correct {}): the levels do not span the threshold",
                            points
                                .iter()
                                .map(|p| format!("{}/{} at {}", p.n_correct, p.n_trials, p.level))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ))
                    } else {
                        Ok(ci)
                    }
                })
            } else {
                Err("no bootstrap asked for".to_string())
            };
            ModelFit { model, result }
        })
        .collect()
}

fn keyed(names: &[String], values: &[f64]) -> BTreeMap<String, f64> {
    names.iter().cloned().zip(values.iter().copied()).collect()
}
