//! The distributions the analysis needs and statrs lacks: Tukey's studentized range (CDF and
//! quantile, for the yardsticks of paired comparisons), and the F upper tail (the ANOVA p-values).
//!
//! The studentized range is computed from its definition, not from tables and not from any other
//! library's code:
//!
//! - the range W of k independent standard normals has the CDF
//!   P(W ≤ w) = k ∫ φ(z) [Φ(z) − Φ(z − w)]^{k−1} dz (z is the largest of the k);
//! - the studentized range Q = W / s, with ν s² ~ χ²_ν independent of W, has the CDF
//!   P(Q ≤ q) = ∫ f_s(s) P(W ≤ q s) ds, f_s the density of s = sqrt(χ²_ν / ν).
//!
//! Both integrals are done by Gauss–Legendre quadrature on consecutive intervals, the scheme
//! Copenhaver & Holland describe ("Computation of the distribution of the maximum studentized
//! range statistic with application to multiple significance testing of simple effects",
//! J. Statist. Comput. Simul. 30 (1988) 1–15). Ours integrates the outer integral in y = ln s,
//! where the density is smooth for every ν ≥ 1 (no s^{ν−1} corner at s = 0) and its normalising
//! constant has a closed form, and marches outwards from the mode until the integrand is below
//! 1e-17. The nodes and weights are computed here by Newton's method on the Legendre polynomial.
//! `docs/experiment-analysis.md` gives the formulas and the table the tests hold it to.

use std::sync::OnceLock;

use statrs::function::beta::checked_beta_reg;
use statrs::function::erf::erfc;
use statrs::function::gamma::ln_gamma;

/// Points of the Gauss–Legendre rule on each interval: 16 points integrate the smooth, bell-shaped
/// integrands here to ~1e-15 relative on intervals of a few standard deviations.
const GL_POINTS: usize = 16;

/// The inner integral runs over z ∈ [−Z_EDGE, Z_EDGE] in unit intervals: k φ(z) < 1e-15 outside
/// for every k below ~1e9, and the power of Φ(z) − Φ(z − w) only makes the left end smaller.
const Z_EDGE: f64 = 8.5;

/// An integrand below this (the density is normalised to 1) no longer changes a probability we
/// quote to 1e-12.
const NEGLIGIBLE: f64 = 1e-17;

/// Gauss–Legendre nodes and weights on [−1, 1].
struct Rule {
    nodes: [f64; GL_POINTS],
    weights: [f64; GL_POINTS],
}

/// The rule, computed once: Newton's method on P_n from the usual first guess
/// cos(π (i − 1/4) / (n + 1/2)), P_n by the three-term recurrence, weight 2 / ((1 − x²) P_n'(x)²).
fn rule() -> &'static Rule {
    static RULE: OnceLock<Rule> = OnceLock::new();
    RULE.get_or_init(|| {
        let n = GL_POINTS;
        let mut nodes = [0.0; GL_POINTS];
        let mut weights = [0.0; GL_POINTS];
        for i in 0..n {
            let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (n as f64 + 0.5)).cos();
            let mut derivative = 1.0;
            for _ in 0..100 {
                // P_0 = 1, P_1 = x, (m + 1) P_{m+1} = (2m + 1) x P_m − m P_{m−1}.
                let (mut p_prev, mut p) = (1.0, x);
                for m in 1..n {
                    let m = m as f64;
                    let p_next = ((2.0 * m + 1.0) * x * p - m * p_prev) / (m + 1.0);
                    p_prev = p;
                    p = p_next;
                }
                derivative = n as f64 * (x * p - p_prev) / (x * x - 1.0);
                let step = p / derivative;
                x -= step;
                if step.abs() < 1e-16 {
                    break;
                }
            }
            nodes[i] = x;
            weights[i] = 2.0 / ((1.0 - x * x) * derivative * derivative);
        }
        Rule { nodes, weights }
    })
}

/// The inner integral's nodes with what does not depend on w: weight × φ(z), Φ(z) and 1 − Φ(z).
struct InnerNodes {
    z: Vec<f64>,
    weight_pdf: Vec<f64>,
    cdf: Vec<f64>,
    sf: Vec<f64>,
}

fn inner_nodes() -> &'static InnerNodes {
    static NODES: OnceLock<InnerNodes> = OnceLock::new();
    NODES.get_or_init(|| {
        let rule = rule();
        let intervals = (2.0 * Z_EDGE).round() as usize;
        let mut nodes = InnerNodes {
            z: Vec::with_capacity(intervals * GL_POINTS),
            weight_pdf: Vec::with_capacity(intervals * GL_POINTS),
            cdf: Vec::with_capacity(intervals * GL_POINTS),
            sf: Vec::with_capacity(intervals * GL_POINTS),
        };
        for interval in 0..intervals {
            // Unit intervals [−Z_EDGE + i, −Z_EDGE + i + 1]: half-width 1/2.
            let centre = -Z_EDGE + interval as f64 + 0.5;
            for (x, w) in rule.nodes.iter().zip(rule.weights.iter()) {
                let z = centre + 0.5 * x;
                nodes.z.push(z);
                nodes.weight_pdf.push(0.5 * w * normal_pdf(z));
                nodes.cdf.push(normal_cdf(z));
                nodes.sf.push(normal_sf(z));
            }
        }
        nodes
    })
}

fn normal_pdf(z: f64) -> f64 {
    (-0.5 * z * z).exp() / (2.0 * std::f64::consts::PI).sqrt()
}

/// Φ(z) through erfc, accurate in the left tail.
fn normal_cdf(z: f64) -> f64 {
    0.5 * erfc(-z / std::f64::consts::SQRT_2)
}

/// 1 − Φ(z) through erfc, accurate in the right tail.
fn normal_sf(z: f64) -> f64 {
    0.5 * erfc(z / std::f64::consts::SQRT_2)
}

/// x^(k − 1) for the count of the other k − 1 normals.
fn pow_others(x: f64, k: u32) -> f64 {
    match i32::try_from(k - 1) {
        Ok(n) => x.powi(n),
        Err(_) => x.powf(f64::from(k - 1)),
    }
}

/// P(W ≤ w) for the range W of k standard normals (k ≥ 2, w finite ≥ 0).
fn range_cdf(w: f64, k: u32) -> f64 {
    if w <= 0.0 {
        return 0.0;
    }
    let nodes = inner_nodes();
    let mut sum = 0.0;
    for i in 0..nodes.z.len() {
        let z = nodes.z[i];
        // Φ(z) − Φ(z − w), from the tail where both are small so that no digits cancel.
        let inside = if z > 0.0 {
            normal_sf(z - w) - nodes.sf[i]
        } else {
            nodes.cdf[i] - normal_cdf(z - w)
        };
        if inside > 0.0 {
            sum += nodes.weight_pdf[i] * pow_others(inside, k);
        }
    }
    (f64::from(k) * sum).clamp(0.0, 1.0)
}

/// ln of the normalising constant of the density of y = ln s, less its value −x at the mode:
/// C = ln Γ(x) − x ln x + x − ln 2 with x = ν / 2. For x ≥ 10 by Stirling's series (error
/// < 1e-12), which avoids the cancellation of terms of size x ln x that the direct form suffers
/// at large ν.
fn log_norm_constant(x: f64) -> f64 {
    if x < 10.0 {
        ln_gamma(x) - x * x.ln() + x - std::f64::consts::LN_2
    } else {
        let inv = 1.0 / x;
        let inv2 = inv * inv;
        let series =
            inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0 - inv2 / 1680.0)));
        -0.5 * x.ln() + 0.5 * (2.0 * std::f64::consts::PI).ln() - std::f64::consts::LN_2 + series
    }
}

/// Tukey's studentized range: P(Q ≤ q) for the range of k independent standard normals divided by
/// an independent s with ν s² ~ χ²_ν, ν = `df` (f64::INFINITY: the range itself).
///
/// NaN where it is undefined: k < 2, df < 1 or NaN, q NaN. 0 for q ≤ 0, 1 for q = ∞. Accurate to
/// about 1e-12 absolute (the quadrature), enough for quantiles to 8 significant digits.
pub fn ptukey(q: f64, k: u32, df: f64) -> f64 {
    if k < 2 || q.is_nan() || df.is_nan() || df < 1.0 {
        return f64::NAN;
    }
    if q <= 0.0 {
        return 0.0;
    }
    if q == f64::INFINITY {
        return 1.0;
    }
    if df == f64::INFINITY {
        return range_cdf(q, k);
    }
    let x = 0.5 * df;
    let log_c = log_norm_constant(x);
    // Density of y = ln s, normalised: exp(2x y − x (e^{2y} − 1) − C); mode at y = 0, standard
    // deviation ≈ 1 / (2 sqrt x). Intervals of ≈ 3 standard deviations (at most 1).
    let density = |y: f64| (2.0 * x * y - x * (2.0 * y).exp_m1() - log_c).exp();
    let step = (1.5 / x.sqrt()).min(1.0);
    let rule = rule();
    let interval = |lo: f64| -> f64 {
        let half = 0.5 * step;
        let centre = lo + half;
        let mut sum = 0.0;
        for (node, weight) in rule.nodes.iter().zip(rule.weights.iter()) {
            let y = centre + half * node;
            sum += weight * density(y) * range_cdf(q * y.exp(), k);
        }
        half * sum
    };
    // The density falls on either side of y = 0. To the right the integrand is at most the density;
    // to the left both factors rise towards 0, so their product at an interval's upper end bounds
    // everything further left. 4000 intervals cover ν = 1 (step 1) far past the 1e-17 point.
    let mut total = 0.0;
    for i in 0..4000 {
        let lo = i as f64 * step;
        if density(lo) < NEGLIGIBLE {
            break;
        }
        total += interval(lo);
    }
    for i in 1..4000 {
        let hi = -((i - 1) as f64) * step;
        if density(hi) * range_cdf(q * hi.exp(), k) < NEGLIGIBLE {
            break;
        }
        total += interval(hi - step);
    }
    total.clamp(0.0, 1.0)
}

/// The quantile of Tukey's studentized range: the q with `ptukey(q, k, df) = p`.
///
/// Found by Brent's method (R. P. Brent, *Algorithms for Minimization without Derivatives*, 1973,
/// ch. 4) on a bracket grown by doubling from [0, 1], to a relative tolerance of 1e-10 in q.
/// NaN where `ptukey` is undefined or p is NaN; 0 for p ≤ 0, ∞ for p ≥ 1.
pub fn qtukey(p: f64, k: u32, df: f64) -> f64 {
    if k < 2 || p.is_nan() || df.is_nan() || df < 1.0 {
        return f64::NAN;
    }
    if p <= 0.0 {
        return 0.0;
    }
    if p >= 1.0 {
        return f64::INFINITY;
    }
    let f = |q: f64| ptukey(q, k, df) - p;
    let (mut lo, mut f_lo) = (0.0, -p);
    let mut hi = 1.0;
    let mut f_hi = f(hi);
    // The quantile grows without bound as p → 1 and ν → 1 (q(0.999; 100, 1) ≈ 4e3): 60 doublings
    // reach 1e18, beyond any p short of 1 − 1e-12.
    let mut doublings = 0;
    while f_hi < 0.0 {
        if doublings == 60 {
            return f64::INFINITY;
        }
        lo = hi;
        f_lo = f_hi;
        hi *= 2.0;
        f_hi = f(hi);
        doublings += 1;
    }
    brent(f, lo, hi, f_lo, f_hi, 1e-10)
}

/// Brent's root finder on [a, b] with f(a) f(b) ≤ 0: inverse quadratic interpolation or the secant
/// step where they stay inside the bracket and shrink it fast enough, bisection otherwise.
fn brent(f: impl Fn(f64) -> f64, a: f64, b: f64, fa: f64, fb: f64, rel_tol: f64) -> f64 {
    let (mut a, mut b, mut fa, mut fb) = (a, b, fa, fb);
    if fa == 0.0 {
        return a;
    }
    if fb == 0.0 {
        return b;
    }
    // c is the previous b (or the bracket's other end), b the best estimate so far.
    let (mut c, mut fc) = (a, fa);
    let mut d = b - a;
    let mut e = d;
    for _ in 0..200 {
        if fb.signum() == fc.signum() {
            c = a;
            fc = fa;
            d = b - a;
            e = d;
        }
        if fc.abs() < fb.abs() {
            a = b;
            b = c;
            c = a;
            fa = fb;
            fb = fc;
            fc = fa;
        }
        let tol = 2.0 * f64::EPSILON * b.abs() + 0.5 * rel_tol * b.abs().max(f64::MIN_POSITIVE);
        let m = 0.5 * (c - b);
        if m.abs() <= tol || fb == 0.0 {
            return b;
        }
        if e.abs() >= tol && fa.abs() > fb.abs() {
            let s = fb / fa;
            let (mut p, mut q) = if a == c {
                (2.0 * m * s, 1.0 - s)
            } else {
                let q = fa / fc;
                let r = fb / fc;
                (
                    s * (2.0 * m * q * (q - r) - (b - a) * (r - 1.0)),
                    (q - 1.0) * (r - 1.0) * (s - 1.0),
                )
            };
            if p > 0.0 {
                q = -q;
            } else {
                p = -p;
            }
            if 2.0 * p < (3.0 * m * q - (tol * q).abs()).min((e * q).abs()) {
                e = d;
                d = p / q;
            } else {
                d = m;
                e = m;
            }
        } else {
            d = m;
            e = m;
        }
        a = b;
        fa = fb;
        b += if d.abs() > tol { d } else { tol.copysign(m) };
        fb = f(b);
    }
    b
}

/// The p-value of an F statistic: P(F > f) for F with `df1` and `df2` degrees of freedom, via
/// statrs' regularised incomplete beta, I_{d2/(d1 f + d2)}(d2/2, d1/2), its argument computed
/// directly so that small p-values keep their digits.
///
/// NaN for NaN f or degrees of freedom that are not positive and finite; 1 for f ≤ 0, 0 for f = ∞.
pub fn f_upper(f: f64, df1: f64, df2: f64) -> f64 {
    let valid_df = |d: f64| d.is_finite() && d > 0.0;
    if f.is_nan() || !valid_df(df1) || !valid_df(df2) {
        return f64::NAN;
    }
    if f <= 0.0 {
        return 1.0;
    }
    if f == f64::INFINITY {
        return 0.0;
    }
    let x = df2 / (df1 * f + df2);
    checked_beta_reg(0.5 * df2, 0.5 * df1, x).unwrap_or(f64::NAN)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauss_legendre_rule_integrates_polynomials_to_degree_31() {
        let rule = rule();
        let weights: f64 = rule.weights.iter().sum();
        assert!((weights - 2.0).abs() < 1e-14);
        // ∫ x^30 over [−1, 1] = 2 / 31.
        let x30: f64 = rule
            .nodes
            .iter()
            .zip(rule.weights.iter())
            .map(|(x, w)| w * x.powi(30))
            .sum();
        assert!((x30 - 2.0 / 31.0).abs() < 1e-14, "{x30}");
    }

    #[test]
    fn range_of_two_is_a_folded_normal_difference() {
        // W = |Z1 − Z2| with Z1 − Z2 ~ N(0, 2): P(W ≤ w) = 2 Φ(w / √2) − 1. To 1e-11: statrs'
        // erfc carries a few 1e-13 of its own.
        for w in [0.1, 0.5, 1.0, 2.0, 3.0, 5.0] {
            let exact = 2.0 * normal_cdf(w / std::f64::consts::SQRT_2) - 1.0;
            let ours = ptukey(w, 2, f64::INFINITY);
            assert!((ours - exact).abs() < 1e-11, "w {w}: {ours} vs {exact}");
        }
    }

    #[test]
    fn two_means_are_a_t_test() {
        // For k = 2, Q / √2 is |t_ν|: P(Q ≤ q) = 1 − 2 P(t_ν > q/√2). For ν = 2 the t CDF has
        // the closed form 1/2 + t / (2 sqrt(2 + t²)).
        for q in [0.5, 1.0, 3.0, 6.08, 14.04] {
            let t = q / std::f64::consts::SQRT_2;
            let exact = t / (2.0 + t * t).sqrt();
            assert!((ptukey(q, 2, 2.0) - exact).abs() < 1e-11, "q {q}");
        }
    }

    #[test]
    fn edges_are_refused_or_limits() {
        assert!(ptukey(1.0, 1, 10.0).is_nan());
        assert!(ptukey(1.0, 3, 0.5).is_nan());
        assert!(ptukey(f64::NAN, 3, 10.0).is_nan());
        assert_eq!(ptukey(-1.0, 3, 10.0), 0.0);
        assert_eq!(ptukey(f64::INFINITY, 3, 10.0), 1.0);
        assert_eq!(qtukey(0.0, 3, 10.0), 0.0);
        assert_eq!(qtukey(1.0, 3, 10.0), f64::INFINITY);
        assert!(qtukey(0.95, 3, f64::NAN).is_nan());
        assert!(f_upper(1.0, 0.0, 3.0).is_nan());
        assert_eq!(f_upper(0.0, 2.0, 3.0), 1.0);
        assert_eq!(f_upper(f64::INFINITY, 2.0, 3.0), 0.0);
    }

    #[test]
    fn qtukey_inverts_ptukey() {
        for (k, df) in [(2, 1.0), (4, 5.0), (10, 30.0), (4, f64::INFINITY)] {
            let q = qtukey(0.95, k, df);
            assert!((ptukey(q, k, df) - 0.95).abs() < 1e-9, "k {k} df {df}");
        }
    }

    #[test]
    fn f_upper_matches_closed_forms() {
        // F(2, d2): P(F > f) = (1 + 2 f / d2)^(−d2/2).
        for (f, d2) in [(0.5, 4.0), (3.0, 10.0), (19.0, 2.0)] {
            let exact = (1.0_f64 + 2.0 * f / d2).powf(-d2 / 2.0);
            assert!((f_upper(f, 2.0, d2) - exact).abs() < 1e-13, "f {f}");
        }
    }
}
