//! Stick-slip frequency of a spring–mass finger on a rough surface (Nara et al., eqs. 10–12).
//!
//! ```text
//! f_ss⁻¹ = (2/ω0)(π − atan R + R)                       (10)
//! R      = (μs − μc) P / (m ω0 U)                        (11)
//! μs − μc = π (s − s') β / (E σ),   ω0 = √(k/m)          (12)
//! 1/E    = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o               (below eq. 9)
//! ```
//!
//! Eq. 10 divides by U through R. With A = Δμ P/(m ω0) (so R = A/U) it is rewritten as
//! `f = ω0 U / (2((π − atan(A/U)) U + A))`, which is finite for every U ≥ 0: U = 0 gives f = 0
//! (the finger sticks for ever), Δμ = 0 gives ω0/(2π), and R → ∞ approaches k U/(2 Δμ P).

use core::f64::consts::PI;

/// Inputs of eq. 10–11 in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StickSlipParams {
    /// μs − μc (dimensionless, ≥ 0).
    pub delta_mu: f64,
    /// Total normal force P, N.
    pub normal_force_n: f64,
    /// Finger mass m, kg.
    pub mass_kg: f64,
    /// Finger stiffness k, N/m.
    pub stiffness_n_per_m: f64,
    /// Exploration speed U, m/s (≥ 0).
    pub speed_m_s: f64,
}

impl StickSlipParams {
    /// The parameters fig. 5 of Nara et al. is drawn with: P = 1 N, m = 1 g, k = 500 N/m, U = 4 cm/s.
    pub const fn fig5(delta_mu: f64) -> Self {
        Self {
            delta_mu,
            normal_force_n: 1.0,
            mass_kg: 1e-3,
            stiffness_n_per_m: 500.0,
            speed_m_s: 0.04,
        }
    }
}

/// Result of eq. 10 with its intermediate values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StickSlip {
    /// ω0 = √(k/m), rad/s.
    pub omega0_rad_s: f64,
    /// A = Δμ P/(m ω0), m/s (R = A/U).
    pub a_m_s: f64,
    /// R of eq. 11 (+∞ when U = 0 and Δμ > 0, 0 when Δμ = 0).
    pub r: f64,
    /// f_ss, Hz.
    pub f_ss_hz: f64,
}

/// Errors of the stick-slip model (bad inputs only; the formula itself never fails).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StickSlipError {
    /// A parameter is NaN or infinite.
    NotFinite,
    /// m ≤ 0 or k ≤ 0.
    NonPositiveMassOrStiffness,
    /// Δμ < 0, P < 0 or U < 0.
    Negative,
    /// Eq. 12: E, σ or β not positive, or a Poisson ratio outside (−1, 0.5].
    BadMaterial,
}

impl core::fmt::Display for StickSlipError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let s = match self {
            Self::NotFinite => "a parameter is NaN or infinite",
            Self::NonPositiveMassOrStiffness => "mass and stiffness must be > 0",
            Self::Negative => "delta-mu, normal force and speed must be >= 0",
            Self::BadMaterial => "material parameters: E, sigma, beta > 0 and -1 < nu <= 0.5",
        };
        f.write_str(s)
    }
}

/// Material parameters of eq. 12 (SI units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Young's modulus of the object E_o, Pa.
    pub e_object_pa: f64,
    /// Poisson ratio of the object ν_o.
    pub nu_object: f64,
    /// Young's modulus of the skin E_s, Pa.
    pub e_skin_pa: f64,
    /// Poisson ratio of the skin ν_s.
    pub nu_skin: f64,
    /// Topography standard deviation σ, m.
    pub sigma_m: f64,
    /// Mean radius of projections β, m.
    pub beta_m: f64,
    /// Difference of the skin's static and kinetic shear strengths s − s', Pa.
    pub shear_strength_diff_pa: f64,
}

impl Material {
    /// Contact modulus E: 1/E = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o.
    pub fn contact_modulus_pa(&self) -> Result<f64, StickSlipError> {
        let v = [
            self.e_object_pa,
            self.nu_object,
            self.e_skin_pa,
            self.nu_skin,
        ];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(StickSlipError::NotFinite);
        }
        let nu_ok = |nu: f64| nu > -1.0 && nu <= 0.5;
        if self.e_object_pa <= 0.0
            || self.e_skin_pa <= 0.0
            || !nu_ok(self.nu_object)
            || !nu_ok(self.nu_skin)
        {
            return Err(StickSlipError::BadMaterial);
        }
        let inv = (1.0 - self.nu_skin * self.nu_skin) / self.e_skin_pa
            + (1.0 - self.nu_object * self.nu_object) / self.e_object_pa;
        Ok(1.0 / inv)
    }

    /// Eq. 12: μs − μc = π (s − s') β / (E σ).
    pub fn delta_mu(&self) -> Result<f64, StickSlipError> {
        let e = self.contact_modulus_pa()?;
        let v = [self.sigma_m, self.beta_m, self.shear_strength_diff_pa];
        if v.iter().any(|x| !x.is_finite()) {
            return Err(StickSlipError::NotFinite);
        }
        if self.sigma_m <= 0.0 || self.beta_m <= 0.0 {
            return Err(StickSlipError::BadMaterial);
        }
        if self.shear_strength_diff_pa < 0.0 {
            return Err(StickSlipError::Negative);
        }
        Ok(PI * self.shear_strength_diff_pa * self.beta_m / (e * self.sigma_m))
    }
}

/// Eq. 10–11 in f64, rewritten so that it never divides by zero (reference implementation).
pub fn stick_slip(p: &StickSlipParams) -> Result<StickSlip, StickSlipError> {
    let v = [
        p.delta_mu,
        p.normal_force_n,
        p.mass_kg,
        p.stiffness_n_per_m,
        p.speed_m_s,
    ];
    if v.iter().any(|x| !x.is_finite()) {
        return Err(StickSlipError::NotFinite);
    }
    if p.mass_kg <= 0.0 || p.stiffness_n_per_m <= 0.0 {
        return Err(StickSlipError::NonPositiveMassOrStiffness);
    }
    if p.delta_mu < 0.0 || p.normal_force_n < 0.0 || p.speed_m_s < 0.0 {
        return Err(StickSlipError::Negative);
    }
    let omega0 = (p.stiffness_n_per_m / p.mass_kg).sqrt();
    let a = p.delta_mu * p.normal_force_n / (p.mass_kg * omega0);
    let u = p.speed_m_s;
    let (r, f) = if a == 0.0 {
        // R = 0 for every U: f = ω0/(2π) (free oscillation half-period twice).
        (0.0, omega0 / (2.0 * PI))
    } else if u == 0.0 {
        (f64::INFINITY, 0.0)
    } else {
        // atan(A/U) = π/2 − atan(U/A) keeps the argument ≤ 1 when R is large; both are exact in f64.
        let at = if a > u {
            PI / 2.0 - (u / a).atan()
        } else {
            (a / u).atan()
        };
        (a / u, omega0 * u / (2.0 * ((PI - at) * u + a)))
    };
    Ok(StickSlip {
        omega0_rad_s: omega0,
        a_m_s: a,
        r,
        f_ss_hz: f,
    })
}

/// Large-R asymptote of eq. 10: f ≈ k U / (2 Δμ P).
pub fn large_r_asymptote_hz(p: &StickSlipParams) -> f64 {
    p.stiffness_n_per_m * p.speed_m_s / (2.0 * p.delta_mu * p.normal_force_n)
}

/// The f32 per-sample form used on the MCU, with the atan passed in (see `models::atan`).
/// `a_m_s` = Δμ P/(m ω0) is precomputed per region; only U changes per sample.
///
/// For U < A it uses atan(A/U) = π/2 − atan(U/A), so the atan argument stays in [0, 1]: A/U
/// overflows f32 for tiny U, and approximations such as micromath's square their argument
/// (inf/inf = NaN). Finite, ≥ 0 and never NaN for every finite U ≥ 0.
pub fn stick_slip_f32(omega0: f32, a_m_s: f32, speed_m_s: f32, atan: impl Fn(f32) -> f32) -> f32 {
    use core::f32::consts::{FRAC_PI_2, PI};
    if a_m_s <= 0.0 {
        return omega0 / (2.0 * PI);
    }
    if speed_m_s <= 0.0 {
        return 0.0;
    }
    let at = if a_m_s > speed_m_s {
        FRAC_PI_2 - atan(speed_m_s / a_m_s)
    } else {
        atan(a_m_s / speed_m_s)
    };
    omega0 * speed_m_s / (2.0 * ((PI - at) * speed_m_s + a_m_s))
}

/// One point of fig. 5's curve (P, m, k, U of [`StickSlipParams::fig5`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fig5Point {
    /// μs − μc.
    pub delta_mu: f64,
    /// R of eq. 11.
    pub r: f64,
    /// f_ss of eq. 10, Hz.
    pub f_ss_hz: f64,
    /// Large-R asymptote kU/(2ΔμP), Hz.
    pub asymptote_hz: f64,
    /// ω0/2π (the Δμ → 0 limit), Hz.
    pub f0_hz: f64,
}

/// Fig. 5's curve at `points + 1` values of Δμ, log-spaced over 1e-3…10 (the paper prints no
/// axis range; this one shows both the plateau and the asymptote).
pub fn fig5_curve(points: usize) -> Result<Vec<Fig5Point>, String> {
    (0..=points)
        .map(|i| {
            let dm = 1e-3 * 1e4f64.powf(i as f64 / points.max(1) as f64);
            let p = StickSlipParams::fig5(dm);
            let r = stick_slip(&p).map_err(|e| e.to_string())?;
            Ok(Fig5Point {
                delta_mu: dm,
                r: r.r,
                f_ss_hz: r.f_ss_hz,
                asymptote_hz: large_r_asymptote_hz(&p),
                f0_hz: r.omega0_rad_s / (2.0 * core::f64::consts::PI),
            })
        })
        .collect()
}
