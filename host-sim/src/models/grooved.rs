//! Static skin model of a finger on a grooved tile (Taylor & Lederman, Appendix 1, eqs. 1–4).
//!
//! Units: lengths mm, forces g (gram-force, as in the paper), k in mm/g, so k·f_g is
//! dimensionless with f_g in g/mm (force per unit length of groove).
//!
//! ```text
//! r   = G/(2 sin θ)                         D = r(1 − cos θ) = G(1 − cos θ)/(2 sin θ)   (1)
//! B   = A_cg = r²(θ − ½ sin 2θ)                                                         (2)
//! d   = B/(L + G),   x = D − d,   p = x/r
//! A_g = ½ r² [asin √(2p − p²) − (1 − p) √(2p − p²)]                                    (3)
//! A   = W A_g/(G + L),   A_c = W B/(G + L)
//! k f_g = 2G²(θ − sin θ) / (G² + LG − ½ L² μ sin θ)                                    (4)
//! ```
//!
//! Force per groove (our reading of the paper's fluid-filled membrane): the pressure inside the
//! finger is P = F/S with S the pad area, and the part of it over one groove is
//! f_g = P·G = F·G/S (per unit length of groove). The pad area follows the paper's measured
//! power law S ∝ F^0.15; its absolute size is not printed, so S(112 g) = 150 mm² is assumed
//! (see [`Pad`]), and W = √S (the width of the equal-area square pad).
//!
//! Eq. 4 is solved for θ ∈ (0, θ_max]: θ_max = π/2 (the arc cannot be wider than a half circle in
//! a rectangular groove) unless the denominator vanishes first, at the pole θ* with
//! sin θ* = 2(G² + LG)/(L² μ). On (0, θ*) k f_g rises from 0 to +∞, so with a pole every target
//! has exactly one root below it; without one, targets above k f_g(π/2) are out of range.
//! Both numerator and denominator are monotone, so k f_g(θ) is strictly increasing on the branch.

use core::f64::consts::FRAC_PI_2;

/// θ − sin θ without cancellation: a series below 0.25 rad (error < 1e-19 relative), direct above.
pub fn theta_minus_sin(t: f64) -> f64 {
    if t.abs() < 0.25 {
        let t2 = t * t;
        // θ³/6 − θ⁵/120 + θ⁷/5040 − θ⁹/362880 + θ¹¹/39916800 − θ¹³/6227020800
        t * t2
            * (1.0 / 6.0
                - t2 * (1.0 / 120.0
                    - t2 * (1.0 / 5040.0
                        - t2 * (1.0 / 362_880.0
                            - t2 * (1.0 / 39_916_800.0 - t2 / 6_227_020_800.0)))))
    } else {
        t - t.sin()
    }
}

/// 1 − cos θ = 2 sin²(θ/2), without cancellation.
pub fn one_minus_cos(t: f64) -> f64 {
    let s = (0.5 * t).sin();
    2.0 * s * s
}

/// Errors of the grooved-tile model. No NaN is ever returned in an `Ok`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GroovedError {
    /// An input is NaN, infinite or out of its physical range.
    InvalidInput(&'static str),
    /// k f_g above the largest value the branch reaches (no pole below π/2).
    TargetOutOfRange {
        /// Requested k f_g.
        target: f64,
        /// k f_g(π/2).
        max: f64,
    },
    /// The denominator G² + LG − ½L²μ sin θ is ≤ 0 at this θ (at or past the pole θ*).
    SingularDenominator {
        /// Where eq. 4 was evaluated.
        theta: f64,
    },
    /// A Newton iterate left (0, π/2].
    LeftDomain {
        /// The iterate.
        theta: f64,
    },
    /// Newton met a zero or non-finite derivative.
    ZeroDerivative {
        /// Where.
        theta: f64,
    },
    /// Iteration limit reached without meeting the tolerance.
    NoConvergence {
        /// Iterations done.
        iterations: u32,
        /// Last iterate.
        theta: f64,
    },
}

impl core::fmt::Display for GroovedError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidInput(s) => write!(f, "invalid input: {s}"),
            Self::TargetOutOfRange { target, max } => {
                write!(f, "no solution: k*f_g = {target:e} exceeds the largest reachable {max:e} (theta = pi/2)")
            }
            Self::SingularDenominator { theta } => {
                write!(f, "no solution at theta = {theta:e}: denominator G^2 + LG - L^2 mu sin(theta)/2 <= 0")
            }
            Self::LeftDomain { theta } => write!(f, "iterate theta = {theta:e} left (0, pi/2]"),
            Self::ZeroDerivative { theta } => write!(f, "zero derivative at theta = {theta:e}"),
            Self::NoConvergence { iterations, theta } => {
                write!(
                    f,
                    "no convergence after {iterations} iterations (theta = {theta:e})"
                )
            }
        }
    }
}

/// Eq. 4 for one tile and friction coefficient.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eq4 {
    /// Groove width G, mm.
    pub g: f64,
    /// Land width L, mm.
    pub l: f64,
    /// Skin–land friction coefficient μ.
    pub mu: f64,
}

impl Eq4 {
    /// Checks G > 0, L ≥ 0, μ ≥ 0, all finite.
    pub fn new(g: f64, l: f64, mu: f64) -> Result<Self, GroovedError> {
        if !(g.is_finite() && g > 0.0) {
            return Err(GroovedError::InvalidInput(
                "groove width must be finite and > 0",
            ));
        }
        if !(l.is_finite() && l >= 0.0) {
            return Err(GroovedError::InvalidInput(
                "land width must be finite and >= 0",
            ));
        }
        if !(mu.is_finite() && mu >= 0.0) {
            return Err(GroovedError::InvalidInput("mu must be finite and >= 0"));
        }
        Ok(Self { g, l, mu })
    }

    /// G² + LG − ½L²μ sin θ.
    pub fn denominator(&self, theta: f64) -> f64 {
        self.g * self.g + self.l * self.g - 0.5 * self.l * self.l * self.mu * theta.sin()
    }

    /// The pole θ* ∈ (0, π/2] where the denominator vanishes, if any.
    pub fn pole(&self) -> Option<f64> {
        let c = 0.5 * self.l * self.l * self.mu;
        if c <= 0.0 {
            return None;
        }
        let s = (self.g * self.g + self.l * self.g) / c;
        if s <= 1.0 {
            Some(s.asin())
        } else {
            None
        }
    }

    /// Upper end of the physical branch: θ* if there is a pole, else π/2.
    pub fn theta_max(&self) -> f64 {
        self.pole().unwrap_or(FRAC_PI_2)
    }

    /// k f_g(θ) of eq. 4.
    pub fn value(&self, theta: f64) -> Result<f64, GroovedError> {
        let den = self.denominator(theta);
        if den <= 0.0 || !den.is_finite() {
            return Err(GroovedError::SingularDenominator { theta });
        }
        Ok(2.0 * self.g * self.g * theta_minus_sin(theta) / den)
    }

    /// k f_g(θ) and d(k f_g)/dθ.
    pub fn value_and_derivative(&self, theta: f64) -> Result<(f64, f64), GroovedError> {
        let den = self.denominator(theta);
        if den <= 0.0 || !den.is_finite() {
            return Err(GroovedError::SingularDenominator { theta });
        }
        let g2 = 2.0 * self.g * self.g;
        let num = g2 * theta_minus_sin(theta);
        let dnum = g2 * one_minus_cos(theta);
        let dden = -0.5 * self.l * self.l * self.mu * theta.cos();
        Ok((num / den, (dnum * den - num * dden) / (den * den)))
    }

    /// Largest k f_g on the branch (+∞ with a pole).
    pub fn max_target(&self) -> f64 {
        if self.pole().is_some() {
            f64::INFINITY
        } else {
            self.value(FRAC_PI_2).unwrap_or(f64::INFINITY)
        }
    }
}

/// Root-finding method for eq. 4.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Solver {
    /// Plain Newton from `theta0`; fails if an iterate leaves the domain or crosses the pole.
    Newton,
    /// Bisection on [0, θ_max].
    Bisection,
    /// Newton kept inside a shrinking bracket, bisection when a step leaves it or stalls.
    Safeguarded,
}

impl Solver {
    /// All three, in the order of the docs.
    pub const ALL: [Solver; 3] = [Solver::Newton, Solver::Bisection, Solver::Safeguarded];

    /// Short name used in the CLI and CSV.
    pub fn name(self) -> &'static str {
        match self {
            Solver::Newton => "newton",
            Solver::Bisection => "bisection",
            Solver::Safeguarded => "safeguarded",
        }
    }

    /// Parses a name of [`Solver::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Converged when |k f_g(θ) − target| ≤ rtol · target.
    pub rtol: f64,
    /// Iteration limit.
    pub max_iter: u32,
    /// Start of plain and safeguarded Newton, rad.
    pub theta0: f64,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            rtol: 1e-13,
            max_iter: 200,
            theta0: core::f64::consts::FRAC_PI_4,
        }
    }
}

/// A root with its cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    /// θ, rad.
    pub theta: f64,
    /// Iterations: evaluations of the model at a new θ (one bracket halving, or one Newton
    /// step with its f and f′; plain Newton counts its starting point too).
    pub iterations: u32,
    /// Evaluations of k f_g (eq. 4).
    pub evaluations: u32,
    /// Evaluations of its derivative.
    pub derivative_evaluations: u32,
    /// |k f_g(θ) − target| / target (0 for target 0).
    pub rel_residual: f64,
}

/// Solves eq. 4 for θ with target k f_g ≥ 0.
pub fn solve_theta(
    eq: &Eq4,
    target: f64,
    solver: Solver,
    opt: &SolveOptions,
) -> Result<Solution, GroovedError> {
    if !(target.is_finite() && target >= 0.0) {
        return Err(GroovedError::InvalidInput("k*f_g must be finite and >= 0"));
    }
    if !(opt.rtol.is_finite() && opt.rtol > 0.0) {
        return Err(GroovedError::InvalidInput("rtol must be > 0"));
    }
    if target == 0.0 {
        return Ok(Solution {
            theta: 0.0,
            iterations: 0,
            evaluations: 0,
            derivative_evaluations: 0,
            rel_residual: 0.0,
        });
    }
    let max = eq.max_target();
    if target > max {
        return Err(GroovedError::TargetOutOfRange { target, max });
    }
    match solver {
        Solver::Newton => newton(eq, target, opt),
        Solver::Bisection => bisection(eq, target, opt),
        Solver::Safeguarded => safeguarded(eq, target, opt),
    }
}

/// Largest relative residual accepted when the bracket has collapsed to machine precision before
/// `rtol` was met. Beyond it the root sits so close to the pole θ* that k f_g cannot be resolved in
/// f64: reported as [`GroovedError::SingularDenominator`] (no numerically resolvable solution).
pub const COLLAPSE_RTOL: f64 = 1e-9;

fn collapse(
    eq: &Eq4,
    theta: f64,
    it: u32,
    ev: u32,
    dev: u32,
    val: f64,
    target: f64,
) -> Result<Solution, GroovedError> {
    let s = done(theta, it, ev, dev, val, target);
    if s.rel_residual <= COLLAPSE_RTOL {
        Ok(s)
    } else if eq.pole().is_some() {
        Err(GroovedError::SingularDenominator { theta })
    } else {
        Err(GroovedError::NoConvergence {
            iterations: it,
            theta,
        })
    }
}

fn done(theta: f64, it: u32, ev: u32, dev: u32, val: f64, target: f64) -> Solution {
    Solution {
        theta,
        iterations: it,
        evaluations: ev,
        derivative_evaluations: dev,
        rel_residual: ((val - target) / target).abs(),
    }
}

fn newton(eq: &Eq4, target: f64, opt: &SolveOptions) -> Result<Solution, GroovedError> {
    let mut x = opt.theta0;
    let (mut ev, mut dev) = (0, 0);
    if !(x > 0.0 && x <= FRAC_PI_2) {
        return Err(GroovedError::LeftDomain { theta: x });
    }
    for it in 1..=opt.max_iter {
        let (f, df) = eq.value_and_derivative(x)?;
        ev += 1;
        dev += 1;
        if (f - target).abs() <= opt.rtol * target {
            return Ok(done(x, it, ev, dev, f, target));
        }
        if it == opt.max_iter {
            break;
        }
        if !(df.is_finite() && df > 0.0) {
            return Err(GroovedError::ZeroDerivative { theta: x });
        }
        let xn = x - (f - target) / df;
        if !(xn > 0.0 && xn <= FRAC_PI_2) {
            return Err(GroovedError::LeftDomain { theta: xn });
        }
        if xn == x {
            // Stalled at machine precision: the best representable root.
            return collapse(eq, x, it, ev, dev, f, target);
        }
        x = xn;
    }
    Err(GroovedError::NoConvergence {
        iterations: opt.max_iter,
        theta: x,
    })
}

/// The bracket [lo, hi] with k f_g(lo) < target < k f_g(hi) (+∞ at a pole).
fn bracket(eq: &Eq4) -> (f64, f64) {
    (0.0, eq.theta_max())
}

fn collapsed(lo: f64, hi: f64) -> bool {
    hi - lo <= 4.0 * f64::EPSILON * hi
}

fn bisection(eq: &Eq4, target: f64, opt: &SolveOptions) -> Result<Solution, GroovedError> {
    let (mut lo, mut hi) = bracket(eq);
    let mut ev = 0;
    for it in 1..=opt.max_iter {
        let mid = 0.5 * (lo + hi);
        let f = eq.value(mid)?;
        ev += 1;
        if (f - target).abs() <= opt.rtol * target {
            return Ok(done(mid, it, ev, 0, f, target));
        }
        if f < target {
            lo = mid;
        } else {
            hi = mid;
        }
        if collapsed(lo, hi) {
            return collapse(eq, mid, it, ev, 0, f, target);
        }
    }
    Err(GroovedError::NoConvergence {
        iterations: opt.max_iter,
        theta: 0.5 * (lo + hi),
    })
}

fn safeguarded(eq: &Eq4, target: f64, opt: &SolveOptions) -> Result<Solution, GroovedError> {
    let (mut lo, mut hi) = bracket(eq);
    let mut x = if opt.theta0 > lo && opt.theta0 < hi {
        opt.theta0
    } else {
        0.5 * (lo + hi)
    };
    let (mut ev, mut dev) = (0, 0);
    let mut dx_prev = hi - lo;
    for it in 1..=opt.max_iter {
        let (f, df) = eq.value_and_derivative(x)?;
        ev += 1;
        dev += 1;
        if (f - target).abs() <= opt.rtol * target {
            return Ok(done(x, it, ev, dev, f, target));
        }
        if f < target {
            lo = x;
        } else {
            hi = x;
        }
        if collapsed(lo, hi) {
            return collapse(eq, x, it, ev, dev, f, target);
        }
        let newton = if df.is_finite() && df > 0.0 {
            x - (f - target) / df
        } else {
            f64::NAN
        };
        // rtsafe rule: keep the Newton step only inside the open bracket and only while it is at
        // most half the previous step (otherwise it is converging no faster than bisection).
        let xn = if newton > lo && newton < hi && (newton - x).abs() <= 0.5 * dx_prev {
            newton
        } else {
            0.5 * (lo + hi)
        };
        dx_prev = (xn - x).abs();
        if xn == x {
            return collapse(eq, x, it, ev, dev, f, target);
        }
        x = xn;
    }
    Err(GroovedError::NoConvergence {
        iterations: opt.max_iter,
        theta: x,
    })
}

/// Finger pad: area S(F) = area_ref · (F/force_ref)^exponent (Taylor & Lederman: exponent ≈ 0.15).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pad {
    /// Pad area at `force_ref_g`, mm² (assumed: 150 mm² at 4 oz; the paper does not print it).
    pub area_ref_mm2: f64,
    /// Reference force, g.
    pub force_ref_g: f64,
    /// Power-law exponent.
    pub exponent: f64,
}

impl Default for Pad {
    fn default() -> Self {
        Self {
            area_ref_mm2: 150.0,
            force_ref_g: 112.0,
            exponent: 0.15,
        }
    }
}

impl Pad {
    /// S(F), mm².
    pub fn area_mm2(&self, force_g: f64) -> f64 {
        self.area_ref_mm2 * (force_g / self.force_ref_g).powf(self.exponent)
    }

    /// Equivalent width W = √S, mm.
    pub fn width_mm(&self, force_g: f64) -> f64 {
        self.area_mm2(force_g).sqrt()
    }
}

/// Inputs of one grooved-tile evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroovedInput {
    /// G, mm.
    pub groove_mm: f64,
    /// L, mm.
    pub land_mm: f64,
    /// F, g.
    pub force_g: f64,
    /// k, mm/g.
    pub k_mm_per_g: f64,
    /// μ.
    pub mu: f64,
    /// Pad model.
    pub pad: Pad,
}

impl GroovedInput {
    /// The paper's most studied values: k = 0.08 mm/g, μ = 0.5, default pad.
    pub fn paper(groove_mm: f64, land_mm: f64, force_g: f64) -> Self {
        Self {
            groove_mm,
            land_mm,
            force_g,
            k_mm_per_g: 0.08,
            mu: 0.5,
            pad: Pad::default(),
        }
    }
}

/// Deformation of the skin over a grooved tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grooved {
    /// Force per groove f_g, g/mm.
    pub f_g_g_per_mm: f64,
    /// k f_g (dimensionless).
    pub kfg: f64,
    /// θ, rad.
    pub theta_rad: f64,
    /// r, mm (+∞ at θ = 0).
    pub r_mm: f64,
    /// D, mm (eq. 1).
    pub d_mm: f64,
    /// A_cg = B, mm² (eq. 2).
    pub a_cg_mm2: f64,
    /// Mean skin depth d, mm.
    pub mean_depth_mm: f64,
    /// x = D − d, mm.
    pub x_mm: f64,
    /// A_g, mm² (eq. 3 as printed).
    pub a_g_mm2: f64,
    /// Pad width W, mm.
    pub pad_width_mm: f64,
    /// A_c = W B/(G + L), mm² (A_cg summed over the grooves under the pad).
    pub a_c_mm2: f64,
    /// A = W A_g/(G + L).
    pub a_mm2: f64,
    /// The solve.
    pub solution: Solution,
}

/// Geometry of Appendix 1 at a given θ (eqs. 1–3).
pub fn geometry(g: f64, l: f64, theta: f64) -> (f64, f64, f64, f64, f64, f64) {
    if theta == 0.0 {
        return (f64::INFINITY, 0.0, 0.0, 0.0, 0.0, 0.0);
    }
    let r = g / (2.0 * theta.sin());
    // D = r(1 − cos θ) = (G/2) tan(θ/2)
    let d = 0.5 * g * (0.5 * theta).tan();
    // B = r²(θ − ½ sin 2θ) = r² · ½ (2θ − sin 2θ)
    let b = r * r * 0.5 * theta_minus_sin(2.0 * theta);
    let mean = b / (l + g);
    let x = d - mean;
    let p = x / r;
    // Eq. 3 with φ = asin √(2p − p²) = acos(1 − p) = 2 asin √(p/2):
    // asin s − (1 − p)s = φ − sin φ cos φ = ½ (2φ − sin 2φ).
    let phi = 2.0 * (0.5 * p).sqrt().asin();
    let a_g = 0.5 * r * r * 0.5 * theta_minus_sin(2.0 * phi);
    (r, d, b, mean, x, a_g)
}

/// Solves eq. 4 and evaluates eqs. 1–3 and the pad sums.
pub fn grooved(
    inp: &GroovedInput,
    solver: Solver,
    opt: &SolveOptions,
) -> Result<Grooved, GroovedError> {
    let eq = Eq4::new(inp.groove_mm, inp.land_mm, inp.mu)?;
    if !(inp.force_g.is_finite() && inp.force_g >= 0.0) {
        return Err(GroovedError::InvalidInput("force must be finite and >= 0"));
    }
    if !(inp.k_mm_per_g.is_finite() && inp.k_mm_per_g > 0.0) {
        return Err(GroovedError::InvalidInput("k must be finite and > 0"));
    }
    let pad = inp.pad;
    if !(pad.area_ref_mm2 > 0.0
        && pad.force_ref_g > 0.0
        && pad.exponent.is_finite()
        && pad.area_ref_mm2.is_finite())
    {
        return Err(GroovedError::InvalidInput(
            "pad area, reference force must be > 0",
        ));
    }
    let (f_g, w) = if inp.force_g == 0.0 {
        (0.0, 0.0)
    } else {
        (
            inp.force_g * inp.groove_mm / pad.area_mm2(inp.force_g),
            pad.width_mm(inp.force_g),
        )
    };
    let kfg = inp.k_mm_per_g * f_g;
    let solution = solve_theta(&eq, kfg, solver, opt)?;
    let (r, d, b, mean, x, a_g) = geometry(inp.groove_mm, inp.land_mm, solution.theta);
    let per = w / (inp.groove_mm + inp.land_mm);
    Ok(Grooved {
        f_g_g_per_mm: f_g,
        kfg,
        theta_rad: solution.theta,
        r_mm: r,
        d_mm: d,
        a_cg_mm2: b,
        mean_depth_mm: mean,
        x_mm: x,
        a_g_mm2: a_g,
        pad_width_mm: w,
        a_c_mm2: per * b,
        a_mm2: per * a_g,
        solution,
    })
}
