//! Scheffé's paired comparisons and their variants: scale values, the analysis of variance and the
//! studentized-range yardsticks from graded judgments of pairs. No I/O; results as data.
//!
//! Each judgment grades the first-presented stimulus against the second (positive: the first
//! judged more, e.g. rougher). Four designs, each with its own analysis:
//!
//! | variant | order effect | each subject judges |
//! |---|---|---|
//! | Scheffé (1952), the original | modelled | one ordered pair; each ordered pair by n subjects |
//! | Haga | not modelled | one pair; each unordered pair by n subjects, either order |
//! | Ura (1958) | modelled, with its subject interaction | every ordered pair once |
//! | Nakaya (1970) | not modelled | every unordered pair once, either order |
//!
//! The formulas, their sources and the worked examples the tests hold the code to are in
//! `docs/experiment-analysis.md`. Every F is tested against the error mean square; the yardstick
//! Y_φ = q(φ; t, f_e) sqrt(σ̂² / (2 t n)) with order in the design, sqrt(σ̂² / (t n)) without, is
//! the least difference of two scale values significant at level φ (Tukey's studentized range).

use std::collections::HashMap;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::dist::{f_upper, qtukey};

/// The studentized range's quantile, remembered: a study's yardsticks ask for the same few
/// (level, t, error df) every time, and each is a nested quadrature inverted by a root finder
/// (tens of ms) — planning runs hundreds of studies.
fn quantile(p: f64, k: u32, df: f64) -> f64 {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static MEMO: OnceLock<Mutex<HashMap<(u64, u32, u64), f64>>> = OnceLock::new();
    let key = (p.to_bits(), k, df.to_bits());
    let memo = MEMO.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(q) = memo.lock().ok().and_then(|m| m.get(&key).copied()) {
        return q;
    }
    let q = qtukey(p, k, df);
    if let Ok(mut m) = memo.lock() {
        // Bounded: a long-running caller with ever new designs does not grow it without end.
        if m.len() > 4096 {
            m.clear();
        }
        m.insert(key, q);
    }
    q
}

/// One graded comparison: `subject` was shown `first`, then `second`, and graded the first
/// against the second by `score` grades (positive: the first judged more).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Judgment {
    pub subject: String,
    pub first: String,
    pub second: String,
    pub score: f64,
}

/// The paired-comparison design, hence the analysis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Variant {
    /// Scheffé (1952): order effect; each subject judges one pair, each ordered pair by its own
    /// subjects, equally many.
    Scheffe,
    /// Ura (1958): order effect; every subject judges every ordered pair once.
    Ura,
    /// Haga: no order effect; each subject judges one pair, each unordered pair equally often.
    Haga,
    /// Nakaya (1970): no order effect; every subject judges every unordered pair once.
    Nakaya,
}

impl Variant {
    /// The name the error sentences use.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Scheffe => "Scheffé's original design",
            Variant::Ura => "Ura's variant",
            Variant::Haga => "Haga's variant",
            Variant::Nakaya => "Nakaya's variant",
        }
    }

    /// Whether the design separates the order of presentation (Scheffé, Ura).
    pub fn has_order_effect(self) -> bool {
        matches!(self, Variant::Scheffe | Variant::Ura)
    }
}

impl fmt::Display for Variant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A line of the analysis of variance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Source {
    /// The stimuli's main effects α_i (the scale).
    MainEffect,
    /// Subjects' own scales, α_ik (Ura, Nakaya).
    MainBySubject,
    /// Deviation from subtractivity, γ_ij: what a pair adds beyond α_i − α_j.
    Combination,
    /// Order of presentation: δ_ij per pair (Scheffé), the average δ (Ura).
    Order,
    /// Subjects' own order effects, δ_k (Ura).
    OrderBySubject,
    Error,
    Total,
}

/// A line of the table. `ms` is `None` for the total and for lines without degrees of freedom;
/// `f` and `p` are `None` for the error and the total, for lines without degrees of freedom, and
/// when the error has no degrees of freedom or no variance to test against.
#[derive(Clone, Debug, Serialize)]
pub struct AnovaRow {
    pub source: Source,
    pub ss: f64,
    pub df: f64,
    pub ms: Option<f64>,
    pub f: Option<f64>,
    pub p: Option<f64>,
}

/// The least significant difference of two scale values at level `alpha`: `y` = `q` ×
/// sqrt(MS_error / divisor), `q` the upper-`alpha` point of the studentized range of t means on
/// the error's degrees of freedom, the divisor 2 t n with an order effect in the design (Scheffé,
/// Ura) and t n without (Haga, Nakaya).
#[derive(Clone, Debug, Serialize)]
pub struct Yardstick {
    pub alpha: f64,
    pub q: f64,
    pub y: f64,
    /// The pairs whose scale values differ by more than `y`, as (higher, lower), in the order of
    /// `stimuli`.
    pub separated: Vec<(String, String)>,
}

/// A subject's own scale, α̂_i + α̂_ik, in the order of `stimuli` (Ura, Nakaya).
#[derive(Clone, Debug, Serialize)]
pub struct SubjectScale {
    pub subject: String,
    pub scale: Vec<f64>,
}

/// What the analysis returns.
#[derive(Clone, Debug, Serialize)]
pub struct PairedAnalysis {
    pub variant: Variant,
    /// In order of first appearance in the judgments.
    pub stimuli: Vec<String>,
    /// α̂_i, in the order of `stimuli`; they sum to 0. In grades of the judgments' scale.
    pub scale: Vec<f64>,
    /// In order of first appearance.
    pub subjects: Vec<String>,
    /// n: judgments of each ordered pair (Scheffé), of each unordered pair (Haga), or the number
    /// of subjects (Ura, Nakaya).
    pub replications: usize,
    /// The lines the variant has, sources in the order of [`Source`], then error and total.
    pub anova: Vec<AnovaRow>,
    /// At 5 % and 1 %; empty when the error has no degrees of freedom.
    pub yardstick: Vec<Yardstick>,
    /// The average order effect δ̂ in grades (positive: the first presented judged more), for the
    /// variants with an order effect.
    pub order_effect: Option<f64>,
    /// Each subject's own scale (Ura, Nakaya); empty otherwise.
    pub subject_scales: Vec<SubjectScale>,
}

/// Why the judgments cannot be analysed.
#[non_exhaustive]
#[derive(Clone, Debug, PartialEq)]
pub enum PairedError {
    NoJudgments,
    /// A subject or stimulus name is empty (`field`: "subject", "first" or "second"); rows count
    /// from 1.
    EmptyName {
        row: usize,
        field: &'static str,
    },
    SelfComparison {
        row: usize,
        stimulus: String,
    },
    /// NaN or infinite.
    BadScore {
        row: usize,
        score: f64,
    },
    TooFewStimuli {
        found: usize,
    },
    /// The same pair `count` times from one subject where the variant allows it once.
    Repeated {
        subject: String,
        first: String,
        second: String,
        count: usize,
        variant: Variant,
    },
    /// The counts of judgments do not make the balanced design a variant needs.
    Unbalanced {
        reason: String,
    },
}

impl fmt::Display for PairedError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PairedError::NoJudgments => write!(f, "there are no judgments to analyse"),
            PairedError::EmptyName { row, field } => {
                write!(f, "the {field} name in row {row} is empty")
            }
            PairedError::SelfComparison { row, stimulus } => {
                write!(
                    f,
                    "stimulus \"{stimulus}\" is compared with itself in row {row}"
                )
            }
            PairedError::BadScore { row, score } => {
                write!(
                    f,
                    "the score in row {row} is {score}, not a number of grades"
                )
            }
            PairedError::TooFewStimuli { found } => {
                write!(f, "fewer than 2 stimuli: the judgments name {found}")
            }
            PairedError::Repeated {
                subject,
                first,
                second,
                count,
                variant,
            } => write!(
                f,
                "subject {subject} judged pair ({first}, {second}) {}, which {} does not allow",
                times(*count),
                variant.name()
            ),
            PairedError::Unbalanced { reason } => write!(f, "the design is unbalanced: {reason}"),
        }
    }
}

impl std::error::Error for PairedError {}

/// The judgments indexed: stimuli and subjects numbered in order of first appearance.
struct Indexed {
    stimuli: Vec<String>,
    subjects: Vec<String>,
    /// (subject, first, second, score) by index.
    rows: Vec<(usize, usize, usize, f64)>,
}

fn index(judgments: &[Judgment]) -> Result<Indexed, PairedError> {
    if judgments.is_empty() {
        return Err(PairedError::NoJudgments);
    }
    let mut stimuli: Vec<String> = Vec::new();
    let mut subjects: Vec<String> = Vec::new();
    let mut stimulus_index: HashMap<String, usize> = HashMap::new();
    let mut subject_index: HashMap<String, usize> = HashMap::new();
    // The number of a name, given on its first appearance.
    let number = |name: &str, index: &mut HashMap<String, usize>, names: &mut Vec<String>| {
        *index.entry(name.to_string()).or_insert_with(|| {
            names.push(name.to_string());
            names.len() - 1
        })
    };
    let mut rows = Vec::with_capacity(judgments.len());
    for (i, j) in judgments.iter().enumerate() {
        let row = i + 1;
        for (field, name) in [
            ("subject", &j.subject),
            ("first", &j.first),
            ("second", &j.second),
        ] {
            if name.is_empty() {
                return Err(PairedError::EmptyName { row, field });
            }
        }
        if j.first == j.second {
            return Err(PairedError::SelfComparison {
                row,
                stimulus: j.first.clone(),
            });
        }
        if !j.score.is_finite() {
            return Err(PairedError::BadScore {
                row,
                score: j.score,
            });
        }
        let first = number(&j.first, &mut stimulus_index, &mut stimuli);
        let second = number(&j.second, &mut stimulus_index, &mut stimuli);
        let subject = number(&j.subject, &mut subject_index, &mut subjects);
        rows.push((subject, first, second, j.score));
    }
    if stimuli.len() < 2 {
        return Err(PairedError::TooFewStimuli {
            found: stimuli.len(),
        });
    }
    Ok(Indexed {
        stimuli,
        subjects,
        rows,
    })
}

/// Counts of judgments: per subject and ordered pair, per ordered pair, per subject.
struct Counts {
    t: usize,
    subject_pair: Vec<Vec<Vec<usize>>>,
    pair: Vec<Vec<usize>>,
    per_subject: Vec<usize>,
}

impl Counts {
    fn of(ix: &Indexed) -> Counts {
        let t = ix.stimuli.len();
        let mut subject_pair = vec![vec![vec![0; t]; t]; ix.subjects.len()];
        let mut pair = vec![vec![0; t]; t];
        let mut per_subject = vec![0; ix.subjects.len()];
        for &(k, i, j, _) in &ix.rows {
            subject_pair[k][i][j] += 1;
            pair[i][j] += 1;
            per_subject[k] += 1;
        }
        Counts {
            t,
            subject_pair,
            pair,
            per_subject,
        }
    }

    fn ordered_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let t = self.t;
        (0..t).flat_map(move |i| (0..t).filter(move |&j| j != i).map(move |j| (i, j)))
    }

    fn unordered_pairs(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let t = self.t;
        (0..t).flat_map(move |i| (i + 1..t).map(move |j| (i, j)))
    }
}

/// "never", "once", "twice", "3 times".
fn times(n: usize) -> String {
    match n {
        0 => "never".to_string(),
        1 => "once".to_string(),
        2 => "twice".to_string(),
        n => format!("{n} times"),
    }
}

/// Whether the data make the variant's design; `Ok(n)` with its replication count.
fn check(ix: &Indexed, counts: &Counts, variant: Variant) -> Result<usize, PairedError> {
    let name = |i: usize| ix.stimuli[i].as_str();
    let pair_name = |i: usize, j: usize| format!("({}, {})", name(i), name(j));
    match variant {
        Variant::Scheffe | Variant::Haga => {
            // One judgment per subject: a subject's judgments would otherwise share the subject's
            // own scale, which these designs leave in the error.
            if let Some(k) = counts.per_subject.iter().position(|&c| c != 1) {
                return Err(PairedError::Unbalanced {
                    reason: format!(
                        "subject {} made {} judgments, but in {} each subject judges one pair \
                         (Ura's and Nakaya's variants take subjects who judge every pair)",
                        ix.subjects[k],
                        counts.per_subject[k],
                        variant.name()
                    ),
                });
            }
            if variant == Variant::Scheffe {
                let pairs: Vec<(usize, usize)> = counts.ordered_pairs().collect();
                let (i0, j0) = pairs[0];
                let n = counts.pair[i0][j0];
                for &(i, j) in &pairs {
                    if counts.pair[i][j] != n || n == 0 {
                        return Err(PairedError::Unbalanced {
                            reason: format!(
                                "ordered pair {} was judged {} and {} {}, but {} needs every \
                                 ordered pair judged equally often",
                                pair_name(i0, j0),
                                times(n),
                                pair_name(i, j),
                                times(counts.pair[i][j]),
                                variant.name()
                            ),
                        });
                    }
                }
                Ok(n)
            } else {
                let both = |i: usize, j: usize| counts.pair[i][j] + counts.pair[j][i];
                let pairs: Vec<(usize, usize)> = counts.unordered_pairs().collect();
                let (i0, j0) = pairs[0];
                let n = both(i0, j0);
                for &(i, j) in &pairs {
                    if both(i, j) != n || n == 0 {
                        return Err(PairedError::Unbalanced {
                            reason: format!(
                                "pair {} was judged {} and {} {}, but {} needs every pair \
                                 judged equally often",
                                pair_name(i0, j0),
                                times(n),
                                pair_name(i, j),
                                times(both(i, j)),
                                variant.name()
                            ),
                        });
                    }
                }
                Ok(n)
            }
        }
        Variant::Ura => {
            for (k, subject) in ix.subjects.iter().enumerate() {
                for (i, j) in counts.ordered_pairs() {
                    match counts.subject_pair[k][i][j] {
                        1 => {}
                        0 => {
                            return Err(PairedError::Unbalanced {
                                reason: format!(
                                    "subject {subject} did not judge {}, and {} needs every \
                                     ordered pair from every subject",
                                    pair_name(i, j),
                                    variant.name()
                                ),
                            })
                        }
                        count => {
                            return Err(PairedError::Repeated {
                                subject: subject.clone(),
                                first: name(i).to_string(),
                                second: name(j).to_string(),
                                count,
                                variant,
                            })
                        }
                    }
                }
            }
            Ok(ix.subjects.len())
        }
        Variant::Nakaya => {
            for (k, subject) in ix.subjects.iter().enumerate() {
                for (i, j) in counts.unordered_pairs() {
                    let c = &counts.subject_pair[k];
                    match c[i][j] + c[j][i] {
                        1 => {}
                        0 => {
                            return Err(PairedError::Unbalanced {
                                reason: format!(
                                    "subject {subject} did not judge pair {}, and {} needs every \
                                     pair from every subject",
                                    pair_name(i, j),
                                    variant.name()
                                ),
                            })
                        }
                        count => {
                            return Err(PairedError::Repeated {
                                subject: subject.clone(),
                                first: name(i).to_string(),
                                second: name(j).to_string(),
                                count,
                                variant,
                            })
                        }
                    }
                }
            }
            Ok(ix.subjects.len())
        }
    }
}

/// The variant the design the data show calls for: subjects who each made one judgment make
/// Scheffé's original design when every ordered pair was judged equally often, Haga's when only
/// the unordered pairs were; subjects who judged several pairs make Ura's variant when each judged
/// every ordered pair once, Nakaya's when each judged every unordered pair once.
pub fn infer_variant(judgments: &[Judgment]) -> Result<Variant, PairedError> {
    let ix = index(judgments)?;
    infer(&ix, &Counts::of(&ix))
}

fn infer(ix: &Indexed, counts: &Counts) -> Result<Variant, PairedError> {
    let one_each = counts.per_subject.iter().all(|&c| c == 1);
    let candidates = if one_each {
        [Variant::Scheffe, Variant::Haga]
    } else {
        [Variant::Ura, Variant::Nakaya]
    };
    let (first, second) = match (
        check(ix, counts, candidates[0]),
        check(ix, counts, candidates[1]),
    ) {
        (Ok(_), _) => return Ok(candidates[0]),
        (_, Ok(_)) => return Ok(candidates[1]),
        (Err(first), Err(second)) => (first, second),
    };
    // Neither fits. One judgment per subject: the unordered pairs' counts are already unequal
    // (Haga's complaint), which is the more basic fault. Several: explain against Ura's design
    // when some subject judged a pair in both orders, else against Nakaya's.
    let error = if one_each {
        second
    } else {
        let both_orders = |c: &Vec<Vec<usize>>| {
            counts
                .unordered_pairs()
                .any(|(i, j)| c[i][j] > 0 && c[j][i] > 0)
        };
        if counts.subject_pair.iter().any(both_orders) {
            first
        } else {
            second
        }
    };
    Err(match error {
        PairedError::Repeated {
            subject,
            first,
            second,
            ..
        } => PairedError::Unbalanced {
            reason: format!(
                "subject {subject} judged ({first}, {second}) more than once, which neither \
                 Ura's nor Nakaya's variant allows"
            ),
        },
        other => other,
    })
}

/// Sums of the judgments the analyses use, oriented: `d[k][i][j]` = Σ over subject k's judgments
/// of (i, j) minus Σ of (j, i), so d[k][j][i] = −d[k][i][j] whatever order the pair was shown in.
struct Sums {
    t: usize,
    d: Vec<Vec<Vec<f64>>>,
    /// Σ of subject k's scores as given (first over second): the order effect's raw material.
    subject_total: Vec<f64>,
    /// Σ of scores of ordered pair (i, j) as given.
    pair_total: Vec<Vec<f64>>,
    sum_squares: f64,
}

impl Sums {
    fn of(ix: &Indexed) -> Sums {
        let t = ix.stimuli.len();
        let mut d = vec![vec![vec![0.0; t]; t]; ix.subjects.len()];
        let mut subject_total = vec![0.0; ix.subjects.len()];
        let mut pair_total = vec![vec![0.0; t]; t];
        let mut sum_squares = 0.0;
        for &(k, i, j, x) in &ix.rows {
            d[k][i][j] += x;
            d[k][j][i] -= x;
            subject_total[k] += x;
            pair_total[i][j] += x;
            sum_squares += x * x;
        }
        Sums {
            t,
            d,
            subject_total,
            pair_total,
            sum_squares,
        }
    }

    /// d_ij summed over subjects.
    fn pooled(&self) -> Vec<Vec<f64>> {
        let mut pooled = vec![vec![0.0; self.t]; self.t];
        for dk in &self.d {
            for i in 0..self.t {
                for j in 0..self.t {
                    pooled[i][j] += dk[i][j];
                }
            }
        }
        pooled
    }
}

/// A line before the F tests.
struct Line {
    source: Source,
    ss: f64,
    df: usize,
}

/// Analyses the judgments by `variant`, or by the variant their design calls for
/// ([`infer_variant`]) when `None`.
pub fn analyze(
    judgments: &[Judgment],
    variant: Option<Variant>,
) -> Result<PairedAnalysis, PairedError> {
    let ix = index(judgments)?;
    let counts = Counts::of(&ix);
    let variant = match variant {
        Some(v) => v,
        None => infer(&ix, &counts)?,
    };
    let n = check(&ix, &counts, variant)?;
    let sums = Sums::of(&ix);
    let t = ix.stimuli.len();
    let (tf, nf) = (t as f64, n as f64);
    let d = sums.pooled();
    // X_i = Σ_j d_ij: for the ordered designs x_i.. − x_.i., for the unordered ones x_i.. with
    // the pair's judgments oriented towards i.
    let x: Vec<f64> = d.iter().map(|row| row.iter().sum()).collect();
    // With the order in the design every ordered pair carries n judgments, so the stimuli's totals
    // count each pair twice as often: α̂_i = X_i / (2 t n) there, X_i / (t n) without.
    let divisor = if variant.has_order_effect() {
        2.0 * tf * nf
    } else {
        tf * nf
    };
    let scale: Vec<f64> = x.iter().map(|xi| xi / divisor).collect();
    let ss_main: f64 = x.iter().map(|xi| xi * xi).sum::<f64>() / divisor;
    // Each unordered pair's oriented total d_ij carries 2n (ordered) or n (unordered) judgments.
    let pair_divisor = divisor / tf;
    let ss_pairs: f64 = (0..t)
        .flat_map(|i| (i + 1..t).map(move |j| (i, j)))
        .map(|(i, j)| d[i][j] * d[i][j])
        .sum::<f64>()
        / pair_divisor;
    let ss_combination = (ss_pairs - ss_main).max(0.0);
    let df_main = t - 1;
    let df_combination = (t - 1) * (t - 2) / 2;
    let judgments_total = ix.rows.len();
    let grand: f64 = sums.subject_total.iter().sum();

    let mut lines = vec![Line {
        source: Source::MainEffect,
        ss: ss_main,
        df: df_main,
    }];
    let mut subject_scales = Vec::new();
    let mut order_effect = None;
    match variant {
        Variant::Ura | Variant::Nakaya => {
            // Subject k's own totals X_ik over the t − 1 pairs each stimulus is in.
            let subject_divisor = divisor / nf;
            let mut ss_subject_main = 0.0;
            for (k, dk) in sums.d.iter().enumerate() {
                let xk: Vec<f64> = dk.iter().map(|row| row.iter().sum()).collect();
                ss_subject_main += xk.iter().map(|v| v * v).sum::<f64>() / subject_divisor;
                subject_scales.push(SubjectScale {
                    subject: ix.subjects[k].clone(),
                    scale: xk.iter().map(|v| v / subject_divisor).collect(),
                });
            }
            lines.push(Line {
                source: Source::MainBySubject,
                ss: (ss_subject_main - ss_main).max(0.0),
                df: (t - 1) * (n - 1),
            });
            lines.push(Line {
                source: Source::Combination,
                ss: ss_combination,
                df: df_combination,
            });
            if variant == Variant::Ura {
                // The average order effect δ over all t (t − 1) N judgments, and each subject's
                // own δ_k over its t (t − 1).
                let per_subject = (t * (t - 1)) as f64;
                let ss_order = grand * grand / (per_subject * nf);
                let ss_subject_order = sums
                    .subject_total
                    .iter()
                    .map(|s| s * s / per_subject)
                    .sum::<f64>();
                lines.push(Line {
                    source: Source::Order,
                    ss: ss_order,
                    df: 1,
                });
                lines.push(Line {
                    source: Source::OrderBySubject,
                    ss: (ss_subject_order - ss_order).max(0.0),
                    df: n - 1,
                });
                order_effect = Some(grand / judgments_total as f64);
            }
        }
        Variant::Scheffe => {
            lines.push(Line {
                source: Source::Combination,
                ss: ss_combination,
                df: df_combination,
            });
            // δ_ij per pair: the pair's two ordered totals added, over its 2n judgments.
            let ss_order = (0..t)
                .flat_map(|i| (i + 1..t).map(move |j| (i, j)))
                .map(|(i, j)| {
                    let s = sums.pair_total[i][j] + sums.pair_total[j][i];
                    s * s
                })
                .sum::<f64>()
                / (2.0 * nf);
            lines.push(Line {
                source: Source::Order,
                ss: ss_order,
                df: t * (t - 1) / 2,
            });
            order_effect = Some(grand / judgments_total as f64);
        }
        Variant::Haga => {
            lines.push(Line {
                source: Source::Combination,
                ss: ss_combination,
                df: df_combination,
            });
        }
    }
    let ss_model: f64 = lines.iter().map(|l| l.ss).sum();
    let df_model: usize = lines.iter().map(|l| l.df).sum();
    // The total is uncorrected: the model has no general mean (a pair's expected grade is
    // α_i − α_j plus order and combination terms). Rounding can leave the error a hair below 0
    // when the model fits exactly.
    let ss_error = (sums.sum_squares - ss_model).max(0.0);
    let df_error = judgments_total.saturating_sub(df_model);
    let ms_error = (df_error > 0).then(|| ss_error / df_error as f64);
    let testable_error = ms_error.filter(|&ms| ms > 0.0);

    let mut anova: Vec<AnovaRow> = lines
        .iter()
        .map(|l| {
            let ms = (l.df > 0).then(|| l.ss / l.df as f64);
            let f = match (ms, testable_error) {
                (Some(ms), Some(mse)) => Some(ms / mse),
                _ => None,
            };
            let p = f.map(|f| f_upper(f, l.df as f64, df_error as f64));
            AnovaRow {
                source: l.source,
                ss: l.ss,
                df: l.df as f64,
                ms,
                f,
                p,
            }
        })
        .collect();
    anova.push(AnovaRow {
        source: Source::Error,
        ss: ss_error,
        df: df_error as f64,
        ms: ms_error,
        f: None,
        p: None,
    });
    anova.push(AnovaRow {
        source: Source::Total,
        ss: sums.sum_squares,
        df: judgments_total as f64,
        ms: None,
        f: None,
        p: None,
    });

    // No error variance (every judgment exactly additive): no F and no yardstick either; a
    // yardstick of 0 would separate every pair.
    let yardstick = match testable_error {
        Some(mse) => [0.05, 0.01]
            .iter()
            .map(|&alpha| {
                let q = quantile(1.0 - alpha, t as u32, df_error as f64);
                let y = q * (mse / divisor).sqrt();
                let mut separated = Vec::new();
                for i in 0..t {
                    for j in i + 1..t {
                        if (scale[i] - scale[j]).abs() > y {
                            let (hi, lo) = if scale[i] > scale[j] { (i, j) } else { (j, i) };
                            separated.push((ix.stimuli[hi].clone(), ix.stimuli[lo].clone()));
                        }
                    }
                }
                Yardstick {
                    alpha,
                    q,
                    y,
                    separated,
                }
            })
            .collect(),
        None => Vec::new(),
    };

    Ok(PairedAnalysis {
        variant,
        stimuli: ix.stimuli,
        scale,
        subjects: ix.subjects,
        replications: n,
        anova,
        yardstick,
        order_effect,
        subject_scales,
    })
}
