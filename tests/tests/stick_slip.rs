//! The core's f32 stick-slip frequency against host-sim's f64 model of [N] eq. 10–12 (SAW
//! display paper, `shared/seeds/001_…`; docs/models.md §1):
//!
//! ```text
//! f_ss⁻¹ = (2/ω0)(π − atan R + R),  R = Δμ P/(m ω0 U),  ω0 = √(k/m)
//! ```
//!
//! `saw_core::texture::Material::stick_slip_hz` (the load-time constants and the per-sample
//! formula the controller runs) is compared with `host_sim::models::stick_slip::stick_slip` over a
//! grid of U, Δμ, P, m, k spanning the ranges the scene file accepts
//! (core/src/scene_file/regions.rs: Δμ 0 ..= 100, P 1 mN ..= 100 N, m 1 mg ..= 10 kg,
//! k 1 mN/m ..= 10 MN/m) and every speed the controller can pass (0, then 1 µm/s — the
//! resolution of `velocity_um_s` — up to i32::MAX µm/s),
//! plus the edges docs/models.md names: U → 0 (R → ∞), Δμ = 0 (R = 0), large U (R → 0).
//! The f64 model gets exactly the f32 inputs (widened), so the comparison measures the core's
//! arithmetic and atan only.
//!
//! # Error bound
//!
//! The core evaluates f = ω0 U / (2((π − atan R) U + A)) with A = Δμ P/(m ω0) (R = A/U) and
//! micromath's atan on an argument in [0, 1] (atan(A/U) = π/2 − atan(U/A) when U < A). Write
//! D = (π − atan R) U + A. An absolute atan error ε enters the denominator as D − εU, so
//!
//! ```text
//! f_core / f − 1 = εU / (D − εU),   |·| ≤ |ε| / (D/U − |ε|) = |ε| / (π − atan R + R − |ε|)
//!                                          ≤ |ε| / (π − |ε|)
//! ```
//!
//! since π − atan R + R is π at R = 0 and increasing (its derivative is R²/(1 + R²) ≥ 0).
//! micromath documents |ε| ≤ 0.1620° = 2.827·10⁻³ rad (docs/models.md measures 2.83·10⁻³);
//! `micromath_atan_error_is_as_assumed` checks it on [0, 1] here. That gives 9.01·10⁻⁴ (the
//! "0.09 %" of docs/models.md). On top: f32 rounding. The path has about a dozen correctly
//! rounded operations (k/m, √, Δμ·P, m·ω0, the quotient A, the atan argument, π − atan, ·U, + A,
//! ω0·U, the final quotient), each ≤ 2⁻²⁴ relative, and the atan argument's rounding moves atan
//! by at most its own 2⁻²⁴; 32·2⁻²⁴ = 1.9·10⁻⁶ covers them with margin. Total:
//! `REL_BOUND` = 2.83·10⁻³/(π − 2.83·10⁻³) + 1.9·10⁻⁶ = 9.03·10⁻⁴.
//!
//! The bound assumes normal f32 intermediates. The grid keeps U ≥ 10⁻³⁰ m/s (24 decades below
//! the slowest speed the controller can pass), where ω0 U, (π − atan R) U and f are normal for
//! every grid point; below that, `vanishing_speeds_stay_finite` holds Δμ = 0 to the bound down to
//! the smallest normal U and records what the core loses at subnormal U (f32 range, not the
//! formula: the controller never passes such speeds).
//!
//! One point is not compared by value: U = 0 with Δμ = 0, where R = 0/0. The f64 model returns
//! ω0/2π (the Δμ = 0 value for every U > 0), the core returns 0 (it returns 0 for every U ≤ 0:
//! no motion, no bursts). `zero_speed` asserts both as they are.

use core::f64::consts::PI;

use host_sim::models::atan::AtanImpl;
use host_sim::models::stick_slip::{stick_slip, StickSlipParams};
use saw_core::texture::Material;

/// micromath's worst atan error, rad (0.1620° is 2.827·10⁻³).
const ATAN_ABS_ERR: f64 = 2.83e-3;
/// f32 rounding of the core's path: 32 · 2⁻²⁴.
const F32_ROUNDING: f64 = 32.0 * (f32::EPSILON as f64 / 2.0);
/// Relative error bound of the core's f_ss against the f64 model (module docs).
const REL_BOUND: f64 = ATAN_ABS_ERR / (PI - ATAN_ABS_ERR) + F32_ROUNDING;

/// The slowest non-zero speed the controller passes: 1 µm/s (`velocity_um_s` is in µm/s).
const U_MIN_CONTROLLER: f32 = 1e-6;
/// The fastest: i32::MAX µm/s.
const U_MAX_CONTROLLER: f32 = i32::MAX as f32 * 1e-6;

/// One grid point, in the core's f32.
#[derive(Clone, Copy, Debug)]
struct Point {
    u: f32,
    delta_mu: f32,
    p: f32,
    m: f32,
    k: f32,
}

impl Point {
    fn material(&self) -> Material {
        Material {
            delta_mu: self.delta_mu,
            normal_force_n: self.p,
            mass_kg: self.m,
            stiffness_n_per_m: self.k,
            ..Material::fig5(0.0)
        }
    }

    /// The core's f_ss, Hz.
    fn core(&self) -> f32 {
        let m = self.material();
        assert!(
            m.validate().is_ok(),
            "grid point rejected by the core: {self:?}"
        );
        m.stick_slip_hz(self.u)
    }

    /// The f64 model's f_ss and R for exactly the same (f32) inputs.
    fn reference(&self) -> (f64, f64) {
        let r = stick_slip(&StickSlipParams {
            delta_mu: self.delta_mu as f64,
            normal_force_n: self.p as f64,
            mass_kg: self.m as f64,
            stiffness_n_per_m: self.k as f64,
            speed_m_s: self.u as f64,
        })
        .expect("grid point rejected by the f64 model");
        (r.f_ss_hz, r.r)
    }
}

/// `n` log-spaced values from `lo` to `hi` inclusive, as f32.
fn log_space(lo: f64, hi: f64, n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| (lo * (hi / lo).powf(i as f64 / (n - 1) as f64)) as f32)
        .collect()
}

/// Worst case and coverage of a sweep.
#[derive(Default)]
struct Sweep {
    points: usize,
    worst_rel: f64,
    worst: Option<(Point, f32, f64, f64)>,
    failures: Vec<String>,
    failed: usize,
    r_min_pos: f64,
    r_max: f64,
    r_zero: usize,
    r_above_1e6: usize,
}

impl Sweep {
    fn new() -> Self {
        Self {
            r_min_pos: f64::INFINITY,
            ..Self::default()
        }
    }

    fn check(&mut self, pt: Point) {
        let f = pt.core();
        let (want, r) = pt.reference();
        self.points += 1;
        if r == 0.0 {
            self.r_zero += 1;
        } else {
            self.r_min_pos = self.r_min_pos.min(r);
            self.r_max = self.r_max.max(r);
        }
        if r > 1e6 {
            self.r_above_1e6 += 1;
        }
        let rel = if !f.is_finite() {
            f64::INFINITY
        } else if want == 0.0 {
            if f == 0.0 {
                0.0
            } else {
                f64::INFINITY
            }
        } else {
            (f as f64 - want).abs() / want
        };
        let ok = f.is_finite() && f >= 0.0 && rel <= REL_BOUND;
        if !ok {
            self.failed += 1;
            if self.failures.len() < 20 {
                self.failures.push(format!(
                    "{pt:?}: core {f:e} Hz, f64 {want:e} Hz, R {r:e}, rel {rel:e}"
                ));
            }
        }
        if rel > self.worst_rel {
            self.worst_rel = rel;
            self.worst = Some((pt, f, want, r));
        }
    }

    fn assert_within_bound(&self, what: &str) {
        assert!(
            self.failed == 0,
            "{what}: core f32 f_ss off the f64 model by more than {REL_BOUND:e} at {} of {} \
             points (worst rel {:e} at {:?}); first {}:\n{}",
            self.failed,
            self.points,
            self.worst_rel,
            self.worst,
            self.failures.len(),
            self.failures.join("\n")
        );
        println!(
            "{what}: {} points, worst rel {:.3e} (bound {REL_BOUND:.3e}) at {:?}, R in {:e} ..= {:e} \
             ({} with R = 0, {} with R > 1e6)",
            self.points,
            self.worst_rel,
            self.worst,
            self.r_min_pos,
            self.r_max,
            self.r_zero,
            self.r_above_1e6
        );
    }
}

#[test]
fn bound_is_what_the_docs_say() {
    // docs/models.md: micromath's worst f_ss error is 0.09 %.
    assert!((9.0e-4..9.1e-4).contains(&REL_BOUND), "{REL_BOUND:e}");
}

#[test]
fn micromath_atan_error_is_as_assumed() {
    // The core reduces the argument to [0, 1]; π/2 − atan(x) carries atan's absolute error.
    // host-sim's `AtanImpl::Micromath` is the same `micromath::F32Ext::atan` (one crate in the lock).
    let n = 1 << 20;
    let mut worst = (0.0f64, 0.0f32);
    for i in 0..=n {
        let x = i as f32 / n as f32;
        let e = (AtanImpl::Micromath.eval(x) as f64 - (x as f64).atan()).abs();
        if e > worst.0 {
            worst = (e, x);
        }
    }
    assert!(
        worst.0 <= ATAN_ABS_ERR,
        "micromath atan error {:e} at {}",
        worst.0,
        worst.1
    );
    // And the assumption is not loose: the worst case is within 1 % of it.
    assert!(worst.0 > 0.99 * ATAN_ABS_ERR, "{worst:?}");
}

/// The full grid: every combination of U, Δμ, P, m, k below.
#[test]
fn core_matches_f64_model_over_the_parameter_grid() {
    // U: the U → 0 edge far below the controller's 1 µm/s, then 6 per decade from 1 µm/s to
    // i32::MAX µm/s, with the default gate speed (15 mm/s), fig. 5's 4 cm/s and the slider's
    // 2 m/s limit.
    let mut us: Vec<f32> = vec![1e-30, 1e-24, 1e-18, 1e-12, 1e-9];
    us.extend(log_space(
        U_MIN_CONTROLLER as f64,
        U_MAX_CONTROLLER as f64,
        6 * 9 + 1,
    ));
    us.extend([0.015, 0.04, 2.0]);
    // Δμ: 0 (R = 0), 10⁻⁶ … 10⁻³, 1-2-5 from 0.01 to 50, 0.3 (scenes/material.toml) and 100
    // (the scene file's limit).
    let mut dms: Vec<f32> = vec![0.0, 1e-6, 1e-4, 1e-3];
    for e in -2..=1 {
        for s in [1.0, 2.0, 5.0] {
            dms.push((s * 10f64.powi(e)) as f32);
        }
    }
    dms.extend([0.3, 100.0]);
    // P, m, k: each decade of the scene file's range, ends included.
    let ps = log_space(1e-3, 100.0, 6);
    let ms = log_space(1e-6, 10.0, 8);
    let ks = log_space(1e-3, 1e7, 11);

    let mut sweep = Sweep::new();
    for &u in &us {
        for &delta_mu in &dms {
            for &p in &ps {
                for &m in &ms {
                    for &k in &ks {
                        sweep.check(Point {
                            u,
                            delta_mu,
                            p,
                            m,
                            k,
                        });
                    }
                }
            }
        }
    }
    sweep.assert_within_bound("grid");
    // The edges are in the grid: R = 0 (Δμ = 0), R far beyond the atan study's 1000 (U → 0 with
    // a large Δμ P / √(k m)), and R ≪ 1 (large U, small Δμ).
    assert!(sweep.r_zero > 0);
    assert!(sweep.r_max > 1e30, "R max {:e}", sweep.r_max);
    assert!(sweep.r_min_pos < 1e-12, "R min {:e}", sweep.r_min_pos);
    assert!(sweep.r_above_1e6 > 1000);
}

/// Fig. 5's finger over R = 10⁻³ … 10⁶ densely: the atan error's worst case (around R ~ 0.1–10)
/// lies between grid points of the full grid.
#[test]
fn core_matches_f64_model_densely_in_r() {
    let mut sweep = Sweep::new();
    for delta_mu in [0.3f32, 1.0, 100.0] {
        let fig5 = Material::fig5(delta_mu);
        let a = delta_mu as f64 * 1.0 / (1e-3 * (500.0f64 / 1e-3).sqrt());
        for r in log_space(1e-3, 1e6, 20_001) {
            sweep.check(Point {
                u: (a / r as f64) as f32,
                delta_mu,
                p: fig5.normal_force_n,
                m: fig5.mass_kg,
                k: fig5.stiffness_n_per_m,
            });
        }
    }
    sweep.assert_within_bound("dense R");
    // The bound is tight: micromath's worst case shows up at ≥ 95 % of it.
    assert!(
        sweep.worst_rel > 0.95 * (REL_BOUND - F32_ROUNDING),
        "{}",
        sweep.worst_rel
    );
}

/// R → ∞: the core follows kU/(2ΔμP) as the model does (docs/models.md: the model's gap < 2/R).
#[test]
fn large_r_follows_the_asymptote() {
    for (delta_mu, u) in [
        (1.0f32, 1e-6f32),
        (100.0, 1e-6),
        (100.0, 1e-12),
        (100.0, 1e-30),
    ] {
        let m = Material::fig5(delta_mu);
        let (k, mass, p) = (
            m.stiffness_n_per_m as f64,
            m.mass_kg as f64,
            m.normal_force_n as f64,
        );
        let f = m.stick_slip_hz(u) as f64;
        let asym = k * u as f64 / (2.0 * delta_mu as f64 * p);
        let r = delta_mu as f64 * p / (mass * (k / mass).sqrt() * u as f64);
        assert!(r > 1e4, "R {r:e}");
        let rel = (f - asym).abs() / asym;
        assert!(
            rel < 2.0 / r + REL_BOUND,
            "Δμ {delta_mu}, U {u}: {f:e} vs {asym:e}"
        );
    }
}

#[test]
fn zero_speed() {
    // U = 0, Δμ > 0: both 0 (R = ∞: the finger sticks).
    for delta_mu in [1e-6f32, 0.3, 100.0] {
        let pt = Point {
            u: 0.0,
            delta_mu,
            p: 1.0,
            m: 1e-3,
            k: 500.0,
        };
        assert_eq!(pt.core(), 0.0);
        assert_eq!(pt.reference().0, 0.0);
    }
    // U = 0, Δμ = 0 (R = 0/0): the two disagree by convention, not by accuracy — the model takes
    // the Δμ = 0 limit ω0/2π, the core stops (0 for every U ≤ 0). Asserted as they are; any U > 0
    // agrees (grid).
    let pt = Point {
        u: 0.0,
        delta_mu: 0.0,
        p: 1.0,
        m: 1e-3,
        k: 500.0,
    };
    assert_eq!(pt.core(), 0.0);
    let omega0 = (pt.k as f64 / pt.m as f64).sqrt();
    assert_eq!(pt.reference().0, omega0 / (2.0 * PI));
}

/// Below the grid's U = 10⁻³⁰ m/s, down to the smallest subnormal f32 (1.4·10⁻⁴⁵ m/s).
///
/// Δμ > 0: f ≈ kU/(2ΔμP) is below 10⁻²⁰ Hz for both, nothing to render. Δμ = 0: the model gives
/// ω0/2π for every U > 0; the core computes ω0 U/(2πU), which keeps the bound while U is a normal
/// f32 (≥ 1.18·10⁻³⁸ m/s) but not for subnormal U: ω0 U and πU lose digits (≈ 6 % high at
/// U = 1.4·10⁻⁴⁵) and with ω0 = 0.01 rad/s (k = 1 mN/m, m = 10 kg) ω0 U underflows and the core
/// returns 0. The controller never passes such speeds (its smallest non-zero U is 1 µm/s), so this
/// only pins that the result stays finite, ≥ 0 and not above the model.
#[test]
fn vanishing_speeds_stay_finite() {
    let normal = [1e-35f32, f32::MIN_POSITIVE];
    let subnormal = [1e-40f32, 1e-44, f32::from_bits(1)];
    for u in normal.into_iter().chain(subnormal) {
        for delta_mu in [0.0f32, 1e-6, 0.3, 100.0] {
            for k in [1e-3f32, 500.0, 1e7] {
                for m in [1e-6f32, 1e-3, 10.0] {
                    let pt = Point {
                        u,
                        delta_mu,
                        p: 1.0,
                        m,
                        k,
                    };
                    let f = pt.core();
                    let (want, _) = pt.reference();
                    assert!(f.is_finite() && f >= 0.0, "{pt:?}: {f}");
                    if delta_mu > 0.0 {
                        assert!(f < 1e-20 && want < 1e-20, "{pt:?}: {f} vs {want}");
                    } else if u >= f32::MIN_POSITIVE {
                        let rel = (f as f64 - want).abs() / want;
                        assert!(rel <= REL_BOUND, "{pt:?}: {f} vs {want}");
                    } else {
                        assert!(f as f64 <= 1.1 * want, "{pt:?}: {f} vs {want}");
                    }
                }
            }
        }
    }
}
