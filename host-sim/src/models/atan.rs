//! atan for the per-sample stick-slip path on the MCU: `micromath::F32Ext::atan` against
//! `libm::atanf`, with f64 `atan` as the reference.
//!
//! Errors are measured over the R range of interest (R = Δμ P/(m ω0 U) ∈ [0, 1000]: Δμ up to 1,
//! fig. 5's P, m, k and U down to 1.4 mm/s), both on atan itself and on the f_ss it feeds
//! (eq. 10 in f32 against the f64 reference). Cost is counted, not timed: the `bench_*` loops are
//! `#[inline(never)]` so that `valgrind --tool=callgrind --toggle-collect=<loop>` counts exactly
//! their instructions (see docs/models.md for the commands).

use super::stick_slip::{stick_slip, stick_slip_f32, StickSlipParams};
use core::hint::black_box;

/// Implementations compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AtanImpl {
    /// `micromath::F32Ext::atan` (polynomial approximation, no division by a polynomial).
    Micromath,
    /// `libm::atanf` (musl's, ≤ 1 ulp).
    Libm,
    /// f64 `atan` of std, rounded to f32 (reference; not an MCU option).
    F64,
}

impl AtanImpl {
    /// All three.
    pub const ALL: [AtanImpl; 3] = [AtanImpl::Micromath, AtanImpl::Libm, AtanImpl::F64];

    /// CLI/CSV name.
    pub fn name(self) -> &'static str {
        match self {
            AtanImpl::Micromath => "micromath",
            AtanImpl::Libm => "libm",
            AtanImpl::F64 => "f64",
        }
    }

    /// Parses [`AtanImpl::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|x| x.name() == s)
    }

    /// Evaluates the implementation.
    pub fn eval(self, x: f32) -> f32 {
        match self {
            AtanImpl::Micromath => micromath::F32Ext::atan(x),
            AtanImpl::Libm => libm::atanf(x),
            AtanImpl::F64 => (x as f64).atan() as f32,
        }
    }
}

/// Largest R of interest.
pub const R_MAX: f64 = 1000.0;

/// The R grid: 0…10 in steps of 0.001, then log-spaced 10…1000 (10 001 + 2 000 points).
pub fn r_grid() -> Vec<f32> {
    let mut v: Vec<f32> = (0..=10_000).map(|i| i as f32 * 0.001).collect();
    for i in 1..=2000 {
        v.push((10f64 * (R_MAX / 10.0).powf(i as f64 / 2000.0)) as f32);
    }
    v
}

/// Error statistics of one implementation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtanError {
    /// Which.
    pub imp: AtanImpl,
    /// max |atan_impl(x) − atan(x)| over the grid, rad (x the f32 grid value, reference in f64).
    pub max_abs_rad: f64,
    /// mean |…|, rad.
    pub mean_abs_rad: f64,
    /// max relative f_ss error of eq. 10 in f32 with this atan against the f64 model.
    pub max_rel_f_ss: f64,
    /// mean relative f_ss error.
    pub mean_rel_f_ss: f64,
}

/// Measures atan and f_ss errors over [`r_grid`]. f_ss uses fig. 5's P, m, k, Δμ = 1 and U = A/R.
pub fn atan_errors(imp: AtanImpl) -> AtanError {
    let grid = r_grid();
    let p = StickSlipParams::fig5(1.0);
    let reference = stick_slip(&p).expect("fig. 5 parameters are valid");
    let (w0, a) = (reference.omega0_rad_s, reference.a_m_s);
    let (mut max_a, mut sum_a, mut max_f, mut sum_f) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut n_f = 0usize;
    for &x in &grid {
        let e = (imp.eval(x) as f64 - (x as f64).atan()).abs();
        max_a = max_a.max(e);
        sum_a += e;
        if x > 0.0 {
            let u = a / x as f64;
            let fr = stick_slip(&StickSlipParams { speed_m_s: u, ..p })
                .expect("valid")
                .f_ss_hz;
            let f = stick_slip_f32(w0 as f32, a as f32, u as f32, |r| imp.eval(r)) as f64;
            let rel = ((f - fr) / fr).abs();
            max_f = max_f.max(rel);
            sum_f += rel;
            n_f += 1;
        }
    }
    AtanError {
        imp,
        max_abs_rad: max_a,
        mean_abs_rad: sum_a / grid.len() as f64,
        max_rel_f_ss: max_f,
        mean_rel_f_ss: sum_f / n_f as f64,
    }
}

/// One point of the atan error curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AtanCurvePoint {
    /// R = Δμ P/(m ω0 U) (an f32 grid value).
    pub r: f32,
    /// Implementation.
    pub imp: AtanImpl,
    /// |atan_impl(R) − atan(R)|, rad (reference in f64).
    pub abs_err_rad: f64,
    /// Relative error of eq. 10 in f32 with this atan against the f64 model.
    pub rel_err_f_ss: f64,
}

/// Error against R for each implementation (every 10th point of the R grid, R > 0; all
/// implementations at one R before the next R).
pub fn atan_curve() -> Vec<AtanCurvePoint> {
    let p = StickSlipParams::fig5(1.0);
    let Ok(reference) = stick_slip(&p) else {
        return Vec::new();
    };
    let (w0, a) = (reference.omega0_rad_s, reference.a_m_s);
    let mut v = Vec::new();
    for (i, &x) in r_grid().iter().enumerate() {
        if i % 10 != 0 || x <= 0.0 {
            continue;
        }
        let u = a / x as f64;
        let Ok(fr) = stick_slip(&StickSlipParams { speed_m_s: u, ..p }) else {
            continue;
        };
        for imp in AtanImpl::ALL {
            let e = (imp.eval(x) as f64 - (x as f64).atan()).abs();
            let f = stick_slip_f32(w0 as f32, a as f32, u as f32, |r| imp.eval(r)) as f64;
            v.push(AtanCurvePoint {
                r: x,
                imp,
                abs_err_rad: e,
                rel_err_f_ss: ((f - fr.f_ss_hz) / fr.f_ss_hz).abs(),
            });
        }
    }
    v
}

/// ω0 of fig. 5 (√(500/0.001)), rad/s.
pub const FIG5_OMEGA0: f32 = 707.106_8;
/// A = Δμ P/(m ω0) of fig. 5 with Δμ = 1, m/s (= √2).
pub const FIG5_A: f32 = core::f32::consts::SQRT_2;

/// Bench input: `n` values spread over the R grid.
pub fn bench_input(n: usize) -> Vec<f32> {
    let g = r_grid();
    (0..n).map(|i| g[(i * 7919) % g.len()]).collect()
}

/// Loop overhead only (identity), for subtraction.
#[inline(never)]
pub fn bench_atan_none(xs: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &x in xs {
        s += black_box(x);
    }
    s
}

/// Σ micromath atan.
#[inline(never)]
pub fn bench_atan_micromath(xs: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &x in xs {
        s += micromath::F32Ext::atan(black_box(x));
    }
    s
}

/// Σ libm atanf.
#[inline(never)]
pub fn bench_atan_libm(xs: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &x in xs {
        s += libm::atanf(black_box(x));
    }
    s
}

/// Σ f64 atan.
#[inline(never)]
pub fn bench_atan_f64(xs: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &x in xs {
        s += (black_box(x) as f64).atan() as f32;
    }
    s
}

/// Σ f_ss (eq. 10, f32) with micromath atan; the per-sample path with U = A/R.
#[inline(never)]
pub fn bench_fss_micromath(us: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &u in us {
        s += stick_slip_f32(FIG5_OMEGA0, FIG5_A, black_box(u), micromath::F32Ext::atan);
    }
    s
}

/// Σ f_ss with libm atanf.
#[inline(never)]
pub fn bench_fss_libm(us: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for &u in us {
        s += stick_slip_f32(FIG5_OMEGA0, FIG5_A, black_box(u), libm::atanf);
    }
    s
}

/// The loops [`run_bench`] runs (`model atan-bench --impl`).
pub const BENCH_IMPLS: [&str; 6] = [
    "none",
    "micromath",
    "libm",
    "f64",
    "fss-micromath",
    "fss-libm",
];

/// Runs one bench loop over `n` inputs; `what` is `none`, `micromath`, `libm`, `f64`,
/// `fss-micromath` or `fss-libm`.
pub fn run_bench(what: &str, n: usize) -> Result<f32, String> {
    let xs = bench_input(n);
    let us: Vec<f32> = xs.iter().map(|&r| FIG5_A / r.max(1e-3)).collect();
    Ok(match what {
        "none" => bench_atan_none(&xs),
        "micromath" => bench_atan_micromath(&xs),
        "libm" => bench_atan_libm(&xs),
        "f64" => bench_atan_f64(&xs),
        "fss-micromath" => bench_fss_micromath(&us),
        "fss-libm" => bench_fss_libm(&us),
        _ => return Err(format!("unknown bench {what:?}")),
    })
}
