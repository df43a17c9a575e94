//! Grating renderers compared: where do the bursts land relative to the ridges of a virtual
//! grating, how long are they, and what happens at rest and under fast motion?
//!
//! Ridges sit at every multiple of λ = 1 mm. The placement error of a burst is the true finger
//! position at its rising edge minus the nearest ridge, signed along the motion (positive: late).
//! - **position phase** and **velocity synthesis** are the core's two renderers
//!   (`saw_core::texture::GratingRender`), run through the whole closed loop (`sim::run`:
//!   NUCLEO-F446RE, rheostat/ADC model, the default estimator, the gate and the preload timer
//!   model); the bursts are the recorded gate waveform's pulses (`metrics::ridge_hits`).
//! - **hybrid** (`GratingRender::Hybrid`) is position phase with each crossing predicted inside
//!   the sample period from a 64-sample line fit and the burst started there by a delayed
//!   one-pulse; position phase where the line is not trusted. It replaced the host model of
//!   earlier rounds (a 16-sample line, 4–5 µm RMS).
//!
//! [`placement_sweep`] runs all three over λ = 0.1–4 mm and 20–200 mm/s for the chart of worst
//! placement against λ, with the physical floor ([`floor`]).

use saw_boards::NUCLEO_F446RE;
use saw_core::texture::{Grating, GratingRender, Texture};

use super::methods::Dyn;

use super::scenario::{self, constant};
use crate::metrics;
use crate::sim::{self, SimParams};
use crate::trajectory::Trajectory;

/// Ridge period, µm.
pub const RIDGE_UM: f64 = 1_000.0;
/// Speeds of the comparison, mm/s.
pub const SPEEDS_MM_S: [f64; 4] = [20.0, 50.0, 100.0, 200.0];

/// One renderer on one motion.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderStats {
    /// Renderer.
    pub renderer: &'static str,
    /// The motion: a speed in mm/s, "mixed" or "rest".
    pub case: String,
    /// Ridges the finger crossed.
    pub ridges: u64,
    /// Bursts emitted.
    pub bursts: usize,
    /// Ridge crossings the core counted as skipped (position phase), if known.
    pub skipped: Option<u32>,
    /// Mean signed placement error, µm.
    pub mean_err_um: f64,
    /// RMS placement error, µm.
    pub rms_err_um: f64,
    /// Largest |placement error|, µm.
    pub worst_err_um: f64,
    /// RMS on-time error against duty·λ/|V| (true speed), %, when the renderer sets on-times.
    pub on_rms_pct: Option<f64>,
}

fn stats(
    renderer: &'static str,
    case: String,
    ridges: u64,
    errs: &[f64],
    on_errs_pct: &[f64],
    skipped: Option<u32>,
) -> RenderStats {
    let n = errs.len().max(1) as f64;
    let rms = |v: &[f64]| (v.iter().map(|e| e * e).sum::<f64>() / v.len().max(1) as f64).sqrt();
    RenderStats {
        renderer,
        case,
        ridges,
        bursts: errs.len(),
        skipped,
        mean_err_um: errs.iter().sum::<f64>() / n,
        rms_err_um: rms(errs),
        worst_err_um: errs.iter().map(|e| e.abs()).fold(0.0, f64::max),
        on_rms_pct: (!on_errs_pct.is_empty()).then(|| rms(on_errs_pct)),
    }
}

/// A one-region scene: a λ = 1 mm grating rendered by `render`.
pub fn grating_config(render: GratingRender) -> saw_core::Config {
    grating_config_at(render, RIDGE_UM as u32)
}

/// A one-region scene: a grating of period `wavelength_um` rendered by `render`.
pub fn grating_config_at(render: GratingRender, wavelength_um: u32) -> saw_core::Config {
    let mut cfg = saw_core::default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    let g = Grating {
        render,
        ..Grating::new(wavelength_um)
    };
    let _ = cfg.scene.textures.push(Texture::Grating(g));
    cfg
}

/// Runs the core's renderer `render` over `trajectory` and scores its bursts; `estimator` in the
/// controller if given, the default one otherwise.
pub fn core_run(
    render: GratingRender,
    case: String,
    trajectory: Trajectory,
    duration_s: f64,
    noise_lsb: f64,
    seed: u64,
    estimator: Option<Dyn>,
) -> RenderStats {
    let p = SimParams::new(&NUCLEO_F446RE, trajectory, duration_s)
        .with_config(grating_config(render))
        .with_noise(noise_lsb, seed)
        // docs/renderers.md's figures were measured on this stream.
        .with_reference_noise();
    let r = match estimator {
        Some(e) => sim::run_with(&p, e),
        None => sim::run(&p),
    }
    .expect("the grating scene loads");
    let hits = metrics::ridge_hits(&r, RIDGE_UM);
    let errs: Vec<f64> = hits.iter().map(|h| h.error_um).collect();
    // On-time against duty·λ/|V| where that is inside the caps (above 8 mm/s for 0.4 mm of
    // ridge and a 50 ms cap), and the pulse was not cut by a later Off.
    let limits = &p.config.limits;
    let duty = match p.config.scene.textures[0] {
        Texture::Grating(g) => g.duty_permille as f64 / 1000.0,
        _ => unreachable!("grating_config makes one grating region"),
    };
    let on_errs: Vec<f64> = hits
        .iter()
        .filter_map(|h| {
            let ideal_s = duty * RIDGE_UM / h.speed_um_s;
            (h.speed_um_s > 0.0 && ideal_s * 1e6 < limits.max_on_time_us as f64)
                .then(|| 100.0 * (h.on_s - ideal_s) / ideal_s)
        })
        .collect();
    let name = renderer_name(render);
    let skipped =
        (render != GratingRender::VelocitySynthesis).then_some(r.telemetry.ridges_skipped);
    stats(
        name,
        case,
        metrics::ridges_crossed(&r, RIDGE_UM),
        &errs,
        &on_errs,
        skipped,
    )
}

/// The renderer's name in tables and charts.
pub fn renderer_name(render: GratingRender) -> &'static str {
    match render {
        GratingRender::PositionPhase => "position phase",
        GratingRender::VelocitySynthesis => "velocity synthesis",
        GratingRender::Hybrid => "hybrid",
    }
}

/// Every renderer on every motion: constant 20–200 mm/s (40 ridges each), the bench's mixed
/// motion (reversals, up to 10 m/s²) and 10 s at rest on a ridge with 3 LSB of noise.
pub fn run(seed: u64) -> Vec<RenderStats> {
    let mut out = Vec::new();
    let renders = [
        GratingRender::PositionPhase,
        GratingRender::VelocitySynthesis,
        GratingRender::Hybrid,
    ];
    for (k, &mm_s) in SPEEDS_MM_S.iter().enumerate() {
        let v = mm_s * 1_000.0;
        let (traj, _) = constant(v);
        let duration = 40_000.0 / v;
        let s = seed.wrapping_add(900 + k as u64);
        for render in renders {
            out.push(core_run(
                render,
                format!("{mm_s}"),
                traj.clone(),
                duration,
                2.0,
                s,
                None,
            ));
        }
    }
    let (mixed, d) = scenario::mixed();
    for render in renders {
        out.push(core_run(
            render,
            "mixed".into(),
            mixed.clone(),
            d,
            2.0,
            seed,
            None,
        ));
    }
    for render in renders {
        let rest = Trajectory::Rest { at_um: 30_000.0 };
        out.push(core_run(
            render,
            "rest 10 s, 3 LSB".into(),
            rest,
            10.0,
            3.0,
            seed,
            None,
        ));
    }
    out
}

/// Wavelengths of the placement sweep, µm: 0.1–4 mm (table 1 of the SAW paper's grits to a
/// coarse grating).
pub const SWEEP_WAVELENGTHS_UM: [u32; 6] = [100, 200, 500, 1_000, 2_000, 4_000];

/// Bursts this soon after a turn are scored apart: the hybrid's 64-sample line (6.4 ms at
/// 10 kHz) refills there.
pub const SETTLE_S: f64 = 0.0067;

/// One renderer at one λ and speed, over several noise seeds.
#[derive(Clone, Debug, PartialEq)]
pub struct Placement {
    pub renderer: &'static str,
    pub wavelength_um: u32,
    pub speed_mm_s: f64,
    /// Worst |placement error| over the seeds, µm, on the steady stroke (more than
    /// [`SETTLE_S`] after a turn).
    pub worst_um: f64,
    /// Worst |placement error| within [`SETTLE_S`] of a turn, µm (the hybrid's line refills
    /// there, and it is position phase).
    pub worst_turn_um: f64,
    /// RMS placement error over the seeds, µm.
    pub rms_um: f64,
    pub bursts: usize,
    pub ridges: u64,
    /// Ridge crossings the core counted without a pulse.
    pub skipped: u32,
}

/// Every renderer over [`SWEEP_WAVELENGTHS_UM`] × [`SPEEDS_MM_S`]: a stroke there and back
/// (24 mm each way, turning half a period from the ridges), 2 LSB, `seeds` noise seeds each.
pub fn placement_sweep(seed: u64, seeds: u64) -> Vec<Placement> {
    let mut out = Vec::new();
    for render in [
        GratingRender::PositionPhase,
        GratingRender::VelocitySynthesis,
        GratingRender::Hybrid,
    ] {
        for &wavelength_um in &SWEEP_WAVELENGTHS_UM {
            for &mm_s in &SPEEDS_MM_S {
                let v = mm_s * 1_000.0;
                let half = wavelength_um as f64 / 2.0;
                let traj = Trajectory::Triangle {
                    a_um: 8_000.0 + half,
                    b_um: 32_000.0 + half,
                    speed_um_s: v,
                };
                let leg_s = 24_000.0 / v;
                let (mut errs, mut turn_worst, mut bursts, mut ridges, mut skipped) =
                    (Vec::new(), 0.0f64, 0, 0, 0);
                for k in 0..seeds {
                    let p = SimParams::new(&NUCLEO_F446RE, traj.clone(), 2.0 * 24_000.0 / v)
                        .with_config(grating_config_at(render, wavelength_um))
                        .with_noise(2.0, seed.wrapping_add(k));
                    let r = sim::run(&p).expect("the grating scene loads");
                    let hits = metrics::ridge_hits(&r, wavelength_um as f64);
                    bursts += hits.len();
                    ridges += metrics::ridges_crossed(&r, wavelength_um as f64);
                    skipped += r.telemetry.ridges_skipped;
                    for h in &hits {
                        if h.t_s % leg_s < SETTLE_S {
                            turn_worst = turn_worst.max(h.error_um.abs());
                        } else {
                            errs.push(h.error_um);
                        }
                    }
                }
                let n = errs.len().max(1) as f64;
                out.push(Placement {
                    renderer: renderer_name(render),
                    wavelength_um,
                    speed_mm_s: mm_s,
                    worst_um: errs.iter().map(|e| e.abs()).fold(0.0, f64::max),
                    worst_turn_um: turn_worst,
                    rms_um: (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
                    bursts,
                    ridges,
                    skipped,
                });
            }
        }
    }
    out
}

/// The physical floor of burst placement on the F446 at 2 LSB, µm, none of which a renderer can
/// beat: (σ of one sample's position, 3 σ of the hybrid's fitted position — the line's end
/// has √((4N − 2)/(N(N + 1))) = 0.25 of one sample's noise at N = 64 — and one timer tick of
/// travel at 200 mm/s). The sample σ is measured on the ADC model (20 000 samples at
/// mid-travel, `seed`), not taken from the renderer's results.
pub fn floor(seed: u64) -> (f64, f64, f64) {
    use crate::adc::{AdcModel, AdcParams};
    let cal = saw_core::default_config().calibration;
    let mapper = saw_core::position::PositionMapper::new(cal).expect("default calibration");
    let mut adc = AdcModel::new(cal, AdcParams::default().with_noise(2.0, seed))
        .expect("default ADC parameters");
    let at_um = 30_000.0 + 0.37 * 16.0; // off the code grid, as a moving finger is
    let xs: Vec<f64> = (0..20_000u64)
        .filter_map(|k| adc.sample(at_um, k * 100))
        .filter_map(|s| mapper.position_um(&s).ok())
        .map(|p| p as f64)
        .collect();
    let mean = xs.iter().sum::<f64>() / xs.len() as f64;
    let sigma = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64).sqrt();
    let n = saw_core::texture::predict::FIT_SAMPLES as f64;
    let fitted = 3.0 * sigma * ((4.0 * n - 2.0) / (n * (n + 1.0))).sqrt();
    let tick_um = 200_000.0 / NUCLEO_F446RE.burst_timer_clk_hz as f64;
    (sigma, fitted, tick_um)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor's sample σ against the hand-worked figure: 2 LSB per conversion, 16 summed,
    /// is 0.5 LSB per sample; one 12-bit LSB is length / (0.96 · 4096) = 63 mm / 3 932 ≈ 16.0 µm
    /// with the default calibration's 2–98 % span, so σ ≈ 8.0 µm (plus the mapping's own
    /// rounding, 1/√12 µm), and the fitted position's 3 σ is 3 × 0.247 × 8.0 ≈ 5.9 µm.
    #[test]
    fn the_floor_is_the_sample_noise_through_the_fit() {
        let (sigma, fitted, tick) = floor(5);
        assert!((sigma - 8.0).abs() < 0.4, "{sigma}");
        assert!((fitted - 5.9).abs() < 0.3, "{fitted}");
        assert!(tick < 0.01, "{tick}");
    }
}
