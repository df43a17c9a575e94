//! The estimators under test, each with the configuration the bench gives it.
//!
//! Windows and gains are in samples, as the firmware would configure them for 10 kHz; the
//! sample-rate sweep keeps them in samples (so the delay in ms scales with the period).

use saw_core::velocity::{
    AlphaBeta, AlphaBetaFixed, BackwardDifference, Foaw, FoawFit, LsqSlope, Median3,
    OneSampleDifference, SuperTwisting, VelocityEstimator,
};

/// A boxed estimator the bench can move between threads.
pub type BoxedEstimator = Box<dyn VelocityEstimator + Send>;

/// A boxed estimator as the controller takes it (the closed-loop runs of the renderer columns).
pub struct Dyn(pub BoxedEstimator);

impl VelocityEstimator for Dyn {
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32> {
        self.0.update(position_um, t_us)
    }
    fn reset(&mut self) {
        self.0.reset()
    }
    fn group_delay_us(&self) -> u32 {
        self.0.group_delay_us()
    }
}

/// One configured estimator.
#[derive(Clone, Copy, Debug)]
pub struct Method {
    /// Short name used in tables, charts and the cost run.
    pub name: &'static str,
    /// Family, for chart colours.
    pub family: Family,
    /// Builds the estimator for a sample period (µs).
    pub build: fn(u32) -> BoxedEstimator,
}

/// Estimator families.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// Backward differences.
    Difference,
    /// Least-squares slope (integer, the baseline).
    Lsq,
    /// First-order adaptive windowing.
    Foaw,
    /// α-β filters, f32 and fixed.
    AlphaBeta,
    /// Super-twisting differentiator.
    SuperTwisting,
    /// Median-of-3 wrapped.
    Median,
}

/// FOAW band at the bench's reference noise: 3 σ of 2 LSB (σ_x = 4 × 2 codes ≈ 8 µm).
pub const FOAW_BAND_UM: f32 = 24.0;

macro_rules! m {
    ($name:expr, $fam:ident, |$p:ident| $e:expr) => {
        Method {
            name: $name,
            family: Family::$fam,
            build: |$p: u32| -> BoxedEstimator { Box::new($e) },
        }
    };
}

/// Every method the bench runs, the default (`lsq32`) included.
pub fn all() -> Vec<Method> {
    vec![
        m!("diff1", Difference, |p| OneSampleDifference::new(p)
            .unwrap()),
        m!("diff4", Difference, |p| BackwardDifference::<4>::new(p)
            .unwrap()),
        m!("diff16", Difference, |p| BackwardDifference::<16>::new(p)
            .unwrap()),
        m!("lsq8", Lsq, |p| LsqSlope::<8>::new(p).unwrap()),
        m!("lsq16", Lsq, |p| LsqSlope::<16>::new(p).unwrap()),
        m!("lsq24", Lsq, |p| LsqSlope::<24>::new(p).unwrap()),
        m!("lsq32", Lsq, |p| LsqSlope::<32>::new(p).unwrap()),
        m!("lsq48", Lsq, |p| LsqSlope::<48>::new(p).unwrap()),
        m!("lsq64", Lsq, |p| LsqSlope::<64>::new(p).unwrap()),
        m!("foaw-end-d24-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::EndFit,
            FOAW_BAND_UM,
            p
        )
        .unwrap()),
        m!("foaw-best-d24-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::BestFit,
            FOAW_BAND_UM,
            p
        )
        .unwrap()),
        m!("foaw-best-d12-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::BestFit,
            12.0,
            p
        )
        .unwrap()),
        m!("foaw-best-d32-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::BestFit,
            32.0,
            p
        )
        .unwrap()),
        m!("foaw-best-d48-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::BestFit,
            48.0,
            p
        )
        .unwrap()),
        m!("foaw-end-d48-n32", Foaw, |p| Foaw::<33>::new(
            FoawFit::EndFit,
            48.0,
            p
        )
        .unwrap()),
        m!("foaw-best-d40-n64", Foaw, |p| Foaw::<65>::new(
            FoawFit::BestFit,
            40.0,
            p
        )
        .unwrap()),
        m!("ab-p0.8", AlphaBeta, |p| AlphaBeta::critically_damped(
            p, 0.8
        )
        .unwrap()),
        m!("ab-p0.9", AlphaBeta, |p| AlphaBeta::critically_damped(
            p, 0.9
        )
        .unwrap()),
        m!("ab-p0.95", AlphaBeta, |p| AlphaBeta::critically_damped(
            p, 0.95
        )
        .unwrap()),
        m!("abq16-p0.9", AlphaBeta, |p| {
            AlphaBetaFixed::critically_damped(p, 0.9).unwrap()
        }),
        m!("abq16-p0.95", AlphaBeta, |p| {
            AlphaBetaFixed::critically_damped(p, 0.95).unwrap()
        }),
        m!("std-L1e6", SuperTwisting, |p| SuperTwisting::new(p, 1e6)
            .unwrap()),
        m!("std-L1e7", SuperTwisting, |p| SuperTwisting::new(p, 1e7)
            .unwrap()),
        m!("med3+lsq32", Median, |p| Median3::new(
            LsqSlope::<32>::new(p).unwrap(),
            p
        )),
        m!("med3+ab-p0.9", Median, |p| Median3::new(
            AlphaBeta::critically_damped(p, 0.9).unwrap(),
            p
        )),
        m!("med3+foaw-best-d24-n32", Median, |p| Median3::new(
            Foaw::<33>::new(FoawFit::BestFit, FOAW_BAND_UM, p).unwrap(),
            p
        )),
    ]
}

/// The controller's default.
pub const DEFAULT: &str = "med3+lsq32";
/// The FOAW best-fit the targets compare against, unless another band tunes it better: the
/// report picks the FOAW best-fit with n_max = 32 and the lowest RMS on the reference motion.
pub const FOAW_REFERENCE: &str = "foaw-best-d24-n32";
/// The FOAW best-fit candidates for the reference (n_max = 32, bands 12–48 µm).
pub const FOAW_CANDIDATES: [&str; 4] = [
    "foaw-best-d12-n32",
    "foaw-best-d24-n32",
    "foaw-best-d32-n32",
    "foaw-best-d48-n32",
];
