//! Thresholds and psychometric-function fits: the staircase's reversal threshold, maximum-
//! likelihood fits of a Weibull or logistic psychometric function with fixed guess and lapse
//! rates, and percentile bootstrap intervals on threshold and slope. No I/O; results as data.
//!
//! The psychometric function (Wichmann & Hill 2001a, Percept. Psychophys. 63, 1293–1313):
//!
//! ψ(x) = γ + (1 − γ − λ) F(x; α, β)
//!
//! with γ the guess rate (0.5 for two-interval forced choice), λ the lapse rate (the errors far
//! above threshold), both fixed by the call, and
//! - Weibull: F = 1 − exp(−(x/α)^β), x ≥ 0; α is the level where F = 1 − e⁻¹ ≈ 0.632
//!   (ψ ≈ 0.816 in 2AFC with λ = 0), β a dimensionless shape;
//! - logistic: F = 1 / (1 + exp(−β(x − α))); α is the level where F = ½ (ψ = 0.75 in 2AFC with
//!   λ = 0), β in 1 / level units.
//!
//! The fit maximises Σ kᵢ ln ψ(xᵢ) + (nᵢ − kᵢ) ln(1 − ψ(xᵢ)) (the binomial log-likelihood
//! without its constant, as Palamedes' `PAL_PFML_negLL` states it) over (α, β) by Nelder–Mead
//! from the best point of a coarse grid, as Palamedes' `PAL_PFML_Fit` does. The simplex is
//! written out here (≈ 80 lines): none of the crate's dependencies has an optimiser (statrs
//! has none; argmin and friends would be a new dependency for two parameters).

use std::fmt;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Binomial, Distribution};
use serde::{Deserialize, Serialize};

use crate::staircase::StepScale;

/// The threshold of a staircase: the mean of the last `last` reversal levels, the geometric
/// mean on a [`StepScale::Log`] track (its steps are factors, so its levels are averaged as
/// logarithms). `None` when there are fewer than `last` reversals, `last` is 0, or a level is
/// not finite (or not positive on a log scale).
pub fn reversal_threshold(reversal_levels: &[f64], last: usize, scale: StepScale) -> Option<f64> {
    if last == 0 || reversal_levels.len() < last {
        return None;
    }
    let tail = &reversal_levels[reversal_levels.len() - last..];
    if tail.iter().any(|x| !x.is_finite()) {
        return None;
    }
    match scale {
        StepScale::Linear => Some(tail.iter().sum::<f64>() / last as f64),
        StepScale::Log => {
            if tail.iter().any(|&x| x <= 0.0) {
                return None;
            }
            Some((tail.iter().map(|x| x.ln()).sum::<f64>() / last as f64).exp())
        }
    }
}

/// The trials at one stimulus level.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelCount {
    /// The stimulus level (≥ 0 for the Weibull).
    pub level: f64,
    /// Trials at this level.
    pub n_trials: u32,
    /// Of them, answered correctly.
    pub n_correct: u32,
}

/// The shape F of the psychometric function.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// F = 1 − exp(−(x/α)^β).
    Weibull,
    /// F = 1 / (1 + exp(−β(x − α))).
    Logistic,
}

impl Model {
    /// F(x; α, β) in [0, 1].
    pub fn f(self, level: f64, alpha: f64, beta: f64) -> f64 {
        match self {
            Model::Weibull => {
                if level <= 0.0 {
                    0.0
                } else {
                    -(-(level / alpha).powf(beta)).exp_m1()
                }
            }
            Model::Logistic => 1.0 / (1.0 + (-beta * (level - alpha)).exp()),
        }
    }

    /// ψ(x) = γ + (1 − γ − λ) F(x; α, β).
    pub fn psi(self, level: f64, alpha: f64, beta: f64, guess: f64, lapse: f64) -> f64 {
        guess + (1.0 - guess - lapse) * self.f(level, alpha, beta)
    }

    /// The level where F = `f` (0 < f < 1), `None` outside.
    pub fn level_at_f(self, f: f64, alpha: f64, beta: f64) -> Option<f64> {
        if !(f > 0.0 && f < 1.0) {
            return None;
        }
        let x = match self {
            Model::Weibull => alpha * (-(-f).ln_1p()).powf(1.0 / beta),
            Model::Logistic => alpha + (f / (1.0 - f)).ln() / beta,
        };
        x.is_finite().then_some(x)
    }
}

/// What a fit holds fixed and what it reports.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitOptions {
    /// Guess rate γ in [0, 1): 0.5 for two-interval forced choice.
    pub guess: f64,
    /// Lapse rate λ in [0, 1), γ + λ < 1.
    pub lapse: f64,
    /// The proportion correct whose level is reported ([`Fit::level_at_target`]), e.g. 0.75
    /// or a 2-down-1-up staircase's 0.7071; it must lie strictly between γ and 1 − λ.
    pub target: f64,
}

impl Default for FitOptions {
    /// 2AFC: γ = 0.5, λ = 0, target 0.75.
    fn default() -> Self {
        Self {
            guess: 0.5,
            lapse: 0.0,
            target: 0.75,
        }
    }
}

/// A maximum-likelihood fit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Fit {
    /// The shape fitted.
    pub model: Model,
    /// Threshold α (level units).
    pub alpha: f64,
    /// Slope β (Weibull: dimensionless shape; logistic: per level unit).
    pub beta: f64,
    /// γ, as fixed by the call.
    pub guess: f64,
    /// λ, as fixed by the call.
    pub lapse: f64,
    /// Σ k ln ψ + (n − k) ln(1 − ψ) at the fit (no binomial constant).
    pub log_likelihood: f64,
    /// 2 Σ [k ln(k / nψ) + (n − k) ln((n − k) / n(1 − ψ))]: the fit against the saturated
    /// model (the residual deviance of a GLM when γ = λ = 0).
    pub deviance: f64,
    /// Levels with trials − 2.
    pub deviance_df: usize,
    /// The target proportion correct, as asked.
    pub target: f64,
    /// The level where ψ = target.
    pub level_at_target: Option<f64>,
    /// Standard error of α from the observed information (the inverse of the negative
    /// Hessian of the log-likelihood, by central differences); `None` if it is not positive
    /// definite (e.g. a [`Fit::degenerate`] one).
    pub se_alpha: Option<f64>,
    /// Standard error of β, likewise.
    pub se_beta: Option<f64>,
    /// Whether the data have no proper maximum: the fit ended at the search's bounds, or the
    /// likelihood is as high a step further towards the edge (a slope twice as steep, or the
    /// threshold moved by half itself (Weibull) or by the levels' span (logistic)). That is
    /// what data stepping from chance to perfect between two levels, or all correct, do: the
    /// best slope is infinite or the threshold unbounded. The estimates are then one point of
    /// a ridge, not a maximum, and no SE is given.
    pub degenerate: bool,
    /// Whether the simplex met its tolerance (1e-10 in −log-likelihood) within its budget.
    pub converged: bool,
    /// Log-likelihood evaluations spent.
    pub evaluations: u32,
}

impl Fit {
    /// The fitted ψ at `level`.
    pub fn psi(&self, level: f64) -> f64 {
        self.model
            .psi(level, self.alpha, self.beta, self.guess, self.lapse)
    }

    /// The level where the fitted ψ = `p`; `None` unless γ < p < 1 − λ.
    pub fn level_at(&self, p: f64) -> Option<f64> {
        let f = (p - self.guess) / (1.0 - self.guess - self.lapse);
        self.model.level_at_f(f, self.alpha, self.beta)
    }
}

/// A refusal of a fit's or a bootstrap's input: one sentence naming the field, the value and
/// the rule.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum FitError {
    /// A field breaks its rule.
    Field {
        /// The field, e.g. `data[3].n_correct`.
        field: String,
        /// Its value, as written.
        value: String,
        /// The rule, completing "but it …".
        rule: String,
    },
}

impl fmt::Display for FitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FitError::Field { field, value, rule } => {
                write!(f, "psychometric fit: `{field}` is {value}, but it {rule}.")
            }
        }
    }
}

impl std::error::Error for FitError {}

fn refuse(field: impl Into<String>, value: impl fmt::Display, rule: impl Into<String>) -> FitError {
    FitError::Field {
        field: field.into(),
        value: value.to_string(),
        rule: rule.into(),
    }
}

fn check_options(opts: &FitOptions) -> Result<(), FitError> {
    if !(opts.guess.is_finite() && (0.0..1.0).contains(&opts.guess)) {
        return Err(refuse("guess", opts.guess, "must lie in [0, 1)"));
    }
    if !(opts.lapse.is_finite() && (0.0..1.0).contains(&opts.lapse)) {
        return Err(refuse("lapse", opts.lapse, "must lie in [0, 1)"));
    }
    if opts.guess + opts.lapse >= 1.0 {
        return Err(refuse(
            "lapse",
            opts.lapse,
            format!("must be below 1 − guess = {}", 1.0 - opts.guess),
        ));
    }
    if !(opts.target > opts.guess && opts.target < 1.0 - opts.lapse) {
        return Err(refuse(
            "target",
            opts.target,
            format!(
                "must lie strictly between the guess rate {} and 1 − lapse = {}",
                opts.guess,
                1.0 - opts.lapse
            ),
        ));
    }
    Ok(())
}

/// The data a fit uses: levels with trials, checked.
fn check_data(data: &[LevelCount], model: Model) -> Result<Vec<LevelCount>, FitError> {
    for (i, d) in data.iter().enumerate() {
        if !d.level.is_finite() {
            return Err(refuse(
                format!("data[{i}].level"),
                d.level,
                "must be a finite number",
            ));
        }
        if model == Model::Weibull && d.level < 0.0 {
            return Err(refuse(
                format!("data[{i}].level"),
                d.level,
                "must be at least 0 for the Weibull (its F is defined on x ≥ 0)",
            ));
        }
        if d.n_correct > d.n_trials {
            return Err(refuse(
                format!("data[{i}].n_correct"),
                d.n_correct,
                format!("must not exceed `n_trials` ({})", d.n_trials),
            ));
        }
    }
    let used: Vec<LevelCount> = data.iter().copied().filter(|d| d.n_trials > 0).collect();
    let mut levels: Vec<f64> = used.iter().map(|d| d.level).collect();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    let needed = match model {
        // The Weibull's F(0) = 0 whatever α and β: a level 0 says nothing of them.
        Model::Weibull => levels.iter().filter(|&&x| x > 0.0).count(),
        Model::Logistic => levels.len(),
    };
    if needed < 2 {
        return Err(refuse(
            "data",
            format!("{needed} distinct informative level(s) with trials"),
            "must hold at least 2 (two parameters are fitted)",
        ));
    }
    Ok(used)
}

/// The search box and scaling for one data set.
#[derive(Clone, Copy, Debug)]
struct Space {
    model: Model,
    /// Logistic: the levels' centre and span; Weibull: the smallest positive and largest level.
    lo: f64,
    hi: f64,
}

impl Space {
    fn new(model: Model, data: &[LevelCount]) -> Self {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for d in data {
            if model == Model::Weibull && d.level <= 0.0 {
                continue;
            }
            lo = lo.min(d.level);
            hi = hi.max(d.level);
        }
        Self { model, lo, hi }
    }

    fn span(&self) -> f64 {
        self.hi - self.lo
    }

    /// Bounds of (α, β). Wide enough that any fit of data with an interior maximum lies
    /// inside; a fit that ends on them is flagged `degenerate`.
    fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        match self.model {
            Model::Weibull => ([self.lo * 1e-3, self.hi * 1e3], [1e-2, 1e3]),
            Model::Logistic => {
                let span = self.span();
                (
                    [self.lo - 10.0 * span, self.hi + 10.0 * span],
                    [1e-3 / span, 1e4 / span],
                )
            }
        }
    }

    /// Natural (α, β) from search coordinates, clamped into the box: (ln α, ln β) for the
    /// Weibull, ((α − lo) / span, ln(β·span)) for the logistic, so that a unit step means the
    /// same thing whatever the level units.
    fn natural(&self, theta: [f64; 2]) -> [f64; 2] {
        let (a_box, b_box) = self.bounds();
        let (alpha, beta) = match self.model {
            Model::Weibull => (theta[0].exp(), theta[1].exp()),
            Model::Logistic => (
                self.lo + theta[0] * self.span(),
                theta[1].exp() / self.span(),
            ),
        };
        [
            clamp_nan(alpha, a_box[0], a_box[1]),
            clamp_nan(beta, b_box[0], b_box[1]),
        ]
    }

    fn search(&self, natural: [f64; 2]) -> [f64; 2] {
        match self.model {
            Model::Weibull => [natural[0].ln(), natural[1].ln()],
            Model::Logistic => [
                (natural[0] - self.lo) / self.span(),
                (natural[1] * self.span()).ln(),
            ],
        }
    }

    fn at_bound(&self, natural: [f64; 2]) -> bool {
        let (a_box, b_box) = self.bounds();
        let near = |x: f64, lo: f64, hi: f64| {
            let tol = 1e-6 * (hi - lo).abs().max(f64::MIN_POSITIVE);
            x <= lo + tol || x >= hi - tol
        };
        // β's box spans decades: compare it in logarithms.
        let near_log = |x: f64, lo: f64, hi: f64| {
            let (x, lo, hi) = (x.ln(), lo.ln(), hi.ln());
            x <= lo + 1e-6 || x >= hi - 1e-6
        };
        match self.model {
            Model::Weibull => {
                near_log(natural[0], a_box[0], a_box[1]) || near_log(natural[1], b_box[0], b_box[1])
            }
            Model::Logistic => {
                near(natural[0], a_box[0], a_box[1]) || near_log(natural[1], b_box[0], b_box[1])
            }
        }
    }
}

fn clamp_nan(x: f64, lo: f64, hi: f64) -> f64 {
    if x.is_nan() {
        lo
    } else {
        x.clamp(lo, hi)
    }
}

/// ψ kept off 0 and 1 so that a log never sees 0: with λ = 0 a level far above threshold has
/// ψ = 1 to double precision, and one error there would otherwise make the likelihood −∞.
const PSI_FLOOR: f64 = 1e-15;

fn log_likelihood(
    data: &[LevelCount],
    model: Model,
    alpha: f64,
    beta: f64,
    opts: &FitOptions,
) -> f64 {
    let mut ll = 0.0;
    for d in data {
        let psi = model
            .psi(d.level, alpha, beta, opts.guess, opts.lapse)
            .clamp(PSI_FLOOR, 1.0 - PSI_FLOOR);
        let k = f64::from(d.n_correct);
        let n = f64::from(d.n_trials);
        if k > 0.0 {
            ll += k * psi.ln();
        }
        if n - k > 0.0 {
            ll += (n - k) * (1.0 - psi).ln();
        }
    }
    if ll.is_nan() {
        f64::NEG_INFINITY
    } else {
        ll
    }
}

fn deviance(data: &[LevelCount], model: Model, alpha: f64, beta: f64, opts: &FitOptions) -> f64 {
    let mut dev = 0.0;
    for d in data {
        let psi = model
            .psi(d.level, alpha, beta, opts.guess, opts.lapse)
            .clamp(PSI_FLOOR, 1.0 - PSI_FLOOR);
        let k = f64::from(d.n_correct);
        let n = f64::from(d.n_trials);
        // 0 · ln 0 = 0.
        if k > 0.0 {
            dev += k * (k / (n * psi)).ln();
        }
        if n - k > 0.0 {
            dev += (n - k) * ((n - k) / (n * (1.0 - psi))).ln();
        }
    }
    2.0 * dev
}

struct Simplex {
    best: [f64; 2],
    value: f64,
    evaluations: u32,
    converged: bool,
}

/// Nelder & Mead (1965) in two dimensions with the standard coefficients (reflection 1,
/// expansion 2, contraction ½, shrink ½). Stops when the simplex's values agree to 1e-10
/// (absolute: f is a −log-likelihood, so 1e-10 is far below any meaningful difference) and its
/// points to 1e-7 (search coordinates are logarithms or fractions of the levels' span, so
/// that is a relative 1e-7), or after `max_evaluations`.
fn nelder_mead(
    f: &mut dyn FnMut([f64; 2]) -> f64,
    start: [f64; 2],
    step: [f64; 2],
    max_evaluations: u32,
) -> Simplex {
    const F_TOL: f64 = 1e-10;
    const X_TOL: f64 = 1e-7;
    let mut evaluations = 0u32;
    let mut eval = |x: [f64; 2], evaluations: &mut u32| {
        *evaluations += 1;
        let v = f(x);
        if v.is_nan() {
            f64::INFINITY
        } else {
            v
        }
    };
    let mut pts = [
        start,
        [start[0] + step[0], start[1]],
        [start[0], start[1] + step[1]],
    ];
    let mut vals = [0.0; 3];
    for (v, p) in vals.iter_mut().zip(pts.iter()) {
        *v = eval(*p, &mut evaluations);
    }
    let mut converged = false;
    while evaluations < max_evaluations {
        // Order: 0 best, 2 worst.
        let mut idx = [0usize, 1, 2];
        idx.sort_by(|&a, &b| vals[a].total_cmp(&vals[b]));
        pts = [pts[idx[0]], pts[idx[1]], pts[idx[2]]];
        vals = [vals[idx[0]], vals[idx[1]], vals[idx[2]]];
        let spread_f = vals[2] - vals[0];
        let spread_x = (1..3)
            .map(|i| {
                (pts[i][0] - pts[0][0])
                    .abs()
                    .max((pts[i][1] - pts[0][1]).abs())
            })
            .fold(0.0, f64::max);
        if spread_f <= F_TOL && spread_x <= X_TOL {
            converged = true;
            break;
        }
        let c = [0.5 * (pts[0][0] + pts[1][0]), 0.5 * (pts[0][1] + pts[1][1])];
        let along = |t: f64| [c[0] + t * (pts[2][0] - c[0]), c[1] + t * (pts[2][1] - c[1])];
        let xr = along(-1.0);
        let fr = eval(xr, &mut evaluations);
        if fr < vals[0] {
            let xe = along(-2.0);
            let fe = eval(xe, &mut evaluations);
            if fe < fr {
                pts[2] = xe;
                vals[2] = fe;
            } else {
                pts[2] = xr;
                vals[2] = fr;
            }
            continue;
        }
        if fr < vals[1] {
            pts[2] = xr;
            vals[2] = fr;
            continue;
        }
        let (xc, fc, accept) = if fr < vals[2] {
            let xc = along(-0.5);
            let fc = eval(xc, &mut evaluations);
            (xc, fc, fc <= fr)
        } else {
            let xc = along(0.5);
            let fc = eval(xc, &mut evaluations);
            (xc, fc, fc < vals[2])
        };
        if accept {
            pts[2] = xc;
            vals[2] = fc;
            continue;
        }
        for i in 1..3 {
            pts[i] = [
                pts[0][0] + 0.5 * (pts[i][0] - pts[0][0]),
                pts[0][1] + 0.5 * (pts[i][1] - pts[0][1]),
            ];
            vals[i] = eval(pts[i], &mut evaluations);
        }
    }
    let best = (0..3)
        .min_by(|&a, &b| vals[a].total_cmp(&vals[b]))
        .unwrap_or(0);
    Simplex {
        best: pts[best],
        value: vals[best],
        evaluations,
        converged,
    }
}

/// The best (α, β) of a coarse grid: the seed of the simplex, which otherwise can stall on
/// the flat likelihood far from the data (Palamedes seeds its search the same way).
fn grid_start(data: &[LevelCount], space: &Space, opts: &FitOptions) -> [f64; 2] {
    const N: usize = 21;
    let mut best = ([0.0, 0.0], f64::NEG_INFINITY);
    for i in 0..N {
        let u = i as f64 / (N - 1) as f64;
        let alpha = match space.model {
            Model::Weibull => (space.lo.ln() + u * (space.hi.ln() - space.lo.ln())).exp(),
            Model::Logistic => space.lo + u * space.span(),
        };
        for j in 0..N {
            let v = j as f64 / (N - 1) as f64;
            // Weibull shapes 0.3 … 30; logistic slopes 0.3 … 100 per span.
            let beta = match space.model {
                Model::Weibull => (0.3f64.ln() + v * (30.0f64.ln() - 0.3f64.ln())).exp(),
                Model::Logistic => {
                    (0.3f64.ln() + v * (100.0f64.ln() - 0.3f64.ln())).exp() / space.span()
                }
            };
            let ll = log_likelihood(data, space.model, alpha, beta, opts);
            if ll > best.1 {
                best = ([alpha, beta], ll);
            }
        }
    }
    best.0
}

fn fit_from(
    data: &[LevelCount],
    model: Model,
    opts: &FitOptions,
    space: &Space,
    start: [f64; 2],
) -> Fit {
    let mut objective = |theta: [f64; 2]| {
        let [alpha, beta] = space.natural(theta);
        -log_likelihood(data, model, alpha, beta, opts)
    };
    let theta0 = space.search(start);
    let first = nelder_mead(&mut objective, theta0, [0.1, 0.1], 4000);
    // A restart from the best point with a fresh simplex: a collapsed simplex can stop short
    // of the minimum (a standard safeguard for Nelder–Mead).
    let second = nelder_mead(&mut objective, first.best, [0.02, 0.02], 2000);
    let (best, converged) = if second.value <= first.value {
        (second.best, first.converged && second.converged)
    } else {
        (first.best, first.converged)
    };
    let evaluations = first.evaluations + second.evaluations;
    let [alpha, beta] = space.natural(best);
    let log_likelihood = log_likelihood(data, model, alpha, beta, opts);
    let degenerate = space.at_bound([alpha, beta])
        || on_ridge(data, model, alpha, beta, opts, space, log_likelihood);
    let (se_alpha, se_beta) = if degenerate {
        (None, None)
    } else {
        standard_errors(data, model, alpha, beta, opts, space)
    };
    let mut levels: Vec<f64> = data.iter().map(|d| d.level).collect();
    levels.sort_by(f64::total_cmp);
    levels.dedup();
    let fit = Fit {
        model,
        alpha,
        beta,
        guess: opts.guess,
        lapse: opts.lapse,
        log_likelihood,
        deviance: deviance(data, model, alpha, beta, opts),
        deviance_df: levels.len().saturating_sub(2),
        target: opts.target,
        level_at_target: None,
        se_alpha,
        se_beta,
        degenerate,
        converged,
        evaluations,
    };
    Fit {
        level_at_target: fit.level_at(opts.target),
        ..fit
    }
}

/// Whether the likelihood is (to 1e-9) as high a large step towards the edge of the
/// parameter space: a slope twice as steep, or the threshold moved by half itself (Weibull) or
/// by the levels' span (logistic), either way. At a proper maximum each of these costs far
/// more than 1e-9 of log-likelihood even with a handful of trials.
fn on_ridge(
    data: &[LevelCount],
    model: Model,
    alpha: f64,
    beta: f64,
    opts: &FitOptions,
    space: &Space,
    ll: f64,
) -> bool {
    let (a_lo, a_hi) = match model {
        Model::Weibull => (0.5 * alpha, 1.5 * alpha),
        Model::Logistic => (alpha - space.span(), alpha + space.span()),
    };
    [(alpha, 2.0 * beta), (a_lo, beta), (a_hi, beta)]
        .iter()
        .any(|&(a, b)| log_likelihood(data, model, a, b, opts) >= ll - 1e-9)
}

/// Standard errors from the observed information: the inverse of the negative Hessian of
/// the log-likelihood in (α, β), by central differences with steps of 1e-4 of each value.
fn standard_errors(
    data: &[LevelCount],
    model: Model,
    alpha: f64,
    beta: f64,
    opts: &FitOptions,
    space: &Space,
) -> (Option<f64>, Option<f64>) {
    let ll = |a: f64, b: f64| log_likelihood(data, model, a, b, opts);
    let ha = 1e-4
        * alpha
            .abs()
            .max(1e-3 * space.span().abs())
            .max(f64::MIN_POSITIVE);
    let hb = 1e-4 * beta.abs().max(f64::MIN_POSITIVE);
    let f0 = ll(alpha, beta);
    let faa = (ll(alpha + ha, beta) - 2.0 * f0 + ll(alpha - ha, beta)) / (ha * ha);
    let fbb = (ll(alpha, beta + hb) - 2.0 * f0 + ll(alpha, beta - hb)) / (hb * hb);
    let fab = (ll(alpha + ha, beta + hb) - ll(alpha + ha, beta - hb) - ll(alpha - ha, beta + hb)
        + ll(alpha - ha, beta - hb))
        / (4.0 * ha * hb);
    // Information = −Hessian; its inverse is the covariance.
    let (i_aa, i_bb, i_ab) = (-faa, -fbb, -fab);
    let det = i_aa * i_bb - i_ab * i_ab;
    if !(det.is_finite() && det > 0.0 && i_aa > 0.0 && i_bb > 0.0) {
        return (None, None);
    }
    let var_a = i_bb / det;
    let var_b = i_aa / det;
    (
        (var_a > 0.0).then(|| var_a.sqrt()),
        (var_b > 0.0).then(|| var_b.sqrt()),
    )
}

/// The maximum-likelihood fit of `model` to `data`, with γ and λ fixed from `opts`.
pub fn fit(data: &[LevelCount], model: Model, opts: &FitOptions) -> Result<Fit, FitError> {
    check_options(opts)?;
    let used = check_data(data, model)?;
    let space = Space::new(model, &used);
    let start = grid_start(&used, &space, opts);
    Ok(fit_from(&used, model, opts, &space, start))
}

/// How a bootstrap draws its resamples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BootstrapKind {
    /// Counts drawn from the fitted ψ at each level (Wichmann & Hill 2001b).
    Parametric,
    /// Counts drawn from each level's observed proportion (the trials resampled).
    NonParametric,
}

/// A bootstrap's settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootstrapOptions {
    /// Parametric or non-parametric.
    pub kind: BootstrapKind,
    /// Resamples (≥ 2; Wichmann & Hill 2001b advise a few thousand for 95 % intervals).
    pub n_resamples: u32,
    /// Seed of the resamples (ChaCha8): the same seed gives the same interval.
    pub seed: u64,
    /// Coverage of the percentile interval, e.g. 0.95.
    pub confidence: f64,
}

/// A percentile interval.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Interval {
    /// The (1 − confidence)/2 quantile of the resampled estimates.
    pub lower: f64,
    /// The (1 + confidence)/2 quantile.
    pub upper: f64,
}

impl Interval {
    /// Whether `x` lies within [lower, upper].
    pub fn contains(&self, x: f64) -> bool {
        self.lower <= x && x <= self.upper
    }
}

/// Percentile bootstrap intervals around a fit.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BootstrapCi {
    /// The fit to the data themselves.
    pub fit: Fit,
    /// Interval on α.
    pub alpha: Interval,
    /// Interval on β.
    pub beta: Interval,
    /// Interval on the level at the target proportion.
    pub level_at_target: Option<Interval>,
    /// Coverage asked.
    pub confidence: f64,
    /// Resamples drawn.
    pub n_resamples: u32,
    /// Resamples whose fit was [`Fit::degenerate`] (kept in the intervals: dropping them
    /// would bias the interval towards well-behaved data).
    pub n_degenerate: u32,
}

/// A type-7 quantile (linear between order statistics) of sorted values.
fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let h = (sorted.len() - 1) as f64 * q.clamp(0.0, 1.0);
    let lo = h.floor() as usize;
    let hi = h.ceil() as usize;
    let (a, b) = (sorted[lo], sorted[hi.min(sorted.len() - 1)]);
    a + (h - lo as f64) * (b - a)
}

fn interval(mut values: Vec<f64>, confidence: f64) -> Interval {
    values.sort_by(f64::total_cmp);
    Interval {
        lower: quantile(&values, (1.0 - confidence) / 2.0),
        upper: quantile(&values, (1.0 + confidence) / 2.0),
    }
}

/// Fit, then refit `n_resamples` data sets drawn from the fit (parametric) or from the
/// observed proportions (non-parametric) with the same trials per level, and take percentile
/// intervals of α, β and the level at target. Each refit starts from the data's fit (the
/// resamples scatter around it), which keeps a thousand refits cheap.
pub fn bootstrap(
    data: &[LevelCount],
    model: Model,
    opts: &FitOptions,
    boot: &BootstrapOptions,
) -> Result<BootstrapCi, FitError> {
    if boot.n_resamples < 2 {
        return Err(refuse(
            "n_resamples",
            boot.n_resamples,
            "must be at least 2",
        ));
    }
    if !(boot.confidence > 0.0 && boot.confidence < 1.0) {
        return Err(refuse(
            "confidence",
            boot.confidence,
            "must lie strictly between 0 and 1",
        ));
    }
    check_options(opts)?;
    let used = check_data(data, model)?;
    let space = Space::new(model, &used);
    let start = grid_start(&used, &space, opts);
    let original = fit_from(&used, model, opts, &space, start);
    let mut rng = ChaCha8Rng::seed_from_u64(boot.seed);
    let (mut alphas, mut betas, mut levels) = (Vec::new(), Vec::new(), Vec::new());
    let mut n_degenerate = 0u32;
    let mut resample = used.clone();
    for _ in 0..boot.n_resamples {
        for (r, d) in resample.iter_mut().zip(used.iter()) {
            let p = match boot.kind {
                BootstrapKind::Parametric => original.psi(d.level),
                BootstrapKind::NonParametric => f64::from(d.n_correct) / f64::from(d.n_trials),
            };
            r.n_correct = match Binomial::new(u64::from(d.n_trials), p.clamp(0.0, 1.0)) {
                Ok(binomial) => binomial.sample(&mut rng).min(u64::from(d.n_trials)) as u32,
                // Unreachable with p in [0, 1]; keep the observed count rather than panic.
                Err(_) => d.n_correct,
            };
        }
        let refit = fit_from(
            &resample,
            model,
            opts,
            &space,
            [original.alpha, original.beta],
        );
        if refit.degenerate {
            n_degenerate += 1;
        }
        alphas.push(refit.alpha);
        betas.push(refit.beta);
        if let Some(x) = refit.level_at_target {
            levels.push(x);
        }
    }
    let level_at_target =
        (levels.len() == boot.n_resamples as usize).then(|| interval(levels, boot.confidence));
    Ok(BootstrapCi {
        fit: original,
        alpha: interval(alphas, boot.confidence),
        beta: interval(betas, boot.confidence),
        level_at_target,
        confidence: boot.confidence,
        n_resamples: boot.n_resamples,
        n_degenerate,
    })
}
