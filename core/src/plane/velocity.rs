//! 2D velocity: the same 1D estimator run on each axis, and the speed and direction made of the
//! pair.
//!
//! The plate reads x and y in turn within one sample period and the touch stage stamps the
//! pair with one time, so each axis is a 1D stream like the slider's: the estimators, their
//! slot clock (jitter, lost samples, gaps), resting and waking all apply per axis unchanged
//! (core/src/velocity). Their noise and lag are the 1D figures per axis (docs/estimators.md).

use super::geometry::PointUm;
use crate::velocity::VelocityEstimator;

/// A velocity in the plane, µm/s per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct VelocityUmS {
    /// Along x, µm/s.
    pub vx_um_s: i32,
    /// Along y, µm/s.
    pub vy_um_s: i32,
}

impl VelocityUmS {
    /// The speed |V|, µm/s (f32: exact to 0.1 µm/s below 2 m/s).
    pub fn speed_um_s(&self) -> f32 {
        let (x, y) = (self.vx_um_s as f32, self.vy_um_s as f32);
        super::geometry::sqrt_f32(x * x + y * y)
    }

    /// The direction of motion as a unit vector (x, y); None at zero speed.
    pub fn direction(&self) -> Option<(f32, f32)> {
        let s = self.speed_um_s();
        (s > 0.0).then(|| (self.vx_um_s as f32 / s, self.vy_um_s as f32 / s))
    }

    /// V · n for a unit vector `n`, µm/s: the speed across a line of normal n.
    pub fn along(&self, n: (f32, f32)) -> f32 {
        self.vx_um_s as f32 * n.0 + self.vy_um_s as f32 * n.1
    }
}

/// One estimator per axis.
#[derive(Clone, Debug)]
pub struct PlaneVelocity<E> {
    x: E,
    y: E,
}

impl<E: VelocityEstimator> PlaneVelocity<E> {
    /// From the two axes' estimators (built alike: same window, same sample period).
    pub fn new(x: E, y: E) -> Self {
        Self { x, y }
    }

    /// Feeds one position; the velocity once both axes have a full window.
    #[inline]
    pub fn update(&mut self, p: PointUm, t_us: u32) -> Option<VelocityUmS> {
        let vx = self.x.update(p.x_um, t_us);
        let vy = self.y.update(p.y_um, t_us);
        Some(VelocityUmS {
            vx_um_s: vx?,
            vy_um_s: vy?,
        })
    }

    /// Forgets both axes (fault, scene load).
    pub fn reset(&mut self) {
        self.x.reset();
        self.y.reset();
    }

    /// Feeds a position nobody reads the velocity of (the sample path's contract, per axis).
    #[inline]
    pub fn rest(&mut self, p: PointUm, t_us: u32) {
        self.x.rest(p.x_um, t_us);
        self.y.rest(p.y_um, t_us);
    }

    /// After rests: the next update answers as if every rest had been one.
    pub fn wake(&mut self) {
        self.x.wake();
        self.y.wake();
    }

    /// True when resting costs less than updating (both axes are built alike): a controller
    /// rests them where nothing reads the velocity.
    pub fn rests(&self) -> bool {
        self.x.rests() && self.y.rests()
    }

    /// Group delay at constant speed, µs (both axes alike).
    pub fn group_delay_us(&self) -> u32 {
        self.x.group_delay_us().max(self.y.group_delay_us())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::WindowEstimator;
    use crate::plane::testing::{directions, sigma_um, Noise, PERIOD_US};
    use crate::velocity::{LsqSlope, Median3};

    fn estimator() -> PlaneVelocity<WindowEstimator<32>> {
        let one = || Median3::new(LsqSlope::<32>::new(PERIOD_US).unwrap(), PERIOD_US);
        PlaneVelocity::new(one(), one())
    }

    #[test]
    fn speed_and_direction_in_eight_directions_with_noise() {
        // 2 LSB per axis (8 µm RMS). The 1D estimator's noise at 8 µm is σ·√(12/(N(N²−1)))/T
        // = 8·0.0191/100 µs ≈ 1.5 mm/s per axis (plus the median's share): the speed is held
        // within 6 mm/s and the direction within 6 mm/s over the speed, as an angle.
        let mut noise = Noise::new(4);
        let sigma = sigma_um(2.0);
        for (dx, dy) in directions() {
            for v_mm_s in [20.0, 200.0] {
                let v = v_mm_s * 1000.0;
                let mut e = estimator();
                let mut got = None;
                for k in 0..200u32 {
                    let t = k as f64 * PERIOD_US as f64 / 1e6;
                    let p = PointUm::new(
                        (30_000.0 + v * t * dx + noise.gauss() * sigma).round() as i32,
                        (30_000.0 + v * t * dy + noise.gauss() * sigma).round() as i32,
                    );
                    got = e.update(p, k * PERIOD_US);
                    if k < 33 {
                        // The median's 3 and the slope's 32: nothing before the 34th sample.
                        assert_eq!(got, None);
                    }
                }
                let got = got.unwrap();
                let speed = got.speed_um_s() as f64;
                assert!((speed - v).abs() < 6_000.0, "{speed} against {v}");
                let (ux, uy) = got.direction().unwrap();
                let angle = (ux as f64 * dy - uy as f64 * dx).asin().abs();
                assert!(angle < 6_000.0 / v, "{angle} rad at {v_mm_s} mm/s");
                // V · d along the true direction is the true speed; across it, ~0.
                assert!((got.along((dx as f32, dy as f32)) as f64 - v).abs() < 6_000.0);
                assert!((got.along((-dy as f32, dx as f32)) as f64).abs() < 6_000.0);
            }
        }
        assert_eq!(VelocityUmS::default().direction(), None);
    }

    #[test]
    fn resting_axes_wake_to_the_same_answer() {
        // Rest 100 samples of a diagonal stroke, wake, update: the same velocity as an
        // estimator updated all along (the 1D contract, per axis).
        let (mut a, mut b) = (estimator(), estimator());
        let at = |k: u32| PointUm::new(1_000 + 7 * k as i32, 5_000 - 3 * k as i32);
        for k in 0..200 {
            let p = at(k);
            let va = a.update(p, k * PERIOD_US);
            if (50..150).contains(&k) {
                b.rest(p, k * PERIOD_US);
            } else {
                if k == 150 {
                    b.wake();
                }
                assert_eq!(b.update(p, k * PERIOD_US), va, "sample {k}");
            }
        }
        assert_eq!(
            a.update(at(200), 200 * PERIOD_US),
            Some(VelocityUmS {
                vx_um_s: 70_000,
                vy_um_s: -30_000
            })
        );
    }
}
