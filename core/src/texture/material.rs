//! Material texture: the stick-slip frequency of the SAW display paper (eq. 10–12) at the live
//! hand speed U = |V|:
//!
//! f_ss⁻¹ = (2/ω0)(π − atan R + R),  R = (μs − μc) P / (m ω0 U),  ω0 = √(k/m).
//!
//! With A = (μs − μc) P / (m ω0), so R = A/U, this is rewritten as
//! f_ss = ω0 U / (2 ((π − atan(A/U)) U + A)),
//! which is finite for every U ≥ 0: U → 0 (R → ∞) gives f → kU/(2ΔμP) → 0, and Δμ = 0 gives
//! ω0/2π. ω0 and A are computed once at scene load; the per-sample cost is one atan, two
//! multiplies and one divide. Δμ itself comes from the material parameters of eq. 12
//! (μs − μc = π(s − s')β/(E σ)), resolved when the scene file is read.

use crate::burst::{BurstTimer, FastPlanner, SafetyLimits};

use super::compiled::{CompileError, Moment, Render, Request};
use super::motion::MotionGate;
use super::{MaterialParam, ParamValue, TextureError, FULL_AMPLITUDE};

/// A material region's parameters (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Material {
    /// μs − μc, the static minus kinetic friction coefficient (eq. 12), ≥ 0.
    pub delta_mu: f32,
    /// P: total normal force of the skin, N.
    pub normal_force_n: f32,
    /// m: finger mass of the spring-mass model, kg.
    pub mass_kg: f32,
    /// k: finger stiffness, N/m.
    pub stiffness_n_per_m: f32,
    /// Duty of each burst, ‰.
    pub duty_permille: u16,
    /// Bursts start above this speed, µm/s, and stop below half of it.
    pub min_speed_um_s: u32,
}

/// Constants of a material prepared at load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MaterialConsts {
    omega0: f32,
    /// A = Δμ P / (m ω0), m/s.
    a_m_per_s: f32,
}

impl Material {
    /// Fig. 5's finger: P = 1 N, m = 1 g, k = 500 N/m, with the given Δμ.
    pub const fn fig5(delta_mu: f32) -> Self {
        Self {
            delta_mu,
            normal_force_n: 1.0,
            mass_kg: 0.001,
            stiffness_n_per_m: 500.0,
            duty_permille: 400,
            min_speed_um_s: 15_000,
        }
    }

    /// Checks the parameters.
    pub fn validate(&self) -> Result<(), TextureError> {
        let positive = |x: f32| x.is_finite() && x > 0.0;
        let bad = |param, x| {
            Err(TextureError::BadMaterial {
                param,
                value: ParamValue(x),
            })
        };
        if !(self.delta_mu.is_finite() && self.delta_mu >= 0.0) {
            return bad(MaterialParam::DeltaMu, self.delta_mu);
        }
        if !positive(self.normal_force_n) {
            return bad(MaterialParam::NormalForce, self.normal_force_n);
        }
        if !positive(self.mass_kg) {
            return bad(MaterialParam::Mass, self.mass_kg);
        }
        if !positive(self.stiffness_n_per_m) {
            return bad(MaterialParam::Stiffness, self.stiffness_n_per_m);
        }
        if self.min_speed_um_s > 1_000_000 {
            return Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: self.min_speed_um_s,
            });
        }
        Ok(())
    }

    pub(crate) fn prepare(&self) -> MaterialConsts {
        let omega0 = libm::sqrtf(self.stiffness_n_per_m / self.mass_kg);
        MaterialConsts {
            omega0,
            a_m_per_s: self.delta_mu * self.normal_force_n / (self.mass_kg * omega0),
        }
    }

    /// f_ss in Hz at hand speed `speed_m_s` ≥ 0 (load-time constants recomputed: for hosts and
    /// tests; the controller uses the prepared form).
    pub fn stick_slip_hz(&self, speed_m_s: f32) -> f32 {
        self.prepare().stick_slip_hz(speed_m_s)
    }
}

impl MaterialConsts {
    /// f_ss in Hz at hand speed `u` m/s, finite for every u ≥ 0.
    // Negated on purpose: a NaN speed is refused like zero.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub(crate) fn stick_slip_hz(&self, u: f32) -> f32 {
        if !(u > 0.0) {
            return 0.0;
        }
        let a = self.a_m_per_s;
        // atan(A/U) with its argument kept in [0, 1]: A/U overflows f32 as U → 0.
        let atan_r = if a == 0.0 {
            0.0
        } else if u < a {
            core::f32::consts::FRAC_PI_2 - atan(u / a)
        } else {
            atan(a / u)
        };
        self.omega0 * u / (2.0 * ((core::f32::consts::PI - atan_r) * u + a))
    }
}

/// The atan of the per-sample path, on [0, 1]. micromath's, per the error-against-cost study
/// (docs/models.md): 2.8·10⁻³ rad worst, 0.09 % worst in f_ss, about a third of libm's cost.
#[inline]
fn atan(x: f32) -> f32 {
    micromath::F32Ext::atan(x)
}

/// A material region, compiled: the stick-slip frequency at the hand speed, above the speed
/// threshold.
#[derive(Clone, Copy, Debug)]
pub(crate) struct StickSlip {
    consts: MaterialConsts,
    motion: MotionGate,
    planner: FastPlanner,
}

impl StickSlip {
    pub(crate) fn new(
        m: &Material,
        timer: &BurstTimer,
        limits: &SafetyLimits,
    ) -> Result<Self, CompileError> {
        m.validate()?;
        Ok(Self {
            consts: m.prepare(),
            motion: MotionGate::new(m.min_speed_um_s),
            planner: FastPlanner::new(timer, limits, m.duty_permille)?,
        })
    }
}

impl Render for StickSlip {
    fn reset(&mut self) {
        self.motion.reset();
    }

    // Every sample from the controller's one call site (`Compiled::request`): inlined.
    #[inline(always)]
    fn request(&mut self, now: &Moment<'_>) -> Request {
        let consts = &self.consts;
        self.motion
            .request(now.velocity_um_s, &self.planner, FULL_AMPLITUDE, |speed| {
                consts.stick_slip_hz(speed * 1e-6)
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_are_finite_and_right() {
        let m = Material::fig5(0.5);
        let omega0 = (500.0f32 / 0.001).sqrt();
        assert_eq!(m.stick_slip_hz(0.0), 0.0);
        // Vanishing speeds stay finite and tiny (A/U would overflow f32 without the reduction).
        for u in [1e-38f32, 1e-30, 1e-12] {
            let f = m.stick_slip_hz(u);
            assert!(f.is_finite() && (0.0..1e-3).contains(&f), "{u}: {f}");
        }
        // Frictionless limit: ω0/2π.
        let free = Material::fig5(0.0).stick_slip_hz(0.04);
        assert!(
            (free - omega0 / (2.0 * core::f32::consts::PI)).abs() < 1e-3,
            "{free}"
        );
        // Slow limit: kU/(2ΔμP).
        let u = 1e-5;
        let slow = m.stick_slip_hz(u);
        let asym = 500.0 * u / (2.0 * 0.5 * 1.0);
        assert!((slow - asym).abs() / asym < 1e-2, "{slow} vs {asym}");
        // Monotone in speed.
        let mut last = 0.0;
        for i in 1..200 {
            let f = m.stick_slip_hz(i as f32 * 0.002);
            assert!(f.is_finite() && f > last);
            last = f;
        }
    }

    #[test]
    fn bad_parameters_rejected() {
        assert!(Material {
            mass_kg: 0.0,
            ..Material::fig5(0.5)
        }
        .validate()
        .is_err());
        assert!(Material {
            delta_mu: f32::NAN,
            ..Material::fig5(0.5)
        }
        .validate()
        .is_err());
        assert!(Material::fig5(0.0).validate().is_ok());
    }

    /// Each parameter alone: Δμ finite and ≥ 0; P, m, k finite and > 0; start threshold up to
    /// 1 m/s.
    #[test]
    fn each_parameter_checked_alone() {
        let m = Material::fig5(0.5);
        let bad = |param, x| {
            Err(TextureError::BadMaterial {
                param,
                value: ParamValue(x),
            })
        };
        for d in [-0.01, f32::INFINITY, f32::NAN] {
            assert_eq!(
                Material { delta_mu: d, ..m }.validate(),
                bad(MaterialParam::DeltaMu, d),
                "delta_mu {d}"
            );
        }
        for x in [0.0, -1.0, f32::INFINITY, f32::NAN] {
            assert_eq!(
                Material {
                    normal_force_n: x,
                    ..m
                }
                .validate(),
                bad(MaterialParam::NormalForce, x),
                "P {x}"
            );
            assert_eq!(
                Material { mass_kg: x, ..m }.validate(),
                bad(MaterialParam::Mass, x),
                "m {x}"
            );
            assert_eq!(
                Material {
                    stiffness_n_per_m: x,
                    ..m
                }
                .validate(),
                bad(MaterialParam::Stiffness, x),
                "k {x}"
            );
        }
        let tiny = f32::MIN_POSITIVE;
        assert_eq!(
            Material {
                normal_force_n: tiny,
                mass_kg: tiny,
                stiffness_n_per_m: tiny,
                ..m
            }
            .validate(),
            Ok(())
        );
        assert_eq!(
            Material {
                min_speed_um_s: 1_000_000,
                ..m
            }
            .validate(),
            Ok(())
        );
        assert_eq!(
            Material {
                min_speed_um_s: 1_000_001,
                ..m
            }
            .validate(),
            Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: 1_000_001
            })
        );
    }
}
