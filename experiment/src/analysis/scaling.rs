//! Scale values from paired choices, as alternatives to Scheffé's method: Thurstone case V
//! (Mosteller's least squares) and Bradley–Terry maximum likelihood (Hunter's MM algorithm),
//! and the correlations used to compare scales (Pearson, Spearman). No I/O; results as data.
//!
//! The input is a list of [`Choice`]s (which of a pair was chosen, ties as ½), which graded
//! paired comparisons reduce to by [`choices_from_scores`] (the grade's sign). Both scales are
//! reported zero-mean, in the order items first appear in the input.

// Matrix code: i and j index several matrices at once; iterators would hide the algebra.
#![allow(clippy::needless_range_loop)]

use std::collections::HashMap;
use std::fmt;

use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};

/// One paired choice.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Choice {
    /// The item presented first.
    pub first: String,
    /// The item presented second.
    pub second: String,
    /// 1 if the first was chosen, 0 if the second, 0.5 for a tie.
    pub first_chosen: f64,
}

/// Choices from graded comparisons `(first, second, score)`: score > 0 → first chosen,
/// < 0 → second, 0 → a tie (½). A score that is NaN says nothing and is dropped.
pub fn choices_from_scores(rows: &[(String, String, f64)]) -> Vec<Choice> {
    rows.iter()
        .filter(|(_, _, score)| !score.is_nan())
        .map(|(first, second, score)| Choice {
            first: first.clone(),
            second: second.clone(),
            first_chosen: if *score > 0.0 {
                1.0
            } else if *score < 0.0 {
                0.0
            } else {
                0.5
            },
        })
        .collect()
}

/// A refusal of scaling input: one sentence naming the field, the value and the rule.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum ScalingError {
    /// A field breaks its rule.
    Field {
        /// The field, e.g. `choices[4].first_chosen`.
        field: String,
        /// Its value, as written.
        value: String,
        /// The rule, completing "but it …".
        rule: String,
    },
}

impl fmt::Display for ScalingError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ScalingError::Field { field, value, rule } => {
                write!(
                    f,
                    "paired-comparison scaling: `{field}` is {value}, but it {rule}."
                )
            }
        }
    }
}

impl std::error::Error for ScalingError {}

fn refuse(
    field: impl Into<String>,
    value: impl fmt::Display,
    rule: impl Into<String>,
) -> ScalingError {
    ScalingError::Field {
        field: field.into(),
        value: value.to_string(),
        rule: rule.into(),
    }
}

/// Choices tallied per ordered pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PairTable {
    /// The items, in order of first appearance.
    pub items: Vec<String>,
    /// `wins[i][j]`: times i was chosen over j (a tie counts ½ to each).
    pub wins: Vec<Vec<f64>>,
}

impl PairTable {
    /// Tally choices. Refuses a `first_chosen` outside [0, 1] (or NaN), an item compared with
    /// itself, and an empty list.
    pub fn from_choices(choices: &[Choice]) -> Result<Self, ScalingError> {
        if choices.is_empty() {
            return Err(refuse("choices", "empty", "must hold at least one choice"));
        }
        let mut index: HashMap<&str, usize> = HashMap::new();
        let mut items: Vec<String> = Vec::new();
        for c in choices {
            for name in [&c.first, &c.second] {
                if !index.contains_key(name.as_str()) {
                    index.insert(name.as_str(), items.len());
                    items.push(name.clone());
                }
            }
        }
        let k = items.len();
        let mut wins = vec![vec![0.0; k]; k];
        for (n, c) in choices.iter().enumerate() {
            if !(c.first_chosen.is_finite() && (0.0..=1.0).contains(&c.first_chosen)) {
                return Err(refuse(
                    format!("choices[{n}].first_chosen"),
                    c.first_chosen,
                    "must lie in [0, 1] (1 first chosen, 0 second, 0.5 a tie)",
                ));
            }
            if c.first == c.second {
                return Err(refuse(
                    format!("choices[{n}].second"),
                    format!("{:?}", c.second),
                    "must differ from `first` (an item is not compared with itself)",
                ));
            }
            let (i, j) = (index[c.first.as_str()], index[c.second.as_str()]);
            wins[i][j] += c.first_chosen;
            wins[j][i] += 1.0 - c.first_chosen;
        }
        Ok(Self { items, wins })
    }

    /// Comparisons of the pair (i, j), either order.
    pub fn n(&self, i: usize, j: usize) -> f64 {
        self.wins[i][j] + self.wins[j][i]
    }
}

/// Proportions chosen per pair, with their counts: Thurstone's input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProportionMatrix {
    /// The items.
    pub items: Vec<String>,
    /// `p[i][j]`: the proportion of the (i, j) comparisons in which i was chosen; `None` for
    /// a pair never compared (and the diagonal).
    pub p: Vec<Vec<Option<f64>>>,
    /// `n[i][j]`: comparisons of the pair (for the clipping rule).
    pub n: Vec<Vec<f64>>,
}

impl ProportionMatrix {
    /// From tallied choices.
    pub fn from_table(table: &PairTable) -> Self {
        let k = table.items.len();
        let mut p = vec![vec![None; k]; k];
        let mut n = vec![vec![0.0; k]; k];
        for i in 0..k {
            for j in 0..k {
                let nij = table.n(i, j);
                if i != j && nij > 0.0 {
                    p[i][j] = Some(table.wins[i][j] / nij);
                    n[i][j] = nij;
                }
            }
        }
        Self {
            items: table.items.clone(),
            p,
            n,
        }
    }
}

/// Thurstone case V scale values.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ThurstoneScale {
    /// The items.
    pub items: Vec<String>,
    /// Zero-mean scale values, in units of the SD of a discriminal difference (σ√2 for
    /// per-item dispersion σ).
    pub scale: Vec<f64>,
    /// Pairs whose proportion was 0 or 1 and was clipped (see [`thurstone_case_v`]).
    pub clipped_pairs: u32,
}

/// Thurstone's law of comparative judgment, case V (Thurstone 1927), by Mosteller's (1951)
/// least squares: with zᵢⱼ = Φ⁻¹(pᵢⱼ), the scale s minimises Σ over compared pairs of
/// (zᵢⱼ − (sᵢ − sⱼ))², subject to Σ s = 0. For a complete design this is Mosteller's closed
/// form sᵢ = (1/k) Σⱼ zᵢⱼ (the R psych package's `thurstone`, up to its shift to a minimum of
/// 0); an incomplete design is solved from the normal equations.
///
/// Clipping rule: Φ⁻¹ of 0 or 1 is infinite, so a proportion below 1/(2n) or above
/// 1 − 1/(2n), n the pair's comparisons, is moved to that bound: half a choice is taken back
/// from a unanimous pair, the usual continuity correction. (A pair judged once is then ½ and
/// says nothing; unanimity from few comparisons is weak evidence.) If the matrix's `n` is 0 for
/// a pair that has a proportion, the bound is 0.01 / 0.99.
///
/// `p[i][j]` and `p[j][i]` are both used: z is averaged as (zᵢⱼ − zⱼᵢ)/2 when both are given,
/// so a matrix whose halves do not sum to 1 (rounded published tables) is read symmetrically.
pub fn thurstone_case_v(m: &ProportionMatrix) -> Result<ThurstoneScale, ScalingError> {
    let k = m.items.len();
    if k < 2 {
        return Err(refuse("items", k, "must number at least 2"));
    }
    if m.p.len() != k || m.p.iter().any(|row| row.len() != k) {
        return Err(refuse(
            "p",
            format!("{} rows", m.p.len()),
            format!("must be {k} × {k}"),
        ));
    }
    if m.n.len() != k || m.n.iter().any(|row| row.len() != k) {
        return Err(refuse(
            "n",
            format!("{} rows", m.n.len()),
            format!("must be {k} × {k}"),
        ));
    }
    let standard = Normal::standard();
    // z of one cell, and whether its proportion was clipped.
    let z_of = |i: usize, j: usize| -> Result<(Option<f64>, bool), ScalingError> {
        let Some(p) = m.p[i][j] else {
            return Ok((None, false));
        };
        if !(p.is_finite() && (0.0..=1.0).contains(&p)) {
            return Err(refuse(format!("p[{i}][{j}]"), p, "must lie in [0, 1]"));
        }
        let n = m.n[i][j];
        // At most ½: a count below 1 (a hand-made matrix) would otherwise invert the bounds.
        let bound = if n.is_finite() && n > 0.0 {
            (0.5 / n).min(0.5)
        } else {
            0.01
        };
        let clipped = p.clamp(bound, 1.0 - bound);
        Ok((Some(standard.inverse_cdf(clipped)), clipped != p))
    };
    // Antisymmetric z over compared pairs.
    let mut clipped_pairs = 0u32;
    let mut z = vec![vec![None; k]; k];
    for i in 0..k {
        for j in (i + 1)..k {
            let (zij, clipped_ij) = z_of(i, j)?;
            let (zji, clipped_ji) = z_of(j, i)?;
            let v = match (zij, zji) {
                (Some(a), Some(b)) => Some(0.5 * (a - b)),
                (Some(a), None) => Some(a),
                (None, Some(b)) => Some(-b),
                (None, None) => None,
            };
            if let Some(v) = v {
                z[i][j] = Some(v);
                z[j][i] = Some(-v);
            }
            if clipped_ij || clipped_ji {
                clipped_pairs += 1;
            }
        }
    }
    // Normal equations: L s = b, L the compared-pair graph's Laplacian, bᵢ = Σⱼ zᵢⱼ.
    let mut laplacian = vec![vec![0.0; k]; k];
    let mut b = vec![0.0; k];
    for i in 0..k {
        for j in 0..k {
            if let Some(v) = z[i][j] {
                laplacian[i][i] += 1.0;
                laplacian[i][j] -= 1.0;
                b[i] += v;
            }
        }
    }
    if !connected(&laplacian) {
        return Err(refuse(
            "p",
            "a design whose compared pairs leave items in separate groups",
            "must link every item to every other through compared pairs (else the groups' scales are not comparable)",
        ));
    }
    let scale = solve_zero_sum(&laplacian, &b).ok_or_else(|| {
        refuse(
            "p",
            "a singular system",
            "must give a solvable least-squares system",
        )
    })?;
    Ok(ThurstoneScale {
        items: m.items.clone(),
        scale,
        clipped_pairs,
    })
}

/// Thurstone case V straight from choices.
pub fn thurstone_from_choices(choices: &[Choice]) -> Result<ThurstoneScale, ScalingError> {
    let table = PairTable::from_choices(choices)?;
    thurstone_case_v(&ProportionMatrix::from_table(&table))
}

/// Whether the undirected graph of a Laplacian's off-diagonal entries is connected.
fn connected(laplacian: &[Vec<f64>]) -> bool {
    let k = laplacian.len();
    if k == 0 {
        return false;
    }
    let mut seen = vec![false; k];
    let mut stack = vec![0usize];
    seen[0] = true;
    while let Some(i) = stack.pop() {
        for j in 0..k {
            if i != j && laplacian[i][j] != 0.0 && !seen[j] {
                seen[j] = true;
                stack.push(j);
            }
        }
    }
    seen.into_iter().all(|s| s)
}

/// Solve L s = b with Σ s = 0 for a connected Laplacian-like L (null space 1): (L + 11ᵀ) s =
/// b, whose solution is zero-sum when Σ b = 0. Gaussian elimination with partial pivoting.
fn solve_zero_sum(laplacian: &[Vec<f64>], b: &[f64]) -> Option<Vec<f64>> {
    let k = b.len();
    let mut a: Vec<Vec<f64>> = laplacian
        .iter()
        .map(|row| row.iter().map(|x| x + 1.0).collect())
        .collect();
    let mut s = solve(&mut a, b.to_vec())?;
    // Σ b = 0 up to rounding; remove what rounding left.
    let mean = s.iter().sum::<f64>() / k as f64;
    for x in &mut s {
        *x -= mean;
    }
    Some(s)
}

/// Gaussian elimination with partial pivoting; `None` if singular.
fn solve(a: &mut [Vec<f64>], mut b: Vec<f64>) -> Option<Vec<f64>> {
    let k = b.len();
    for col in 0..k {
        let pivot = (col..k).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs().is_nan() || a[pivot][col].abs() <= 1e-300 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in (col + 1)..k {
            let factor = a[row][col] / a[col][col];
            if factor != 0.0 {
                for c in col..k {
                    a[row][c] -= factor * a[col][c];
                }
                b[row] -= factor * b[col];
            }
        }
    }
    let mut x = vec![0.0; k];
    for row in (0..k).rev() {
        let sum: f64 = ((row + 1)..k).map(|c| a[row][c] * x[c]).sum();
        x[row] = (b[row] - sum) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The inverse of a symmetric positive-definite-on-a-subspace matrix via Gauss–Jordan;
/// `None` if singular.
fn invert(m: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let k = m.len();
    let mut columns = Vec::with_capacity(k);
    for c in 0..k {
        let mut e = vec![0.0; k];
        e[c] = 1.0;
        let mut a = m.to_vec();
        columns.push(solve(&mut a, e)?);
    }
    // columns[c] is the c-th column of the inverse.
    Some(
        (0..k)
            .map(|r| (0..k).map(|c| columns[c][r]).collect())
            .collect(),
    )
}

/// Bradley–Terry estimates.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BradleyTerry {
    /// The items.
    pub items: Vec<String>,
    /// Zero-mean log-worths λ: P(i chosen over j) = 1 / (1 + exp(−(λᵢ − λⱼ))).
    pub log_worth: Vec<f64>,
    /// Standard errors of the zero-mean log-worths, from the Fisher information (its
    /// Moore–Penrose inverse: the information of a Bradley–Terry model has the null space 1).
    pub se: Vec<f64>,
    /// Their covariance matrix (so that the SE of a difference λᵢ − λⱼ is
    /// √(Cᵢᵢ + Cⱼⱼ − 2Cᵢⱼ): e.g. against a reference item, as R's BradleyTerry2 reports).
    pub covariance: Vec<Vec<f64>>,
    /// Σ wᵢⱼ ln pᵢⱼ over ordered pairs at the estimate.
    pub log_likelihood: f64,
    /// 2 Σ wᵢⱼ ln(wᵢⱼ / (nᵢⱼ pᵢⱼ)): the residual deviance against the saturated model.
    pub deviance: f64,
    /// MM iterations spent.
    pub iterations: u32,
    /// Whether the iteration met its tolerance (max |Δλ| < 1e-12).
    pub converged: bool,
}

/// Bradley–Terry maximum likelihood (Bradley & Terry 1952) by the MM algorithm of Hunter
/// (2004, Ann. Statist. 32, 384–406, eq. 3): γᵢ ← Wᵢ / Σⱼ nᵢⱼ / (γᵢ + γⱼ), Wᵢ the wins of i
/// (ties ½ to each), renormalised each step. It increases the likelihood at every step and
/// converges to the maximum whenever one exists.
///
/// The maximum exists (finite) iff for every split of the items into two groups some item of
/// each group was chosen over some item of the other at least once (Ford 1957; Hunter's
/// assumption 1): the "was chosen over" graph is strongly connected. Otherwise the data say
/// some item is infinitely better and this refuses.
pub fn bradley_terry(choices: &[Choice]) -> Result<BradleyTerry, ScalingError> {
    let table = PairTable::from_choices(choices)?;
    bradley_terry_from_table(&table)
}

/// Bradley–Terry from a tally (see [`bradley_terry`]).
pub fn bradley_terry_from_table(table: &PairTable) -> Result<BradleyTerry, ScalingError> {
    let k = table.items.len();
    if k < 2 {
        return Err(refuse("items", k, "must number at least 2"));
    }
    if table.wins.len() != k || table.wins.iter().any(|row| row.len() != k) {
        return Err(refuse(
            "wins",
            format!("{} rows", table.wins.len()),
            format!("must be {k} × {k}"),
        ));
    }
    for i in 0..k {
        for j in 0..k {
            let w = table.wins[i][j];
            if !(w.is_finite() && w >= 0.0) {
                return Err(refuse(
                    format!("wins[{i}][{j}]"),
                    w,
                    "must be a finite count of at least 0",
                ));
            }
        }
    }
    if !strongly_connected(&table.wins) {
        return Err(refuse(
            "choices",
            "a set in which some group of items was never chosen over the rest",
            "must let every group of items win at least once against the others (Hunter 2004, assumption 1), else the maximum-likelihood worths are infinite",
        ));
    }
    let w_total: Vec<f64> = (0..k).map(|i| table.wins[i].iter().sum()).collect();
    let mut gamma = vec![1.0; k];
    let mut iterations = 0u32;
    let mut converged = false;
    const MAX_ITERATIONS: u32 = 100_000;
    while iterations < MAX_ITERATIONS {
        iterations += 1;
        let mut next = vec![0.0; k];
        for i in 0..k {
            let denominator: f64 = (0..k)
                .filter(|&j| j != i)
                .map(|j| table.n(i, j) / (gamma[i] + gamma[j]))
                .sum();
            next[i] = if denominator > 0.0 {
                w_total[i] / denominator
            } else {
                gamma[i]
            };
        }
        // Renormalise to a geometric mean of 1 (the likelihood does not see a common factor).
        let mean_log = next.iter().map(|g| g.ln()).sum::<f64>() / k as f64;
        let mut change = 0.0f64;
        for i in 0..k {
            let g = (next[i].ln() - mean_log).exp();
            change = change.max((g.ln() - gamma[i].ln()).abs());
            gamma[i] = g;
        }
        if !change.is_finite() {
            break;
        }
        if change < 1e-12 {
            converged = true;
            break;
        }
    }
    let log_worth: Vec<f64> = gamma.iter().map(|g| g.ln()).collect();
    let p = |i: usize, j: usize| 1.0 / (1.0 + (log_worth[j] - log_worth[i]).exp());
    let mut log_likelihood = 0.0;
    let mut deviance = 0.0;
    let mut information = vec![vec![0.0; k]; k];
    for i in 0..k {
        for j in 0..k {
            if i == j {
                continue;
            }
            let (w, n, pij) = (table.wins[i][j], table.n(i, j), p(i, j));
            if w > 0.0 {
                log_likelihood += w * pij.ln();
                deviance += 2.0 * w * (w / (n * pij)).ln();
            }
            // Fisher information of λ: each ordered (i, j) fills row i only, so every entry
            // is written once.
            let v = n * pij * (1.0 - pij);
            information[i][j] -= v;
            information[i][i] += v;
        }
    }
    // Moore–Penrose inverse of a connected Laplacian L: (L + 11ᵀ/k)⁻¹ − 11ᵀ/k (11ᵀ/k is the
    // projection on L's null space 1). NaN if the inversion fails (it cannot for a strongly
    // connected design, refused above otherwise).
    let shifted: Vec<Vec<f64>> = information
        .iter()
        .map(|row| row.iter().map(|x| x + 1.0 / k as f64).collect())
        .collect();
    let covariance: Vec<Vec<f64>> = match invert(&shifted) {
        Some(inv) => inv
            .into_iter()
            .map(|row| row.into_iter().map(|x| x - 1.0 / k as f64).collect())
            .collect(),
        None => vec![vec![f64::NAN; k]; k],
    };
    let se = (0..k).map(|i| covariance[i][i].max(0.0).sqrt()).collect();
    Ok(BradleyTerry {
        items: table.items.clone(),
        log_worth,
        se,
        covariance,
        log_likelihood,
        deviance,
        iterations,
        converged,
    })
}

/// Whether the directed graph i → j (i chosen over j at least once) is strongly connected.
fn strongly_connected(wins: &[Vec<f64>]) -> bool {
    let k = wins.len();
    let reach = |forward: bool| {
        let mut seen = vec![false; k];
        let mut stack = vec![0usize];
        seen[0] = true;
        while let Some(i) = stack.pop() {
            for j in 0..k {
                let edge = if forward { wins[i][j] } else { wins[j][i] };
                if i != j && edge > 0.0 && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            }
        }
        seen.into_iter().all(|s| s)
    };
    k > 0 && reach(true) && reach(false)
}

/// Pearson's correlation; `None` if the lengths differ, fewer than 2 pairs, a value is not
/// finite, or either side is constant.
pub fn pearson(a: &[f64], b: &[f64]) -> Option<f64> {
    if a.len() != b.len() || a.len() < 2 || a.iter().chain(b).any(|x| !x.is_finite()) {
        return None;
    }
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (dx, dy) = (x - ma, y - mb);
        sab += dx * dy;
        saa += dx * dx;
        sbb += dy * dy;
    }
    if saa <= 0.0 || sbb <= 0.0 {
        return None;
    }
    let r = sab / (saa * sbb).sqrt();
    r.is_finite().then_some(r.clamp(-1.0, 1.0))
}

/// Ranks 1..n, ties given their mean rank.
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..v.len()).collect();
    order.sort_by(|&i, &j| v[i].total_cmp(&v[j]));
    let mut r = vec![0.0; v.len()];
    let mut start = 0;
    while start < order.len() {
        let mut end = start + 1;
        while end < order.len() && v[order[end]] == v[order[start]] {
            end += 1;
        }
        let mean_rank = (start + 1 + end) as f64 / 2.0;
        for &i in &order[start..end] {
            r[i] = mean_rank;
        }
        start = end;
    }
    r
}

/// Spearman's rank correlation (Pearson's on ranks, ties given their mean rank); `None` as
/// [`pearson`].
pub fn spearman(a: &[f64], b: &[f64]) -> Option<f64> {
    if a.len() != b.len() || a.len() < 2 || a.iter().chain(b).any(|x| !x.is_finite()) {
        return None;
    }
    pearson(&ranks(a), &ranks(b))
}
