//! Motion threshold: the speed gate of the textures rendered from velocity (a velocity-synthesis
//! grating, a material), so that the estimate's noise at rest makes no bursts.

use crate::burst::{FastPlanner, TimerSettings};

use super::compiled::Request;

/// Relative change of the hand speed below which the last burst plan is kept: 2^-5.
///
/// The velocity estimate moves by parts per thousand from sample to sample while the hand
/// moves steadily (its noise is a few hundred µm/s whatever the speed, so relatively more at
/// low speed), and re-planning every sample costs the frequency (a grating's multiply, a
/// material's atan and two divides), the planner and a gate update — ~250 instructions on the
/// M4F; held, none of it runs and the gate sees its running settings and returns at once.
///
/// Error bound: the plan kept was made at a speed U₀ with |U − U₀| ≤ 2^-5 U₀. Both textures'
/// frequencies have an elasticity d ln f / d ln U in (0, 1] (a grating's f = U/λ: 1; a
/// material's f_ss: A³ / ((U² + A²)((π − atan(A/U))U + A)) ≤ 1), so |f(U) − f(U₀)| ≤ 2^-5 f(U₀)
/// and the burst frequency on the line is off the asked f(U) by at most 2^-5 / (1 − 2^-5)
/// = 1/31 = 32 258 ppm (3.2 %: 3.2 Hz at 100 Hz, 64.5 Hz at the F446's 2 kHz limit), plus the
/// planner's own rounding (≤ 0.5 tick: ≤ 11 ppm at 2 kHz on 90 MHz). For scale: the estimator's
/// lag alone (3.3 ms group delay) is 5.5 % of 60 mm/s under a 1 m/s² acceleration, and a
/// vibrotactile frequency difference is felt from ~15–30 % (Weber fraction). Measured on the
/// material scene's reversal vector (60 mm/s): 466 instructions/sample at 2^-7, 421 at 2^-6,
/// 395 at 2^-5 (docs/target-cost.md).
pub(crate) const PLAN_HOLD: f32 = 1.0 / 32.0;

/// Speed threshold with hysteresis: on at `on_um_s`, off below half of it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MotionGate {
    /// On at this speed, µm/s.
    on_um_s: u32,
    /// Stays on down to this speed, µm/s: ⌈on / 2⌉, so that for a whole speed s, s ≥ on / 2
    /// ⟺ s ≥ `hold_um_s` (integer compares: the float conversion only once moving).
    hold_um_s: u32,
    moving: bool,
    /// The speed last planned at while moving, µm/s, and its plan (see [`PLAN_HOLD`]).
    held: Option<(f32, Option<(TimerSettings, bool)>)>,
}

impl MotionGate {
    pub(crate) fn new(min_speed_um_s: u32) -> Self {
        Self {
            on_um_s: min_speed_um_s,
            hold_um_s: min_speed_um_s.div_ceil(2),
            moving: false,
            held: None,
        }
    }

    /// Back to "at rest" (region change, fault): motion must be seen again above the threshold.
    pub(crate) fn reset(&mut self) {
        self.moving = false;
        self.held = None;
    }

    /// The speed to render, or None while below the threshold (or velocity unknown).
    #[inline]
    pub(crate) fn speed(&mut self, velocity_um_s: Option<i32>) -> Option<f32> {
        let Some(v) = velocity_um_s else {
            self.moving = false;
            return None;
        };
        let speed = v.unsigned_abs();
        self.moving = speed
            >= if self.moving {
                self.hold_um_s
            } else {
                self.on_um_s
            };
        // |v| as f32: the same value as (v as f32).abs().
        self.moving.then_some(speed as f32)
    }

    /// Periodic bursts at `hz_at(speed)` (speed in µm/s) while moving, at `amplitude` ‰; off
    /// below the threshold. The last plan is kept, without asking `hz_at`, while the speed
    /// stays within [`PLAN_HOLD`] of the one it was made at (a NaN never is).
    #[inline]
    pub(crate) fn request(
        &mut self,
        velocity_um_s: Option<i32>,
        planner: &FastPlanner,
        amplitude: u16,
        hz_at: impl FnOnce(f32) -> f32,
    ) -> Request {
        let Some(speed) = self.speed(velocity_um_s) else {
            self.held = None;
            return Request::OFF;
        };
        if let Some((speed0, plan)) = self.held {
            if (speed - speed0).abs() <= speed0 * PLAN_HOLD {
                return Request::planned(plan, amplitude);
            }
        }
        let plan = planner.plan_hz(hz_at(speed));
        self.held = Some((speed, plan));
        Request::planned(plan, amplitude)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::{SafetyLimits, TEST_TIMER};

    /// The plan is kept while the speed stays within 2^-5 of the one it was made at, and
    /// re-made past it. Hand-computed: λ = 1 mm, so f = U / 1 000; at U₀ = 100 mm/s the 90 MHz
    /// timer runs 900 000 ticks (100 Hz). The edges are 100 000 · (1 ± 2^-5) = 103 125 and
    /// 96 875 µm/s. At 96 875 µm/s the line keeps 100 Hz for an asked 96.875 Hz: off by
    /// 3.125 Hz, 32 258 ppm of the asked, the bound 2^-5 / (1 − 2^-5) = 1/31 itself; at the
    /// upper edge 30 303 ppm.
    #[test]
    fn the_plan_is_held_within_the_bound() {
        let planner = FastPlanner::new(&TEST_TIMER, &SafetyLimits::default(), 400).unwrap();
        let arr = |g: &mut MotionGate, v: i32| {
            g.request(Some(v), &planner, 1000, |s| s / 1_000.0)
                .settings
                .map(|s| s.arr)
        };
        let mut g = MotionGate::new(15_000);
        assert_eq!(arr(&mut g, 100_000), Some(899_999));
        assert_eq!(arr(&mut g, 103_125), Some(899_999));
        assert_eq!(arr(&mut g, -96_875), Some(899_999));
        // The rendered frequency against the asked one at the held edges, ppm.
        let ppm = |asked_hz: f64| (100.0 / asked_hz - 1.0).abs() * 1e6;
        assert!((ppm(96.875) - 32_258.06).abs() < 0.01, "{}", ppm(96.875));
        assert!((ppm(103.125) - 30_303.03).abs() < 0.01, "{}", ppm(103.125));
        assert!(ppm(96.875) <= 1e6 / 31.0 + 1e-6);
        // Past the edges: a new plan, ⌊90 MHz / f⌋ − 1 (f in f32: 103.126 → 872 718.8 ticks).
        assert_eq!(arr(&mut g, 103_126), Some(872_717));
        let mut g = MotionGate::new(15_000);
        assert_eq!(arr(&mut g, 100_000), Some(899_999));
        assert_eq!(arr(&mut g, 96_874), Some(929_040));
        // Stopping forgets the plan: the next start plans afresh.
        assert_eq!(arr(&mut g, 0), None);
        assert_eq!(arr(&mut g, 100_500), Some(895_521));
    }
}
