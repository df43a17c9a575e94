//! Oriented gratings: the 1D grating laid across the plane, its ridges perpendicular to a unit
//! normal n.
//!
//! Only the motion across the ridges is felt (Konyo et al.: f = V/λ along the grating), so the
//! 2D grating is the 1D one fed the projections: position p = r·n and velocity V·n. Every 1D
//! renderer then applies unchanged, none copied: position phase (one burst per ridge crossed
//! along n, its pulse sized by duty·λ/|V·n|, the re-arm and the glitch guard), velocity
//! synthesis (f = |V·n|/λ, its speed threshold on |V·n|) and the hybrid (its line fitted to
//! the projected positions). Moving parallel to the ridges, p and V·n stand still: no bursts.

use super::geometry::PointUm;
use super::velocity::VelocityUmS;
use crate::burst::{BurstError, BurstTimer, SafetyLimits};
use crate::gate::Gate;
use crate::texture::compiled::{CompileError, Compiled, Moment, Need, Render, Request};
use crate::texture::{Grating, Texture, TextureError};

/// Largest component of a declared normal (the plane's coordinate range).
pub const MAX_NORMAL_COMPONENT: i32 = 1_000_000;

/// An oriented grating as the scene states it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct OrientedGrating {
    /// The 1D grating: λ, duty, renderer, re-arm, amplitude.
    pub grating: Grating,
    /// The ridges' normal (x, y), any length: (1, 0) gives ridges along y, (1, 1) ridges at
    /// 45°. Normalised at compile.
    pub normal: (i32, i32),
}

/// Why an oriented grating was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum OrientedError {
    /// The normal is (0, 0) or has a component beyond ±[`MAX_NORMAL_COMPONENT`].
    Normal {
        /// Its x component.
        x: i32,
        /// Its y component.
        y: i32,
    },
    /// The 1D grating's parameters are invalid.
    Texture(TextureError),
    /// Its bursts cannot be rendered on this board within the caps.
    Burst(BurstError),
}

impl core::fmt::Display for OrientedError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            OrientedError::Normal { x, y } => write!(
                f,
                "grating normal ({x}, {y}) must be non-zero with components within \
                 ±{MAX_NORMAL_COMPONENT}"
            ),
            OrientedError::Texture(e) => write!(f, "{e}"),
            OrientedError::Burst(e) => write!(f, "{e}"),
        }
    }
}

impl From<CompileError> for OrientedError {
    fn from(e: CompileError) -> Self {
        match e {
            CompileError::Params(t) => OrientedError::Texture(t),
            CompileError::Burst(b) => OrientedError::Burst(b),
        }
    }
}

/// An oriented grating, compiled: the unit normal and the 1D grating's compiled form.
#[derive(Clone, Debug)]
pub struct CompiledOriented {
    nx: f32,
    ny: f32,
    inner: Compiled,
}

impl OrientedGrating {
    /// Validates and prepares the grating for this board and caps, on a plate whose longest
    /// extent is `extent_um` (λ may not exceed it), sampled every `sample_period_us`.
    pub fn compile(
        &self,
        timer: &BurstTimer,
        limits: &SafetyLimits,
        extent_um: u32,
        sample_period_us: u32,
    ) -> Result<CompiledOriented, OrientedError> {
        let (x, y) = self.normal;
        if (x, y) == (0, 0)
            || x.unsigned_abs() > MAX_NORMAL_COMPONENT as u32
            || y.unsigned_abs() > MAX_NORMAL_COMPONENT as u32
        {
            return Err(OrientedError::Normal { x, y });
        }
        let (xf, yf) = (x as f32, y as f32);
        let len = libm::sqrtf(xf * xf + yf * yf);
        let (inner, _) = Compiled::compile(
            &Texture::Grating(self.grating),
            timer,
            limits,
            extent_um,
            sample_period_us,
        )?;
        Ok(CompiledOriented {
            nx: xf / len,
            ny: yf / len,
            inner,
        })
    }
}

impl CompiledOriented {
    /// The unit normal (x, y).
    pub fn normal(&self) -> (f32, f32) {
        (self.nx, self.ny)
    }

    /// The position across the ridges, p = r·n, µm (rounded).
    #[inline]
    pub fn project_um(&self, r: PointUm) -> i32 {
        super::geometry::round_to_i32(r.x_um as f32 * self.nx + r.y_um as f32 * self.ny)
    }

    /// The velocity across the ridges, V·n, µm/s (rounded).
    #[inline]
    pub fn project_um_s(&self, v: VelocityUmS) -> i32 {
        super::geometry::round_to_i32(v.along((self.nx, self.ny)))
    }

    /// What the grating reads per sample (the sample path's contract): the 1D grating's.
    pub fn need(&self) -> Need {
        self.inner.need()
    }

    /// Forgets the finger's place (window change, fault).
    pub fn reset(&mut self) {
        self.inner.reset();
    }

    /// What the grating asks of the gate for the finger at `r` moving at `v`: the 1D
    /// grating's request for the projections.
    #[inline]
    #[allow(
        dead_code,
        reason = "the 2D controller's call (not built yet, issue #36); tests call it until then"
    )]
    pub(crate) fn request(
        &mut self,
        r: PointUm,
        v: Option<VelocityUmS>,
        t_us: u32,
        gate: &Gate,
        timer: &BurstTimer,
    ) -> Request {
        let now = Moment {
            position_um: self.project_um(r),
            velocity_um_s: v.map(|v| self.project_um_s(v)),
            t_us,
            gate,
            timer,
        };
        self.inner.request(&now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::burst::TEST_TIMER;
    use crate::controller::WindowEstimator;
    use crate::plane::testing::{directions, sigma_um, Noise, PERIOD_US};
    use crate::plane::velocity::PlaneVelocity;
    use crate::texture::compiled::Want;
    use crate::texture::GratingRender;
    use crate::velocity::{LsqSlope, Median3};

    fn estimator() -> PlaneVelocity<WindowEstimator<32>> {
        let one = || Median3::new(LsqSlope::<32>::new(PERIOD_US).unwrap(), PERIOD_US);
        PlaneVelocity::new(one(), one())
    }

    fn oriented(normal: (i32, i32), render: GratingRender) -> CompiledOriented {
        let mut g = Grating::new(1_000);
        g.render = render;
        OrientedGrating { grating: g, normal }
            .compile(&TEST_TIMER, &SafetyLimits::default(), 100_000, PERIOD_US)
            .unwrap()
    }

    /// Ridges (multiples of λ) strictly between two projections, counted by hand in f64.
    fn ridges_between(p0: f64, p1: f64, lambda: f64) -> i64 {
        let (lo, hi) = (p0.min(p1), p0.max(p1));
        (hi / lambda).floor() as i64 - (lo / lambda).floor() as i64
    }

    /// Runs a straight stroke with 2 LSB noise and the 2D estimator; returns the pulses fired
    /// plus the ridges passed without one, and the true start and end points.
    fn stroke(
        g: &mut CompiledOriented,
        from: (f64, f64),
        d: (f64, f64),
        v_mm_s: f64,
        length_um: f64,
        noise: &mut Noise,
    ) -> (u32, (f64, f64), (f64, f64)) {
        let v = v_mm_s * 1000.0;
        let step = v * PERIOD_US as f64 / 1e6;
        let n = (length_um / step) as usize;
        let sigma = sigma_um(2.0);
        let mut est = estimator();
        let gate = Gate::default();
        let mut bursts = 0;
        for k in 0..=n {
            let (x, y) = (
                from.0 + k as f64 * step * d.0,
                from.1 + k as f64 * step * d.1,
            );
            let p = PointUm::new(
                (x + noise.gauss() * sigma).round() as i32,
                (y + noise.gauss() * sigma).round() as i32,
            );
            let t = k as u32 * PERIOD_US;
            let vel = est.update(p, t);
            let r = g.request(p, vel, t, &gate, &TEST_TIMER);
            if r.want == Want::Pulse {
                bursts += 1;
            }
            bursts += r.skipped;
        }
        let end = (
            from.0 + n as f64 * step * d.0,
            from.1 + n as f64 * step * d.1,
        );
        (bursts, from, end)
    }

    #[test]
    fn one_burst_per_ridge_crossed_along_n_in_eight_directions() {
        // Position phase and the hybrid (its line fitted to the projections); ridges normal to
        // x, to the diagonal and to (2, 1); strokes of 10 mm in 8 directions
        // at 20–200 mm/s with 2 LSB noise, starting and ending mid-cell (0.5 λ off a ridge
        // along n): the bursts equal the ridges crossed, counted from the true projections.
        let mut noise = Noise::new(5);
        let mut total = 0;
        for render in [GratingRender::PositionPhase, GratingRender::Hybrid] {
            for normal in [(1, 0), (1, 1), (2, 1)] {
                let len = ((normal.0 * normal.0 + normal.1 * normal.1) as f64).sqrt();
                let n = (normal.0 as f64 / len, normal.1 as f64 / len);
                for d in directions() {
                    let across = d.0 * n.0 + d.1 * n.1;
                    if across.abs() < 0.2 {
                        continue; // (nearly) parallel: the next test's
                    }
                    for v_mm_s in [20.0, 50.0, 100.0, 200.0] {
                        let mut g = oriented(normal, render);
                        // Start where the projection is mid-cell: p = 20.5 λ.
                        let from = (20_500.0 * n.0, 20_500.0 * n.1);
                        // End mid-cell too: a length whose travel along n is a whole number of λ.
                        let length = (10_000.0 / across.abs()).round().max(1.0);
                        let length =
                            (length * across.abs() / 1_000.0).round() * 1_000.0 / across.abs();
                        let (bursts, a, b) = stroke(&mut g, from, d, v_mm_s, length, &mut noise);
                        let pa = a.0 * n.0 + a.1 * n.1;
                        let pb = b.0 * n.0 + b.1 * n.1;
                        let want = ridges_between(pa, pb, 1_000.0);
                        assert!(want >= 9, "{want}");
                        assert_eq!(
                        bursts as i64, want,
                        "{render:?} normal {normal:?} dir {d:?} {v_mm_s} mm/s: {pa:.0} → {pb:.0}"
                    );
                        total += want;
                    }
                }
            }
        }
        // Two renderers × 10 ridges a stroke × 4 speeds × the directions not within 0.2 of
        // parallel: 6 for (1, 0) and (1, 1), all 8 for (2, 1).
        assert_eq!(total, 2 * 10 * 4 * (6 + 6 + 8));
    }

    #[test]
    fn none_while_moving_parallel_to_the_ridges() {
        // Along the ridges (d ⟂ n) for 20 mm at 20–200 mm/s with 2 LSB noise, on a ridge and
        // between two: nothing, by position phase or velocity synthesis.
        let mut noise = Noise::new(6);
        for normal in [(1, 0), (1, 1), (-1, 2)] {
            let len = ((normal.0 * normal.0 + normal.1 * normal.1) as f64).sqrt();
            let n = (normal.0 as f64 / len, normal.1 as f64 / len);
            for d in [(-n.1, n.0), (n.1, -n.0)] {
                for offset in [20_000.0, 20_500.0] {
                    for render in [
                        GratingRender::PositionPhase,
                        GratingRender::VelocitySynthesis,
                    ] {
                        for v_mm_s in [20.0, 200.0] {
                            let mut g = oriented(normal, render);
                            let from = (50_000.0 + offset * n.0, 50_000.0 + offset * n.1);
                            let from = (from.0 - 10_000.0 * d.0, from.1 - 10_000.0 * d.1);
                            let (bursts, _, _) =
                                stroke(&mut g, from, d, v_mm_s, 20_000.0, &mut noise);
                            assert_eq!(bursts, 0, "{normal:?} {d:?} {offset} {render:?}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn velocity_synthesis_runs_at_the_speed_across_the_ridges_over_lambda() {
        // λ = 1 mm, ridges at 45° (n = (1, 1)/√2), V = 100 mm/s along x: V·n = 70.71 mm/s,
        // f = 70.71 Hz by hand. Along y the same; along (1, −1), across nothing: off.
        let gate = Gate::default();
        let hz = |v: VelocityUmS| {
            let mut g = oriented((1, 1), GratingRender::VelocitySynthesis);
            let r = g.request(PointUm::new(0, 0), Some(v), 0, &gate, &TEST_TIMER);
            r.settings
                .map(|s| TEST_TIMER.clock_hz as f64 / s.period_clocks() as f64)
        };
        let v = |x, y| VelocityUmS {
            vx_um_s: x,
            vy_um_s: y,
        };
        for got in [hz(v(100_000, 0)), hz(v(0, 100_000)), hz(v(-100_000, 0))] {
            let got = got.unwrap();
            assert!((got - 70.710_678).abs() < 0.01, "{got} Hz");
        }
        assert_eq!(hz(v(100_000, -100_000)), None);
    }

    #[test]
    fn refusals() {
        let g = |normal| {
            OrientedGrating {
                grating: Grating::new(1_000),
                normal,
            }
            .compile(&TEST_TIMER, &SafetyLimits::default(), 100_000, PERIOD_US)
            .err()
            .map(|e| std::format!("{e}"))
        };
        assert_eq!(
            g((0, 0)),
            Some("grating normal (0, 0) must be non-zero with components within ±1000000".into())
        );
        assert!(g((1_000_001, 0)).is_some());
        assert_eq!(g((3, 4)), None);
        let mut bad = OrientedGrating {
            grating: Grating::new(0),
            normal: (1, 0),
        };
        bad.grating.rearm_um = 0;
        assert_eq!(
            bad.compile(&TEST_TIMER, &SafetyLimits::default(), 100_000, PERIOD_US)
                .err(),
            Some(OrientedError::Texture(TextureError::BadWavelength {
                wavelength_um: 0,
                length_um: 100_000
            }))
        );
    }
}
