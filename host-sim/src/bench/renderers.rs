//! Grating renderers compared (host-side models): where do the bursts land relative to the
//! ridges of a virtual grating?
//!
//! The finger moves at a constant speed over ridges every λ = 1 mm; samples are the seeded ADC
//! model at 2 LSB, 10 kHz. Each renderer emits bursts at times t_b; the placement error of a
//! burst is x_true(t_b) − (the ridge it belongs to), signed along the motion, in µm.
//! - **velocity synthesis** (what the core does): a phase integrates |V̂|/λ (V̂ from
//!   `Median3<LsqSlope<32>>`), a burst at each wrap. Its phase is started from the first measured
//!   position (the fairest start); after that it never looks at position again, so velocity error
//!   and lag accumulate as placement error.
//! - **position phase**: a burst on the sample where the measured position passes a ridge; the
//!   same ridge cannot fire again until the position has left it by the hysteresis h = 40 µm (5 σ
//!   of the position noise), so noise at a ridge gives one burst, a real reversal gives another.
//! - **hybrid**: position phase on a smoothed position (least-squares line over the last 16
//!   samples, evaluated at the newest), with the burst scheduled inside the sample period at the
//!   crossing time the line predicts, same hysteresis.

use saw_core::velocity::{LsqSlope, Median3, VelocityEstimator};

use super::scenario::{constant, Input, Spec};

/// Ridge period, µm.
pub const RIDGE_UM: f64 = 1_000.0;
/// Position-phase hysteresis, µm.
pub const HYSTERESIS_UM: f64 = 40.0;
/// Speeds of the comparison, mm/s.
pub const SPEEDS_MM_S: [f64; 4] = [20.0, 50.0, 100.0, 200.0];

/// One renderer at one speed.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderStats {
    /// Renderer.
    pub renderer: &'static str,
    /// Speed, mm/s.
    pub speed_mm_s: f64,
    /// Ridges the finger crossed.
    pub ridges: usize,
    /// Bursts emitted.
    pub bursts: usize,
    /// Mean signed placement error, µm.
    pub mean_err_um: f64,
    /// RMS placement error, µm.
    pub rms_err_um: f64,
    /// Largest |placement error|, µm.
    pub worst_err_um: f64,
}

fn stats(renderer: &'static str, v: f64, ridges: usize, errs: &[f64]) -> RenderStats {
    let n = errs.len().max(1) as f64;
    RenderStats {
        renderer,
        speed_mm_s: v / 1_000.0,
        ridges,
        bursts: errs.len(),
        mean_err_um: errs.iter().sum::<f64>() / n,
        rms_err_um: (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
        worst_err_um: errs.iter().map(|e| e.abs()).fold(0.0, f64::max),
    }
}

/// Signed distance from the nearest ridge, µm, along +x.
fn to_nearest_ridge(x: f64) -> f64 {
    x - (x / RIDGE_UM).round() * RIDGE_UM
}

/// Runs the three renderers at every speed of [`SPEEDS_MM_S`].
pub fn run(seed: u64) -> Vec<RenderStats> {
    let mut out = Vec::new();
    for (k, &mm_s) in SPEEDS_MM_S.iter().enumerate() {
        let v = mm_s * 1_000.0;
        let (traj, _) = constant(v);
        let duration = 40_000.0 / v;
        let mut spec = Spec::new(traj.clone(), duration, 2.0, 10_000);
        spec.seed = seed.wrapping_add(900 + k as u64);
        let stream = spec.generate();
        let period = spec.period_us();
        let dt = period as f64 * 1e-6;
        let x_true = |t_s: f64| traj.state(t_s).position_um;
        let x_start = x_true(0.0);
        let x_end = x_true(duration);
        let ridges = ((x_end / RIDGE_UM).floor() - (x_start / RIDGE_UM).floor()) as usize;

        // Velocity synthesis.
        let mut est = Median3::new(LsqSlope::<32>::new(period).unwrap(), period);
        let mut phase: Option<f64> = None;
        let mut errs = Vec::new();
        // Position phase and hybrid.
        let (mut last_pos, mut fired_pos): (Option<f64>, Option<f64>) = (None, None);
        let mut errs_pos = Vec::new();
        let mut ring: Vec<f64> = Vec::new();
        let (mut last_hyb, mut fired_hyb): (Option<f64>, Option<f64>) = (None, None);
        let mut errs_hyb = Vec::new();
        for o in &stream {
            let Input::Position(x) = o.input else {
                continue;
            };
            let t_s = o.t_us as f64 * 1e-6;
            let xf = x as f64;
            // Velocity synthesis.
            let vhat = est.update(x, o.t_us);
            if phase.is_none() {
                phase = Some((xf / RIDGE_UM).fract());
            }
            if let (Some(p), Some(vh)) = (phase.as_mut(), vhat) {
                *p += (vh as f64).abs() * dt / RIDGE_UM;
                if *p >= 1.0 {
                    *p -= 1.0;
                    errs.push(to_nearest_ridge(x_true(t_s)));
                }
            }
            // Position phase on the raw position.
            if let Some(prev) = last_pos {
                let r = (xf / RIDGE_UM).floor() * RIDGE_UM;
                let crossed = prev < r && xf >= r;
                let armed = fired_pos.is_none_or(|f: f64| f != r);
                if crossed && armed {
                    errs_pos.push(x_true(t_s) - r);
                    fired_pos = Some(r);
                }
            }
            if let Some(f) = fired_pos {
                if (xf - f).abs() > HYSTERESIS_UM {
                    fired_pos = None;
                }
            }
            last_pos = Some(xf);
            // Hybrid: LSQ line over the last 16 samples, scheduled within the period.
            ring.push(xf);
            if ring.len() > 16 {
                ring.remove(0);
            }
            if ring.len() == 16 {
                let n = 16.0;
                let mean = ring.iter().sum::<f64>() / n;
                let slope = ring
                    .iter()
                    .enumerate()
                    .map(|(i, y)| (i as f64 - 7.5) * (y - mean))
                    .sum::<f64>()
                    / (n * (n * n - 1.0) / 12.0); // µm per sample
                let now = mean + slope * 7.5;
                let next = now + slope; // where the line says the finger is one period later
                let r = (next / RIDGE_UM).floor() * RIDGE_UM;
                let armed = fired_hyb.is_none_or(|f: f64| f != r);
                // The line's look-ahead passed a ridge since the previous sample.
                let crossed = last_hyb.is_some_and(|prev: f64| prev < r && next >= r);
                if crossed && armed && slope > 0.0 {
                    // Fire at the predicted crossing time inside the coming period (now, if the
                    // line says it is already past).
                    let t_b = t_s + ((r - now) / slope).clamp(0.0, 1.0) * dt;
                    errs_hyb.push(x_true(t_b) - r);
                    fired_hyb = Some(r);
                }
                if let Some(f) = fired_hyb {
                    if (now - f).abs() > HYSTERESIS_UM {
                        fired_hyb = None;
                    }
                }
                last_hyb = Some(next);
            }
        }
        out.push(stats("velocity synthesis", v, ridges, &errs));
        out.push(stats("position phase", v, ridges, &errs_pos));
        out.push(stats("hybrid", v, ridges, &errs_hyb));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_phase_places_bursts_within_a_sample_and_noise() {
        let r = run(11);
        for s in r.iter().filter(|s| s.renderer == "hybrid") {
            assert!(
                s.bursts + 1 >= s.ridges && s.bursts <= s.ridges + 1,
                "{s:?}"
            );
            assert!(s.rms_err_um < 15.0, "{s:?}");
        }
        for s in r.iter().filter(|s| s.renderer == "position phase") {
            // One burst per ridge (the stroke starts and ends on a ridge, each of which may or may
            // not fire): hysteresis holds noise to one burst per crossing.
            assert!(s.bursts.abs_diff(s.ridges) <= 1, "{s:?}");
            // Late by at most one sample of travel plus a few σ of noise.
            let travel = s.speed_mm_s * 1_000.0 * 1e-4;
            assert!(s.worst_err_um <= travel + 40.0, "{s:?}");
        }
    }
}
