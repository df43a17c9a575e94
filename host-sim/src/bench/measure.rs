//! Replays a stream through an estimator and measures it.

use super::methods::Method;
use super::scenario::{Input, Obs};

/// Error figures of one method on one stream.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Errors {
    /// RMS of (estimate − truth) over scored slots with an estimate, µm/s.
    pub rms_um_s: f64,
    /// Largest |estimate − truth| over the same slots, µm/s.
    pub worst_um_s: f64,
    /// Mean of (truth − estimate) / acceleration over scored slots, µs (the lag under
    /// acceleration; meaningful on the delay probe only).
    pub lag_us: f64,
    /// Scored slots with an estimate.
    pub n: usize,
    /// Scored slots without one (warm-up after a reset, `None`).
    pub missing: usize,
    /// Largest |estimate| seen anywhere, µm/s (boundedness).
    pub max_abs_um_s: f64,
}

/// Runs `method` over `stream` (sample period `period_us`), the controller's way: a fault resets
/// the estimator, a dropped slot feeds nothing.
pub fn replay(method: &Method, stream: &[Obs], period_us: u32) -> Vec<Option<i32>> {
    let mut e = (method.build)(period_us);
    stream
        .iter()
        .map(|o| match o.input {
            Input::Position(x) => e.update(x, o.t_us),
            Input::Fault => {
                e.reset();
                None
            }
            Input::Dropped => None,
        })
        .collect()
}

/// Error figures of `out` against the stream's truth.
pub fn errors(stream: &[Obs], out: &[Option<i32>]) -> Errors {
    let mut r = Errors::default();
    let (mut sq, mut lag) = (0.0, 0.0);
    for (o, v) in stream.iter().zip(out) {
        if let Some(v) = v {
            r.max_abs_um_s = r.max_abs_um_s.max((*v as f64).abs());
        }
        if !o.scored || o.input == Input::Dropped {
            continue;
        }
        match v {
            Some(v) => {
                let e = *v as f64 - o.v_true;
                sq += e * e;
                r.worst_um_s = r.worst_um_s.max(e.abs());
                if o.a_true != 0.0 {
                    lag += -e / o.a_true * 1e6;
                }
                r.n += 1;
            }
            None => r.missing += 1,
        }
    }
    if r.n > 0 {
        r.rms_um_s = (sq / r.n as f64).sqrt();
        r.lag_us = lag / r.n as f64;
    }
    r
}

/// Pools several runs' figures (RMS over all slots, worst of all, mean lag weighted by slots).
pub fn pool(parts: &[Errors]) -> Errors {
    let n: usize = parts.iter().map(|p| p.n).sum();
    let mut r = Errors {
        n,
        missing: parts.iter().map(|p| p.missing).sum(),
        ..Errors::default()
    };
    if n == 0 {
        return r;
    }
    r.rms_um_s = (parts
        .iter()
        .map(|p| p.rms_um_s * p.rms_um_s * p.n as f64)
        .sum::<f64>()
        / n as f64)
        .sqrt();
    r.lag_us = parts.iter().map(|p| p.lag_us * p.n as f64).sum::<f64>() / n as f64;
    r.worst_um_s = parts.iter().map(|p| p.worst_um_s).fold(0.0, f64::max);
    r.max_abs_um_s = parts.iter().map(|p| p.max_abs_um_s).fold(0.0, f64::max);
    r
}

/// Spurious bursts of a grating of period `lambda_um` rendered by velocity synthesis from `out`
/// (sample period `period_us`): the phase integrates |V|/λ and a burst fires at every wrap.
/// Returns (raw count, count with the core grating's start threshold): the second only
/// integrates once |V| has exceeded `start_um_s` and until it drops below half of it, and counts
/// one burst at each switch-on (the burst timer starts every period with its on-time).
pub fn bursts(out: &[Option<i32>], period_us: u32, lambda_um: f64, start_um_s: f64) -> (u64, u64) {
    let dt = period_us as f64 * 1e-6;
    let (mut raw_phase, mut raw) = (0.0f64, 0u64);
    let (mut on, mut phase, mut gated) = (false, 0.0f64, 0u64);
    for v in out {
        let s = v.map_or(0.0, |v| (v as f64).abs());
        raw_phase += s * dt / lambda_um;
        if raw_phase >= 1.0 {
            raw += raw_phase.floor() as u64;
            raw_phase = raw_phase.fract();
        }
        if !on && s > start_um_s {
            on = true;
            phase = 0.0;
            gated += 1;
        } else if on && s < start_um_s / 2.0 {
            on = false;
        }
        if on {
            phase += s * dt / lambda_um;
            if phase >= 1.0 {
                gated += phase.floor() as u64;
                phase = phase.fract();
            }
        }
    }
    (raw, gated)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bursts_count_wraps_and_switch_ons() {
        // 10 mm/s for 1.05 s at 10 kHz over λ = 1 mm: 10 wraps; gated also counts the switch-on.
        let out = vec![Some(10_000); 10_500];
        let (raw, gated) = bursts(&out, 100, 1_000.0, 5_000.0);
        assert_eq!(raw, 10);
        assert_eq!(gated, 11);
        // 3 mm/s never switches the gated one on.
        let out = vec![Some(3_000); 10_500];
        assert_eq!(bursts(&out, 100, 1_000.0, 5_000.0), (3, 0));
    }

    #[test]
    fn pooled_rms() {
        let a = Errors {
            rms_um_s: 3.0,
            n: 10,
            ..Errors::default()
        };
        let b = Errors {
            rms_um_s: 4.0,
            n: 10,
            ..Errors::default()
        };
        assert!((pool(&[a, b]).rms_um_s - 12.5f64.sqrt()).abs() < 1e-12);
    }
}
