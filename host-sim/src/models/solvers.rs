//! The θ solvers of [`super::grooved`] compared over the paper's tiles ([`super::tile`]):
//! iterations, evaluations and accuracy per solver and tolerance — the data of
//! `model theta-solvers` and of the solvers chart and table of docs/models.md.

use super::grooved::{solve_theta, Eq4, Pad, SolveOptions, Solver};
use super::tile::{paper_tiles, PAPER_FORCES_G};

/// The options of θ_ref (with [`Solver::Bisection`]): to machine precision.
fn reference_options() -> SolveOptions {
    SolveOptions {
        rtol: 1e-300,
        max_iter: 5000,
        ..SolveOptions::default()
    }
}

/// The case set of the solver comparison: paper tiles × forces × k ∈ {0.008, 0.08, 0.8} ×
/// μ ∈ {0, 0.5, 2}, keeping the cases that have a resolvable root (bisection to machine precision
/// succeeds; this drops the k = 0.8 cases past the half circle). Returns (Eq4, k f_g) pairs.
pub fn solver_cases() -> Vec<(Eq4, f64)> {
    let refopt = reference_options();
    let mut v = Vec::new();
    for t in paper_tiles() {
        for f in PAPER_FORCES_G {
            for k in [0.008, 0.08, 0.8] {
                for mu in [0.0, 0.5, 2.0] {
                    let eq = Eq4 {
                        g: t.groove_mm,
                        l: t.land_mm,
                        mu,
                    };
                    let pad = Pad::default();
                    let kfg = k * f * t.groove_mm / pad.area_mm2(f);
                    if solve_theta(&eq, kfg, Solver::Bisection, &refopt).is_ok() {
                        v.push((eq, kfg));
                    }
                }
            }
        }
    }
    v
}

/// One row of the solver comparison.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolverStats {
    /// Solver.
    pub solver: Solver,
    /// Requested relative residual.
    pub rtol: f64,
    /// Cases solved / total.
    pub solved: usize,
    /// Cases.
    pub cases: usize,
    /// Mean iterations over solved cases.
    pub mean_iterations: f64,
    /// Max iterations.
    pub max_iterations: u32,
    /// Mean evaluations of eq. 4 plus its derivative.
    pub mean_evaluations: f64,
    /// Max |θ − θ_ref|/θ_ref over solved cases.
    pub max_rel_theta_error: f64,
}

/// Runs the comparison over [`solver_cases`] at one tolerance; θ_ref is bisection to machine
/// precision.
pub fn solver_stats(solver: Solver, rtol: f64) -> SolverStats {
    let cases = solver_cases();
    let refopt = reference_options();
    let opt = SolveOptions {
        rtol,
        ..SolveOptions::default()
    };
    let (mut solved, mut it_sum, mut it_max, mut ev_sum, mut err_max) = (0, 0u64, 0, 0u64, 0.0f64);
    for (eq, t) in &cases {
        let reference = solve_theta(eq, *t, Solver::Bisection, &refopt)
            .expect("bisection")
            .theta;
        if let Ok(s) = solve_theta(eq, *t, solver, &opt) {
            solved += 1;
            it_sum += s.iterations as u64;
            it_max = it_max.max(s.iterations);
            ev_sum += (s.evaluations + s.derivative_evaluations) as u64;
            err_max = err_max.max(((s.theta - reference) / reference).abs());
        }
    }
    let n = solved.max(1) as f64;
    SolverStats {
        solver,
        rtol,
        solved,
        cases: cases.len(),
        mean_iterations: it_sum as f64 / n,
        max_iterations: it_max,
        mean_evaluations: ev_sum as f64 / n,
        max_rel_theta_error: err_max,
    }
}

/// Exponents n of the swept tolerances rtol = 10⁻ⁿ in [`solver_sweep`].
pub const SWEEP_RTOL_EXPONENTS: core::ops::RangeInclusive<i32> = 1..=15;

/// [`solver_stats`] for every solver (in [`Solver::ALL`] order) at every rtol = 10⁻ⁿ,
/// n ∈ [`SWEEP_RTOL_EXPONENTS`] (loosest first).
pub fn solver_sweep() -> Vec<SolverStats> {
    let mut v = Vec::new();
    for solver in Solver::ALL {
        for e in SWEEP_RTOL_EXPONENTS {
            v.push(solver_stats(solver, 10f64.powi(-e)));
        }
    }
    v
}
