//! A simulated participant, for tests and for planning studies: Thurstonian percepts of the
//! burst frequency f_b (or of the seed paper's stick-slip frequency f_ss) for paired
//! comparisons, and a known psychometric function for forced-choice detection. Every random
//! draw comes from the spec's seed (ChaCha8), so a run is reproducible.
//!
//! **Percepts (paired comparisons).** Perceived roughness of a presentation is
//! r(f_b) + N(0, noise²) with r = −ln(f_b / 1 Hz) ([`Percept::LogFb`]: rougher = lower f_b, as
//! the seed paper reports, Nara et al. 2001, "Obtained tactile sensation") or
//! r = −ln(f_ss / 1 Hz) with f_ss the stick-slip frequency of eq. 10–12 of that paper
//! ([`Percept::StickSlip`], see there for how a burst frequency is mapped onto the model). A
//! fresh draw is made for each presentation (Thurstone 1927, case V: equal, uncorrelated
//! dispersions), so P(first judged rougher) = Φ((r₁ − r₂) / (noise·√2)).
//!
//! **Detection (forced choice).** A two-interval forced choice at a stimulus difference x is
//! correct with probability ψ(x) = ½ + (½ − λ) Φ((x − threshold) / spread): a cumulative normal
//! in the level's units, γ = ½, and λ the lapse rate in Wichmann & Hill's (2001) sense (the
//! errors far above threshold).

use std::f64::consts::PI;
use std::fmt;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use statrs::distribution::{ContinuousCDF, Normal};

/// The guess rate of a two-interval forced choice.
pub const GUESS_2IFC: f64 = 0.5;

/// The parameters of the seed paper's stick-slip model (Nara et al. 2001, eq. 10–12): a
/// spring (k) – mass (m) finger pressed with P and drawn at speed U over a surface whose
/// static and kinetic friction coefficients differ by μs − μc.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StickSlipParams {
    /// P, the total normal force of the skin, N.
    pub normal_force_n: f64,
    /// m, the finger's mass, kg.
    pub mass_kg: f64,
    /// k, the finger's stiffness, N/m.
    pub stiffness_n_per_m: f64,
    /// U, the exploration speed, m/s.
    pub speed_m_per_s: f64,
    /// μs − μc, static minus kinetic friction coefficient (dimensionless, ≥ 0): fig. 5's
    /// abscissa; from a surface's parameters by [`friction_difference`] (eq. 12).
    pub friction_difference: f64,
}

impl StickSlipParams {
    /// The paper's fig. 5 values, P = 1 N, m = 1 g, k = 500 N/m, U = 4 cm/s, at a given
    /// μs − μc (the figure's abscissa).
    pub fn fig5(friction_difference: f64) -> Self {
        Self {
            normal_force_n: 1.0,
            mass_kg: 1e-3,
            stiffness_n_per_m: 500.0,
            speed_m_per_s: 0.04,
            friction_difference,
        }
    }

    /// ω0 = √(k/m), rad/s (eq. 12).
    pub fn omega0_rad_per_s(&self) -> f64 {
        (self.stiffness_n_per_m / self.mass_kg).sqrt()
    }

    /// R = (μs − μc) P / (m ω0 U) (eq. 11), dimensionless.
    pub fn r(&self) -> f64 {
        self.friction_difference * self.normal_force_n
            / (self.mass_kg * self.omega0_rad_per_s() * self.speed_m_per_s)
    }

    /// Every rule of the parameters.
    pub fn check(&self) -> Result<(), ObserverError> {
        let positive = [
            ("normal_force_n", self.normal_force_n),
            ("mass_kg", self.mass_kg),
            ("stiffness_n_per_m", self.stiffness_n_per_m),
            ("speed_m_per_s", self.speed_m_per_s),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(ObserverError::field(
                    field,
                    value,
                    "must be a finite number greater than 0",
                ));
            }
        }
        if !(self.friction_difference.is_finite() && self.friction_difference >= 0.0) {
            return Err(ObserverError::field(
                "friction_difference",
                self.friction_difference,
                "must be a finite number of at least 0 (static friction is not below kinetic)",
            ));
        }
        Ok(())
    }
}

impl Default for StickSlipParams {
    /// Fig. 5's values at μs − μc = 0.1, an arbitrary point of the figure's abscissa (R ≈ 3.5,
    /// f_ss ≈ 66 Hz).
    fn default() -> Self {
        Self::fig5(0.1)
    }
}

/// μs − μc of a surface, eq. 12 of the seed paper: π (s − s′) β / (E σ), with s − s′ the skin's
/// static minus kinetic shear strength (Pa), β the mean radius of the surface's projections
/// (m), E the combined Young's modulus, 1/E = (1 − ν_s²)/E_s + (1 − ν_o²)/E_o (Pa), and σ the
/// topography's standard deviation (m).
///
/// The text prints the denominator as "E_σ"; it is read as E·σ, which is what the paper's
/// own summary says ("a stick-slip frequency determined by Eσ/β"). `None` unless every
/// argument is finite, s − s′ ≥ 0, β ≥ 0 and E, σ > 0.
pub fn friction_difference(
    shear_strength_difference_pa: f64,
    beta_m: f64,
    e_pa: f64,
    sigma_m: f64,
) -> Option<f64> {
    let ok = shear_strength_difference_pa.is_finite()
        && shear_strength_difference_pa >= 0.0
        && beta_m.is_finite()
        && beta_m >= 0.0
        && e_pa.is_finite()
        && e_pa > 0.0
        && sigma_m.is_finite()
        && sigma_m > 0.0;
    ok.then(|| PI * shear_strength_difference_pa * beta_m / (e_pa * sigma_m))
}

/// The stick-slip frequency f_ss of the seed paper's eq. 10, Hz:
///
/// f_ss⁻¹ = (2/ω0)(π − tan⁻¹R + R),  R = (μs − μc)P / (m ω0 U),  ω0 = √(k/m).
///
/// Implemented as printed. What the text leaves open: the figure's plotted values are not in
/// the text (only its trend can be checked: f_ss falls as μs − μc, i.e. β, rises); at R = 0
/// the formula gives ω0/2π, the finger's natural frequency, although with equal static and
/// kinetic friction there would be no stick-slip at all; and "E_σ" in eq. 12 is read as E·σ
/// (see [`friction_difference`]).
pub fn stick_slip_hz(params: &StickSlipParams) -> Result<f64, ObserverError> {
    params.check()?;
    let omega0 = params.omega0_rad_per_s();
    let r = params.r();
    let period_s = (2.0 / omega0) * (PI - r.atan() + r);
    let f = 1.0 / period_s;
    if f.is_finite() && f > 0.0 {
        Ok(f)
    } else {
        Err(ObserverError::field(
            "friction_difference",
            params.friction_difference,
            "must give a finite stick-slip period (R overflowed)",
        ))
    }
}

/// What the simulated participant perceives of a stimulus of burst frequency f_b.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Percept {
    /// r = −ln(f_b / 1 Hz).
    LogFb,
    /// r = −ln(f_ss / 1 Hz), f_ss by [`stick_slip_hz`] for the surface the burst stands for.
    ///
    /// The paper maps f_b onto f_ss ("we can control the stick-slip frequency virtually by
    /// changing the burst frequency") but gives no surface for a given f_b. The mapping here
    /// is a planning hypothesis built from the paper's own remarks: an f_b explored at speed U
    /// reads as projections U/f_b apart (20 Hz at 4 cm/s: 2 mm, the paper's "interval of a few
    /// millimeters" below 30 Hz); the projections' radius β is taken in proportion to that
    /// spacing, and μs − μc in proportion to β (eq. 12). So μs − μc =
    /// `friction_difference_hz` / f_b, and f_ss follows from eq. 10–11 with `finger`'s P, m, k,
    /// U (its own `friction_difference` is not used). f_ss then rises with f_b but saturates
    /// at ω0/2π: the percept compresses high f_b, which LogFb does not.
    StickSlip {
        /// P, m, k and U of the finger (fig. 5's by default).
        #[serde(default)]
        finger: StickSlipParams,
        /// (μs − μc) × f_b, Hz: the friction difference of the surface a 1 Hz burst stands
        /// for. 2 Hz gives μs − μc = 0.1 at 20 Hz and 0.01 at 200 Hz (the default).
        #[serde(default = "default_friction_difference_hz")]
        friction_difference_hz: f64,
    },
}

impl Percept {
    /// The noise-free perceived roughness of a stimulus at `fb_hz`; `None` for an f_b that
    /// is not finite and positive (or a StickSlip percept whose parameters break a rule).
    pub fn roughness(&self, fb_hz: f64) -> Option<f64> {
        if !(fb_hz.is_finite() && fb_hz > 0.0) {
            return None;
        }
        let hz = match *self {
            Percept::LogFb => fb_hz,
            Percept::StickSlip {
                finger,
                friction_difference_hz,
            } => {
                let params = StickSlipParams {
                    friction_difference: friction_difference_hz / fb_hz,
                    ..finger
                };
                stick_slip_hz(&params).ok()?
            }
        };
        let r = -hz.ln();
        r.is_finite().then_some(r)
    }
}

/// The simulated participant's description (a planning file's `[observer]`, say). Every key
/// has a default ([`ObserverSpec::default`]); a key it does not know is refused.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObserverSpec {
    /// SD of the perceived roughness per presentation, in units of ln f_b (≥ 0).
    pub noise: f64,
    /// Lapse rate in [0, 1): in a comparison, the chance that the grade is drawn uniformly
    /// from the scale whatever the stimuli (inattention); in detection, Wichmann & Hill's λ
    /// (ψ → 1 − λ far above threshold).
    pub lapse: f64,
    /// What is perceived.
    pub percept: Percept,
    /// The seed of every draw.
    pub seed: u64,
    /// Detection: the level at which the cumulative normal is ½ (ψ = 0.75 − λ/2), in the
    /// level's units.
    #[serde(default = "default_threshold")]
    pub threshold: f64,
    /// Detection: the cumulative normal's SD in the level's units (> 0); the slope of ψ at
    /// threshold is (½ − λ) φ(0) / spread.
    #[serde(default = "default_spread")]
    pub spread: f64,
    /// Comparison: the width of one grade, in units of `noise` (> 0): the perceived
    /// difference divided by `category_width` × `noise`, rounded, is the grade.
    #[serde(default = "default_category_width")]
    pub category_width: f64,
}

fn default_friction_difference_hz() -> f64 {
    2.0
}

fn default_threshold() -> f64 {
    1.0
}
fn default_spread() -> f64 {
    0.5
}
fn default_category_width() -> f64 {
    1.0
}

impl Default for ObserverSpec {
    fn default() -> Self {
        Self {
            noise: 0.3,
            lapse: 0.0,
            percept: Percept::LogFb,
            seed: 0,
            threshold: default_threshold(),
            spread: default_spread(),
            category_width: default_category_width(),
        }
    }
}

/// A refusal of an observer's spec: one sentence naming the field, the value and the rule.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum ObserverError {
    /// A field breaks its rule.
    Field {
        /// The field.
        field: &'static str,
        /// Its value, as written.
        value: String,
        /// The rule, completing "but it …".
        rule: &'static str,
    },
}

impl ObserverError {
    fn field(field: &'static str, value: impl fmt::Display, rule: &'static str) -> Self {
        ObserverError::Field {
            field,
            value: value.to_string(),
            rule,
        }
    }
}

impl fmt::Display for ObserverError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ObserverError::Field { field, value, rule } => {
                write!(
                    f,
                    "simulated observer: `{field}` is {value}, but it {rule}."
                )
            }
        }
    }
}

impl std::error::Error for ObserverError {}

impl ObserverSpec {
    /// Every rule of the spec; the first one broken is returned.
    pub fn check(&self) -> Result<(), ObserverError> {
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err(ObserverError::field(
                "noise",
                self.noise,
                "must be a finite number of at least 0",
            ));
        }
        if !(self.lapse.is_finite() && (0.0..1.0).contains(&self.lapse)) {
            return Err(ObserverError::field(
                "lapse",
                self.lapse,
                "must lie in [0, 1)",
            ));
        }
        if !self.threshold.is_finite() {
            return Err(ObserverError::field(
                "threshold",
                self.threshold,
                "must be a finite number",
            ));
        }
        if !(self.spread.is_finite() && self.spread > 0.0) {
            return Err(ObserverError::field(
                "spread",
                self.spread,
                "must be a finite number greater than 0",
            ));
        }
        if !(self.category_width.is_finite() && self.category_width > 0.0) {
            return Err(ObserverError::field(
                "category_width",
                self.category_width,
                "must be a finite number greater than 0",
            ));
        }
        if let Percept::StickSlip {
            finger,
            friction_difference_hz,
        } = self.percept
        {
            finger.check()?;
            if !(friction_difference_hz.is_finite() && friction_difference_hz >= 0.0) {
                return Err(ObserverError::field(
                    "friction_difference_hz",
                    friction_difference_hz,
                    "must be a finite number of at least 0",
                ));
            }
        }
        Ok(())
    }

    /// The level where the true ψ = `p` (for tests: a staircase's target level); `None`
    /// unless ½ < p < 1 − λ.
    pub fn level_at_p_correct(&self, p: f64) -> Option<f64> {
        let f = (p - GUESS_2IFC) / (1.0 - GUESS_2IFC - self.lapse);
        if !(f > 0.0 && f < 1.0) {
            return None;
        }
        let z = Normal::standard().inverse_cdf(f);
        let x = self.threshold + self.spread * z;
        x.is_finite().then_some(x)
    }
}

/// A simulated participant: a spec and its random stream.
#[derive(Clone, Debug)]
pub struct Observer {
    spec: ObserverSpec,
    rng: ChaCha8Rng,
}

impl Observer {
    /// A participant. `new` refuses nothing (so that it cannot fail mid-plan); call
    /// [`ObserverSpec::check`] or use [`Observer::try_new`] to refuse a bad spec. Out-of-rule
    /// values are made harmless: noise and lapse are clamped into their ranges (NaN → 0), a
    /// spread or category width that is not positive gives a step function (ties at exactly
    /// the threshold), a threshold that is not finite never reaches ½ (0 → all guesses).
    pub fn new(spec: ObserverSpec) -> Self {
        let clean = |x: f64, lo: f64, hi: f64| if x.is_nan() { lo } else { x.clamp(lo, hi) };
        let spec = ObserverSpec {
            noise: clean(spec.noise, 0.0, f64::MAX),
            lapse: clean(spec.lapse, 0.0, 1.0),
            ..spec
        };
        Self {
            rng: ChaCha8Rng::seed_from_u64(spec.seed),
            spec,
        }
    }

    /// A participant, or the first rule its spec breaks.
    pub fn try_new(spec: ObserverSpec) -> Result<Self, ObserverError> {
        spec.check()?;
        Ok(Self::new(spec))
    }

    /// The spec (after `new`'s clamping).
    pub fn spec(&self) -> &ObserverSpec {
        &self.spec
    }

    fn perceive(&mut self, r: f64) -> f64 {
        let e: f64 = self.rng.sample(StandardNormal);
        r + self.spec.noise * e
    }

    /// A paired comparison graded on a symmetric scale of `grades` steps (odd, e.g. 5 →
    /// −2..=2): positive = the first judged rougher. Each presentation draws its own percept;
    /// the grade is their difference divided by `category_width` × `noise`, rounded (halves
    /// away from zero, symmetric) and clipped to the scale, so equal f_b give a grade whose
    /// expectation is 0. With noise 0 the grade is the sign of the difference at full scale.
    /// With probability `lapse` the grade is drawn uniformly from the scale instead.
    ///
    /// An even `grades` is taken as the odd number below it; 0 or 1 always give 0. A
    /// stimulus without a percept (f_b not finite and positive) gives 0: no difference
    /// judged.
    pub fn compare(&mut self, first_fb_hz: f64, second_fb_hz: f64, grades: u32) -> i32 {
        let half = (grades.saturating_sub(1) / 2).min(i32::MAX as u32) as i32;
        // Draw the same number of values whatever the branch, so that one comparison's
        // outcome does not shift the stream of the next.
        let lapse_draw: f64 = self.rng.random();
        let lapse_grade = if half > 0 {
            self.rng.random_range(-half..=half)
        } else {
            0
        };
        let (r1, r2) = match (
            self.spec.percept.roughness(first_fb_hz),
            self.spec.percept.roughness(second_fb_hz),
        ) {
            (Some(r1), Some(r2)) => (r1, r2),
            _ => return 0,
        };
        let d = self.perceive(r1) - self.perceive(r2);
        if half == 0 {
            return 0;
        }
        if lapse_draw < self.spec.lapse {
            return lapse_grade;
        }
        let width = self.spec.category_width * self.spec.noise;
        let grade = if width > 0.0 && width.is_finite() {
            (d / width).round()
        } else if d > 0.0 {
            f64::from(half)
        } else if d < 0.0 {
            -f64::from(half)
        } else {
            0.0
        };
        grade.clamp(-f64::from(half), f64::from(half)) as i32
    }

    /// A forced choice between two stimuli: whether the first is judged rougher (the
    /// Thurstone case V draw; a lapse answers at random). For scaling by choices rather than
    /// grades.
    pub fn choose_first_rougher(&mut self, first_fb_hz: f64, second_fb_hz: f64) -> bool {
        let lapse_draw: f64 = self.rng.random();
        let coin: bool = self.rng.random();
        let (r1, r2) = match (
            self.spec.percept.roughness(first_fb_hz),
            self.spec.percept.roughness(second_fb_hz),
        ) {
            (Some(r1), Some(r2)) => (r1, r2),
            _ => return coin,
        };
        let d = self.perceive(r1) - self.perceive(r2);
        if lapse_draw < self.spec.lapse || d == 0.0 {
            return coin;
        }
        d > 0.0
    }

    /// A two-interval forced choice at stimulus difference `level`: correct with probability
    /// [`Self::p_correct`].
    pub fn detect(&mut self, level: f64) -> bool {
        let u: f64 = self.rng.random();
        u < self.p_correct(level)
    }

    /// The true psychometric function ψ(level) = ½ + (½ − λ) Φ((level − threshold) / spread).
    /// A level that is NaN is guessed at (½).
    pub fn p_correct(&self, level: f64) -> f64 {
        if level.is_nan() {
            return GUESS_2IFC;
        }
        let s = &self.spec;
        let f = if s.spread > 0.0 && s.spread.is_finite() && s.threshold.is_finite() {
            Normal::standard().cdf((level - s.threshold) / s.spread)
        } else if s.threshold.is_finite() {
            match level.total_cmp(&s.threshold) {
                std::cmp::Ordering::Less => 0.0,
                std::cmp::Ordering::Equal => 0.5,
                std::cmp::Ordering::Greater => 1.0,
            }
        } else {
            0.0
        };
        let f = if f.is_nan() { 0.0 } else { f };
        GUESS_2IFC + (1.0 - GUESS_2IFC - s.lapse) * f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Eq. 10–12 with fig. 5's values, by hand: ω0 = √(500 / 0.001) = 707.107 rad/s; at
    /// μs − μc = 0.1, R = 0.1 · 1 / (0.001 · 707.107 · 0.04) = 3.5355 and
    /// f_ss = 707.107 / (2 (π − tan⁻¹ 3.5355 + 3.5355)) = 65.692 Hz; at R = 0, ω0/2π = 112.540.
    #[test]
    fn stick_slip_by_hand_at_fig5_values() {
        let p = StickSlipParams::fig5(0.1);
        assert!((p.omega0_rad_per_s() - 707.1068).abs() < 1e-3);
        assert!((p.r() - 3.535534).abs() < 1e-6);
        assert!((stick_slip_hz(&p).unwrap() - 65.69215).abs() < 1e-4);
        assert!((stick_slip_hz(&StickSlipParams::fig5(0.0)).unwrap() - 112.53954).abs() < 1e-4);
        assert_eq!(StickSlipParams::default(), p);
    }

    /// The paper: "As Figure 5 shows, f_ss increases when β … decreases" — through eq. 12
    /// (μs − μc ∝ β) and eq. 10–11 (f_ss falls as μs − μc rises). Checked both on fig. 5's
    /// abscissa and from a surface's β, with sandpaper-like projection radii (the paper's
    /// #60…#320: 180, 80, 48, 34 µm) and otherwise arbitrary s − s′, E, σ.
    #[test]
    fn stick_slip_rises_as_beta_falls() {
        let mut last = f64::INFINITY;
        for i in 0..=100 {
            let f = stick_slip_hz(&StickSlipParams::fig5(i as f64 * 0.01)).unwrap();
            assert!(f < last, "f_ss must fall as μs − μc rises: {f} at step {i}");
            last = f;
        }
        let mut last = 0.0;
        for beta_um in [180.0, 80.0, 48.0, 34.0] {
            let mu = friction_difference(2e3, beta_um * 1e-6, 1e5, 10e-6).unwrap();
            let f = stick_slip_hz(&StickSlipParams::fig5(mu)).unwrap();
            assert!(
                f > last,
                "f_ss must rise as β falls: {f} Hz at β = {beta_um} µm"
            );
            last = f;
        }
        // Large R: the period tends to 2R/ω0, so f_ss → ω0/(2R).
        let p = StickSlipParams::fig5(100.0);
        let f = stick_slip_hz(&p).unwrap();
        assert!((f * 2.0 * p.r() / p.omega0_rad_per_s() - 1.0).abs() < 1e-3);
    }

    #[test]
    fn stick_slip_refuses_what_has_no_meaning() {
        let e = stick_slip_hz(&StickSlipParams {
            mass_kg: 0.0,
            ..StickSlipParams::default()
        })
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "simulated observer: `mass_kg` is 0, but it must be a finite number greater than 0."
        );
        assert!(stick_slip_hz(&StickSlipParams::fig5(-0.1)).is_err());
        assert!(stick_slip_hz(&StickSlipParams::fig5(f64::NAN)).is_err());
        assert_eq!(friction_difference(1.0, 1.0, 0.0, 1.0), None);
        assert_eq!(friction_difference(-1.0, 1.0, 1.0, 1.0), None);
    }

    #[test]
    fn percepts_order_rougher_as_lower_fb() {
        let log = Percept::LogFb;
        assert_eq!(log.roughness(1.0), Some(0.0));
        assert!((log.roughness(20.0).unwrap() + 20f64.ln()).abs() < 1e-15);
        assert_eq!(log.roughness(0.0), None);
        assert_eq!(log.roughness(f64::NAN), None);
        let ss = Percept::StickSlip {
            finger: StickSlipParams::default(),
            friction_difference_hz: 2.0,
        };
        // 20 Hz → μs − μc = 0.1 → f_ss = 65.692 Hz (the hand value above).
        assert!((ss.roughness(20.0).unwrap() + 65.69215f64.ln()).abs() < 1e-5);
        let fbs = [20.0, 40.0, 80.0, 200.0, 1000.0];
        for w in fbs.windows(2) {
            assert!(ss.roughness(w[0]).unwrap() > ss.roughness(w[1]).unwrap());
        }
        // Compressed at high f_b: 200 → 1000 Hz is a fifth of LogFb's step.
        let d_ss = ss.roughness(200.0).unwrap() - ss.roughness(1000.0).unwrap();
        let d_log = log.roughness(200.0).unwrap() - log.roughness(1000.0).unwrap();
        assert!(d_ss < 0.2 * d_log, "{d_ss} vs {d_log}");
    }

    fn spec(noise: f64, lapse: f64, seed: u64) -> ObserverSpec {
        ObserverSpec {
            noise,
            lapse,
            seed,
            ..ObserverSpec::default()
        }
    }

    #[test]
    fn equal_stimuli_grade_zero_on_average_and_grades_stay_on_the_scale() {
        let mut o = Observer::new(spec(0.4, 0.05, 1));
        let n = 40_000;
        let mut sum = 0i64;
        for _ in 0..n {
            let g = o.compare(40.0, 40.0, 5);
            assert!((-2..=2).contains(&g));
            sum += i64::from(g);
        }
        // Grade SD ≤ 2: the mean of 40 000 is within 0.05 with room.
        assert!(
            (sum as f64 / n as f64).abs() < 0.05,
            "mean grade {}",
            sum as f64 / n as f64
        );
        // Rougher first (lower f_b) → positive grades.
        let mean: f64 = (0..2000)
            .map(|_| f64::from(o.compare(20.0, 200.0, 5)))
            .sum::<f64>()
            / 2000.0;
        assert!(mean > 1.5, "{mean}");
        assert_eq!(o.compare(20.0, 200.0, 1), 0);
        assert_eq!(o.compare(20.0, 200.0, 0), 0);
        assert!((-1..=1).contains(&o.compare(20.0, 200.0, 4)));
        assert_eq!(o.compare(-1.0, 200.0, 5), 0);
        // Noise 0: the sign at full scale.
        let mut exact = Observer::new(spec(0.0, 0.0, 1));
        assert_eq!(exact.compare(20.0, 40.0, 7), 3);
        assert_eq!(exact.compare(40.0, 20.0, 7), -3);
        assert_eq!(exact.compare(40.0, 40.0, 7), 0);
    }

    /// The Thurstone case V draw: P(first rougher) = Φ(Δr / (noise √2)).
    #[test]
    fn forced_choices_follow_case_v() {
        let noise = 0.5;
        let mut o = Observer::new(spec(noise, 0.0, 3));
        for (a, b) in [(40.0, 50.0), (40.0, 80.0), (100.0, 80.0)] {
            let n = 20_000;
            let k = (0..n).filter(|_| o.choose_first_rougher(a, b)).count();
            let dr: f64 = b.ln() - a.ln();
            let want = Normal::standard().cdf(dr / (noise * 2f64.sqrt()));
            let got = k as f64 / n as f64;
            assert!(
                (got - want).abs() < 4.0 * (want * (1.0 - want) / n as f64).sqrt() + 1e-3,
                "{a} vs {b}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn detection_follows_its_psychometric_function() {
        let s = ObserverSpec {
            threshold: 10.0,
            spread: 4.0,
            ..spec(0.0, 0.04, 11)
        };
        let mut o = Observer::new(s);
        assert!((o.p_correct(10.0) - (0.75 - 0.02)).abs() < 1e-12);
        assert!((o.p_correct(1e9) - 0.96).abs() < 1e-12);
        assert!((o.p_correct(-1e9) - 0.5).abs() < 1e-12);
        assert_eq!(o.p_correct(f64::NAN), 0.5);
        for p in [0.6, std::f64::consts::FRAC_1_SQRT_2, 0.9] {
            let x = s.level_at_p_correct(p).unwrap();
            assert!((o.p_correct(x) - p).abs() < 1e-9);
        }
        assert_eq!(s.level_at_p_correct(0.97), None);
        assert_eq!(s.level_at_p_correct(0.5), None);
        for level in [4.0, 10.0, 16.0] {
            let n = 20_000;
            let k = (0..n).filter(|_| o.detect(level)).count();
            let (got, want) = (k as f64 / n as f64, o.p_correct(level));
            assert!(
                (got - want).abs() < 4.0 * (want * (1.0 - want) / n as f64).sqrt(),
                "{level}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn same_seed_same_participant() {
        let run = |seed| {
            let mut o = Observer::new(spec(0.3, 0.1, seed));
            (0..200)
                .map(|i| o.compare(20.0 + i as f64, 40.0, 5))
                .collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }

    #[test]
    fn specs_deserialize_with_defaults_and_refuse_bad_values() {
        let s: ObserverSpec = serde_json::from_str(
            r#"{"noise": 0.2, "lapse": 0.01, "percept": {"kind": "log_fb"}, "seed": 4}"#,
        )
        .unwrap();
        assert_eq!((s.threshold, s.spread, s.category_width), (1.0, 0.5, 1.0));
        let s: ObserverSpec = serde_json::from_str(
            r#"{"noise": 0.2, "lapse": 0.0, "seed": 4, "percept": {"kind": "stick_slip", "friction_difference_hz": 2.0,
                "finger": {"normal_force_n": 1.0, "mass_kg": 0.001, "stiffness_n_per_m": 500.0, "speed_m_per_s": 0.04, "friction_difference": 0.0}}}"#,
        )
        .unwrap();
        assert!(s.check().is_ok());
        for (bad, field) in [
            (ObserverSpec { noise: -1.0, ..s }, "`noise` is -1"),
            (ObserverSpec { lapse: 1.0, ..s }, "`lapse` is 1"),
            (ObserverSpec { spread: 0.0, ..s }, "`spread` is 0"),
            (
                ObserverSpec {
                    threshold: f64::INFINITY,
                    ..s
                },
                "`threshold` is inf",
            ),
            (
                ObserverSpec {
                    category_width: f64::NAN,
                    ..s
                },
                "`category_width` is NaN",
            ),
        ] {
            let text = Observer::try_new(bad).unwrap_err().to_string();
            assert!(text.contains(field) && text.ends_with('.'), "{text}");
            // `new` takes it anyway, and nothing panics.
            let mut o = Observer::new(bad);
            let _ = (
                o.compare(20.0, 40.0, 5),
                o.detect(1.0),
                o.choose_first_rougher(20.0, 40.0),
            );
        }
    }
}
