//! Velocity stage: differentiates position into velocity behind one estimator interface.
//!
//! Baseline: the least-squares slope of the last `N` positions ([`LsqSlope`]). It is unbiased at
//! every constant speed (so it stays honest as v → 0, where finite differences only see
//! quantization steps), its noise and delay are closed-form, and it runs in O(1) integer work per
//! sample by updating two running sums — bit-exact on any platform.
//!
//! For white position noise σ_x and sample period T_s:
//! - noise: σ_v = σ_x · √(12 / (N (N² − 1))) / T_s
//!   (N = 32, T_s = 100 µs, σ_x = 12 µm → σ_v ≈ 2.3 mm/s);
//! - group delay at constant acceleration: (N − 1)/2 · T_s (N = 32 → 1.55 ms).
//!
//! Samples are expected at a fixed period (the ADC is timer-triggered). Every estimator places
//! them on the sampling grid with the shared slot clock (`common.rs`): jitter is rounded away, up
//! to three lost samples are bridged, and a longer silence restarts the estimator.

mod alpha_beta;
mod alpha_beta_fixed;
mod clamp;
mod common;
mod diff;
mod foaw;
mod gate;
mod lsq;
mod median;
mod super_twisting;
#[cfg(test)]
mod test_strokes;

pub use alpha_beta::AlphaBeta;
pub use alpha_beta_fixed::AlphaBetaFixed;
pub use clamp::StepClamp;
pub use common::{TuningError, MAX_BRIDGED_SLOTS, MIN_FIXED_BETA};
pub use diff::{BackwardDifference, OneSampleDifference};
pub use foaw::{Foaw, FoawFit};
pub use gate::InnovationGate;
pub use lsq::{LsqSlope, LSQ_NARROW_WINDOW};
pub use median::Median3;
pub use super_twisting::{SuperTwisting, STD_LAMBDA0, STD_LAMBDA1};
// The pieces the plane's two-axis slope (`plane::velocity::PlaneLsq`) shares with the 1D ones.
pub(crate) use common::{check_period, SlotClock, Tick};
pub(crate) use lsq::{slope_gain_q32, speed_range};
pub(crate) use median::median3;

/// One velocity estimator: fed each position with its timestamp, answers velocity in µm/s
/// (positive towards the far end), or `None` while it has too little history.
pub trait VelocityEstimator {
    /// Feeds one position, returns the current estimate.
    fn update(&mut self, position_um: i32, t_us: u32) -> Option<i32>;
    /// Forgets all history (after a sensor fault or a scene change).
    fn reset(&mut self);
    /// Group delay of the estimate at constant speed, µs.
    fn group_delay_us(&self) -> u32;

    /// True when [`Self::rest`] does less than [`Self::update`]: the controller then rests the
    /// estimator in regions whose texture reads no velocity (`docs/sample-contract.md`). An
    /// estimator that leaves this false is updated on every sample, as before the contract.
    /// (A method, not a constant, so the trait stays usable as `dyn`; inlined, it is one.)
    #[inline(always)]
    fn rests(&self) -> bool {
        false
    }

    /// Feeds one position while nobody reads the estimate: keeps only what [`Self::wake`] needs
    /// to give the estimate `update` would have given. The default updates.
    #[inline(always)]
    fn rest(&mut self, position_um: i32, t_us: u32) {
        let _ = self.update(position_um, t_us);
    }

    /// Makes the state whole again after [`Self::rest`]s, so the next `update` answers exactly
    /// what it would have answered had every rested sample been an `update`.
    fn wake(&mut self) {}

    /// The estimate after the samples fed so far, rests included, without changing anything:
    /// for telemetry, read at the stream's rate rather than every sample. Only called on an
    /// estimator that [`Self::rests`]; the default says nothing.
    fn estimate(&self) -> Option<i32> {
        None
    }

    /// The samples, fed from scratch by [`Self::update`], after which the estimate is the one
    /// an estimator fed all along would give (its window; 0: no such number, never seeded).
    /// The controller lets an estimator with a window sleep where a texture's own fit gives
    /// the velocity, and seeds it from that fit's newest positions on leaving.
    #[inline(always)]
    fn window_samples(&self) -> usize {
        0
    }
}

/// Why an estimator could not be configured (the values its sentence, `Display`, names).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum EstimatorError {
    /// Window shorter than the estimator needs (2 samples for a slope, 1 for a difference).
    WindowTooShort {
        /// The window asked for, samples.
        window: usize,
        /// The shortest this estimator takes, samples.
        min: usize,
    },
    /// Sample period outside 10 µs ..= 100 ms.
    BadSamplePeriod {
        /// The period asked for, µs.
        sample_period_us: u32,
    },
}

impl core::fmt::Display for EstimatorError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            EstimatorError::WindowTooShort { window, min } => write!(
                f,
                "a velocity window of {window} samples is shorter than the {min} the estimator \
                 needs"
            ),
            EstimatorError::BadSamplePeriod { sample_period_us } => write!(
                f,
                "sample period {sample_period_us} µs is outside the estimators' 10 µs to \
                 100000 µs"
            ),
        }
    }
}
