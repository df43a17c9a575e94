//! Figures of merit of a run: commanded vs produced f_b per region (from the gate edges), region
//! switches against the scene's boundaries, velocity error and delay, faults, pulse integrity.

use saw_core::burst::TimerSettings;
use saw_core::gate::GateAction;

use saw_core::texture::Texture;

use crate::sim::SimResult;

/// The f_b a texture asks for with the finger at `true_vel_um_s`, Hz, by the models the core
/// uses: f = |V|/λ for a grating (one pulse per ridge crossed, or periodic bursts at that rate),
/// the stick-slip frequency for a material. None for `off`, a
/// constant texture (it has a commanded f_b) and a finger at rest. For random draws it is the
/// rate the draws give (a harmonic mean), which is what the gate's period count measures.
pub fn expected_hz(texture: &Texture, true_vel_um_s: f64) -> Option<f64> {
    let speed_um_s = true_vel_um_s.abs();
    match texture {
        Texture::Grating(g) if speed_um_s > 0.0 => Some(speed_um_s / g.wavelength_um as f64),
        Texture::Material(m) if speed_um_s > 0.0 => {
            Some(m.stick_slip_hz((speed_um_s * 1e-6) as f32) as f64)
        }
        Texture::Random(r) => {
            // f uniform on c(1 ± s): the rate of bursts is 1/E[1/f] = c·2s / ln((1 + s)/(1 − s)).
            let c = r.center_millihz as f64 / 1000.0;
            let spread = r.spread_permille as f64 / 1000.0;
            Some(if spread > 0.0 {
                c * 2.0 * spread / ((1.0 + spread) / (1.0 - spread)).ln()
            } else {
                c
            })
        }
        _ => None,
    }
}

/// Burst figures of one region.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionStats {
    /// Region index.
    pub region: u8,
    /// f_b the scene asks for, Hz (None for an off or motion-dependent texture).
    pub commanded_hz: Option<f64>,
    /// f_b measured on the gate line while the finger was in this region, Hz.
    pub produced_hz: Option<f64>,
    /// (produced − commanded) / commanded, %.
    pub error_pct: Option<f64>,
    /// For a texture driven by motion or chance (grating, material, random): the f_b its model
    /// gives at the finger's true speed, over the measured intervals (the number of intervals
    /// over the sum of the expected periods, as `produced_hz` is over the measured ones), Hz.
    pub expected_hz: Option<f64>,
    /// Pulses that started in this region.
    pub pulses: usize,
    /// Rise-to-rise intervals used for the measurement (whole intervals inside the region).
    pub intervals: usize,
    /// Mean on-time / period of those intervals, %.
    pub duty_pct: Option<f64>,
    /// Time spent in the region, s.
    pub time_s: f64,
}

/// One region switch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Switch {
    /// Sample time, µs.
    pub t_us: u64,
    /// Region left.
    pub from: u8,
    /// Region entered.
    pub to: u8,
    /// The boundary crossed, µm.
    pub boundary_um: f64,
    /// True finger position at the switch, µm.
    pub true_um: f64,
    /// Measured position at the switch, µm.
    pub meas_um: Option<i32>,
    /// How far past the boundary (in the direction of travel) the finger was, µm; negative if
    /// the switch came early.
    pub past_um: f64,
}

/// Velocity estimate quality.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VelocityStats {
    /// RMS of estimate − true velocity at the same instant, µm/s.
    pub rms_err_um_s: f64,
    /// The lag that best aligns the estimate with the true velocity, µs.
    pub delay_us: f64,
    /// RMS error against the true velocity delayed by that lag, µm/s.
    pub rms_err_at_delay_um_s: f64,
    /// Samples compared.
    pub samples: usize,
}

/// Where the finger left the calibrated travel (0 … the scene's length).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OffTravel {
    /// Samples with the true position outside the travel.
    pub samples: usize,
    /// Time of the first of them, µs.
    pub first_us: Option<u64>,
}

/// All figures of one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    /// Per region.
    pub regions: Vec<RegionStats>,
    /// Every switch, in order.
    pub switches: Vec<Switch>,
    /// Velocity estimate quality (None if the estimator never produced a value).
    pub velocity: Option<VelocityStats>,
    /// Fault onsets seen in the trace.
    pub fault_onsets: usize,
    /// Samples with a fault in force.
    pub fault_samples: usize,
    /// Samples simulated.
    pub samples: usize,
    /// Complete pulses on the line.
    pub pulses: usize,
    /// Pulses whose (period, on-time) matches none of the planned region settings, i.e. runts,
    /// doubled or stretched pulses. Pulses ended by an Off or followed by a restart are judged on
    /// on-time only.
    pub malformed_pulses: usize,
    /// How long the line stayed without a rising edge while the core had periodic bursts
    /// running, beyond two of their periods.
    pub stall: Stall,
    /// Samples with the finger off the travel.
    pub off_travel: OffTravel,
}

/// A gate that stopped making the bursts the core asked for (without preload, a 32-bit counter
/// that has passed a shortened ARR counts on to 2^32 before it wraps: with ARPE = 0 the new ARR
/// takes effect at once, RM0390 §18.3.1 time-base unit for TIM2–5, §17.3.1 for TIM1/8).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Stall {
    /// Total time the line was silent longer than two burst periods while a burst ran, s.
    pub total_s: f64,
    /// The longest such silence, s.
    pub longest_s: f64,
}

/// The silences of the line while the core had a periodic burst running: from the trace's
/// actions (what the core asked) and the timer model's rising edges (what the line did).
fn stall(r: &SimResult) -> Stall {
    let clock = r.timer.clock_hz as f64;
    let mut rises = r.waveform.pulses().into_iter().map(|p| p.rise).peekable();
    let mut last_rise_clk: Option<u64> = None;
    let mut running_period_clk: Option<u64> = None;
    // With preload an update acts at the next update event: until the next rise the period
    // replaced still runs, so it counts for the allowance too.
    let mut replaced_period_clk = 0u64;
    let (mut total, mut longest, mut current) = (0u64, 0u64, 0u64);
    let step_clk = r.clocks(r.sample_period_us as u64);
    for t in &r.trace {
        let now = r.clocks(t.t_us);
        while let Some(&rise) = rises.peek() {
            if rise > now {
                break;
            }
            last_rise_clk = Some(rise);
            replaced_period_clk = 0;
            rises.next();
        }
        match t.action {
            Some(GateAction::Start(s)) => {
                running_period_clk = Some(s.period_clocks());
                last_rise_clk = Some(now);
            }
            Some(GateAction::Update(s)) => {
                replaced_period_clk = replaced_period_clk.max(running_period_clk.unwrap_or(0));
                running_period_clk = Some(s.period_clocks());
            }
            Some(GateAction::Off | GateAction::Pulse(_)) => running_period_clk = None,
            _ => {}
        }
        let silent = match (running_period_clk, last_rise_clk) {
            (Some(period), Some(rise)) => {
                now.saturating_sub(rise) > 2 * period.max(replaced_period_clk)
            }
            _ => false,
        };
        if silent {
            current += step_clk;
            total += step_clk;
            longest = longest.max(current);
        } else {
            current = 0;
        }
    }
    Stall {
        total_s: total as f64 / clock,
        longest_s: longest as f64 / clock,
    }
}

/// Computes the metrics of a run.
pub fn compute(r: &SimResult) -> Metrics {
    let n_regions = r.params.config.scene.textures.len();
    let period_clk = r.clocks(r.sample_period_us as u64);

    // Run-length segments of the region, by trace index.
    let mut seg_end = vec![0usize; r.trace.len()];
    let mut i = r.trace.len();
    while i > 0 {
        i -= 1;
        let same_next = i + 1 < r.trace.len()
            && r.trace[i + 1].region == r.trace[i].region
            && r.trace[i].region.is_some();
        seg_end[i] = if same_next { seg_end[i + 1] } else { i };
    }
    let index_at = |t: u64| (t / period_clk) as usize;

    let pulses = r.waveform.pulses();
    let mut per_region_intervals: Vec<Vec<(u64, u64)>> = vec![Vec::new(); n_regions];
    // Σ expected period (s) and its count, per region, over the same intervals.
    let mut per_region_expected = vec![(0.0f64, 0usize); n_regions];
    let mut per_region_pulses = vec![0usize; n_regions];
    for p in &pulses {
        // The sample before the rise decided the settings that the rise latched.
        let idx = index_at(p.rise.saturating_sub(1));
        let Some(region) = r.trace.get(idx).and_then(|t| t.region) else {
            continue;
        };
        per_region_pulses[region as usize] += 1;
        if let Some(next) = p.next_rise {
            let before = idx.saturating_sub(1);
            let last = index_at(next).min(r.trace.len() - 1);
            if r.trace[before].region == Some(region) && seg_end[before] >= last {
                per_region_intervals[region as usize].push((next - p.rise, p.on()));
                let texture = &r.params.config.scene.textures[region as usize];
                if let Some(f) = expected_hz(texture, r.trace[idx].true_vel_um_s) {
                    let e = &mut per_region_expected[region as usize];
                    e.0 += 1.0 / f;
                    e.1 += 1;
                }
            }
        }
    }
    let mut time_in = vec![0usize; n_regions];
    for t in &r.trace {
        if let Some(reg) = t.region {
            time_in[reg as usize] += 1;
        }
    }
    let clock = r.timer.clock_hz as f64;
    let regions = (0..n_regions)
        .map(|i| {
            let commanded_hz = r.params.config.scene.textures[i]
                .fixed_command()
                .map(|c| c.burst_millihz as f64 / 1000.0);
            let iv = &per_region_intervals[i];
            let (produced_hz, duty_pct) = if iv.is_empty() {
                (None, None)
            } else {
                let total: u64 = iv.iter().map(|x| x.0).sum();
                let on: u64 = iv.iter().map(|x| x.1).sum();
                (
                    Some(clock * iv.len() as f64 / total as f64),
                    Some(100.0 * on as f64 / total as f64),
                )
            };
            let (sum_s, n) = per_region_expected[i];
            let expected_hz = (n > 0).then(|| n as f64 / sum_s);
            let error_pct = match (commanded_hz, produced_hz) {
                (Some(c), Some(p)) => Some(100.0 * (p - c) / c),
                _ => None,
            };
            RegionStats {
                region: i as u8,
                commanded_hz,
                expected_hz,
                produced_hz,
                error_pct,
                pulses: per_region_pulses[i],
                intervals: iv.len(),
                duty_pct,
                time_s: time_in[i] as f64 * r.sample_period_us as f64 * 1e-6,
            }
        })
        .collect();

    let switches = switches(r);

    let mut fault_onsets = 0;
    let mut prev = None;
    for t in &r.trace {
        if t.fault.is_some() && prev.is_none() {
            fault_onsets += 1;
        }
        prev = t.fault;
    }
    let fault_samples = r.trace.iter().filter(|t| t.fault.is_some()).count();

    // Every setting the core handed the timer (constant regions', and the per-sample ones of
    // grating/material/random regions and line pulses): a whole pulse matches one of them.
    let mut planned: Vec<TimerSettings> = r.region_settings.iter().flatten().copied().collect();
    planned.extend(r.trace.iter().filter_map(|t| match t.action {
        Some(GateAction::Start(s) | GateAction::Update(s) | GateAction::Pulse(s)) => Some(s),
        _ => None,
    }));
    planned.sort_by_key(|s| (s.psc, s.arr, s.ccr));
    planned.dedup();
    let malformed_pulses = pulses
        .iter()
        .filter(|p| !pulse_matches(p.on(), p.period(), &planned))
        .count();

    Metrics {
        regions,
        switches,
        velocity: velocity_stats(r),
        fault_onsets,
        fault_samples,
        samples: r.trace.len(),
        pulses: pulses.len(),
        malformed_pulses,
        stall: stall(r),
        off_travel: off_travel(r),
    }
}

/// The samples of `r` whose true position lies outside the calibrated travel.
pub fn off_travel(r: &SimResult) -> OffTravel {
    let len = r.params.config.calibration.length_um as f64;
    let mut off = r.trace.iter().filter(|p| !(0.0..=len).contains(&p.true_um));
    let first_us = off.next().map(|p| p.t_us);
    OffTravel {
        samples: off.count() + usize::from(first_us.is_some()),
        first_us,
    }
}

/// True when a pulse is one of `planned`: on-time and period both equal to one setting's. A pulse
/// not followed by another rise of the same run (Off, restart, end) is checked for on-time ≤ the
/// setting's only, since Off cuts it short by design.
fn pulse_matches(on: u64, period: Option<u64>, planned: &[TimerSettings]) -> bool {
    planned.iter().any(|s| match period {
        Some(p) => {
            (s.on_clocks() == on && s.period_clocks() == p)
                // A pulse cut by Off and restarted later: shorter on-time, longer gap.
                || (on <= s.on_clocks() && p > s.period_clocks())
        }
        None => on <= s.on_clocks(),
    })
}

/// Velocity RMS error, at zero lag and at the best lag (searched 0–10 ms in 10 µs steps against
/// the trajectory's true velocity).
pub fn velocity_stats(r: &SimResult) -> Option<VelocityStats> {
    let pts: Vec<(f64, f64, f64)> = r
        .trace
        .iter()
        .filter(|t| t.fault.is_none())
        .filter_map(|t| {
            t.est_vel_um_s
                .map(|v| (t.t_us as f64 * 1e-6, v as f64, t.true_vel_um_s))
        })
        .collect();
    if pts.is_empty() {
        return None;
    }
    let rms = |lag_s: f64| -> f64 {
        let s: f64 = pts
            .iter()
            .map(|&(t, est, _)| {
                let v = r
                    .params
                    .trajectory
                    .state((t - lag_s).max(0.0))
                    .velocity_um_s;
                (est - v).powi(2)
            })
            .sum();
        (s / pts.len() as f64).sqrt()
    };
    let rms0 = (pts.iter().map(|p| (p.1 - p.2).powi(2)).sum::<f64>() / pts.len() as f64).sqrt();
    // Coarse search (100 µs) then fine (5 µs) around the best.
    let mut best = (0.0, rms(0.0));
    for k in 0..=100 {
        let lag = k as f64 * 100e-6;
        let e = rms(lag);
        if e < best.1 {
            best = (lag, e);
        }
    }
    let centre = best.0;
    for k in -20..=20 {
        let lag = centre + k as f64 * 5e-6;
        if lag < 0.0 {
            continue;
        }
        let e = rms(lag);
        if e < best.1 {
            best = (lag, e);
        }
    }
    Some(VelocityStats {
        rms_err_um_s: rms0,
        delay_us: best.0 * 1e6,
        rms_err_at_delay_um_s: best.1,
        samples: pts.len(),
    })
}

/// Region switches: consecutive samples that both have a region and differ. A region regained
/// after a fault (no region in between) is not a switch, as in the controller's own count.
pub fn switches(r: &SimResult) -> Vec<Switch> {
    let boundaries: Vec<f64> = r
        .params
        .config
        .scene
        .boundaries_um
        .iter()
        .map(|&b| b as f64)
        .collect();
    let mut switches = Vec::new();
    for w in r.trace.windows(2) {
        let (Some(a), Some(b)) = (w[0].region, w[1].region) else {
            continue;
        };
        if a == b {
            continue;
        }
        let up = b > a;
        let bi = if up { b as usize - 1 } else { b as usize };
        let boundary_um = boundaries.get(bi).copied().unwrap_or(f64::NAN);
        let true_um = w[1].true_um;
        let past_um = if up {
            true_um - boundary_um
        } else {
            boundary_um - true_um
        };
        switches.push(Switch {
            t_us: w[1].t_us,
            from: a,
            to: b,
            boundary_um,
            true_um,
            meas_um: w[1].meas_um,
            past_um,
        });
    }

    switches
}

/// One burst of a grating against the ridge it renders.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RidgeHit {
    /// Rising edge, s.
    pub t_s: f64,
    /// True finger position at the rising edge minus the nearest ridge (a multiple of λ),
    /// signed along the motion (positive: the burst came after the ridge), µm.
    pub error_um: f64,
    /// On-time, s.
    pub on_s: f64,
    /// True speed at the rising edge, µm/s.
    pub speed_um_s: f64,
}

/// Where every burst of a run landed against a grating of period `wavelength_um` whose ridges
/// sit at the multiples of λ.
pub fn ridge_hits(r: &SimResult, wavelength_um: f64) -> Vec<RidgeHit> {
    let clock = r.waveform.clock_hz as f64;
    r.waveform
        .pulses()
        .iter()
        .map(|p| {
            let t_s = p.rise as f64 / clock;
            let st = r.params.trajectory.state(t_s);
            let (x, v) = (st.position_um, st.velocity_um_s);
            let off = x - (x / wavelength_um).round() * wavelength_um;
            RidgeHit {
                t_s,
                error_um: if v < 0.0 { -off } else { off },
                on_s: p.on() as f64 / clock,
                speed_um_s: v.abs(),
            }
        })
        .collect()
}

/// Ridges (multiples of `wavelength_um`) the true finger position crossed during the run,
/// counted on the trace's sampling grid.
pub fn ridges_crossed(r: &SimResult, wavelength_um: f64) -> u64 {
    let cells = r
        .trace
        .iter()
        .map(|t| (t.true_um / wavelength_um).floor() as i64);
    cells
        .clone()
        .zip(cells.skip(1))
        .map(|(a, b)| a.abs_diff(b))
        .sum()
}

#[cfg(test)]
mod expected_tests {
    use super::*;
    use saw_core::texture::{Grating, Material, RandomBurst};

    /// Hand-worked: 60 mm/s over a 1 mm grating is 60 Hz, either direction; fig. 5's finger
    /// (Δμ 0.3) at 40 mm/s is 28.811 Hz (worked in the core's controller tests); draws uniform
    /// on 40 Hz ± 30 % come at 40 · 0.6 / ln(13/7) = 24 / (2.564949 − 1.945910) = 38.770 Hz; a constant texture and a
    /// finger at rest have none.
    #[test]
    fn expected_rates_by_hand() {
        let g = Texture::Grating(Grating::new(1_000));
        assert_eq!(expected_hz(&g, 60_000.0), Some(60.0));
        assert_eq!(expected_hz(&g, -60_000.0), Some(60.0));
        assert_eq!(expected_hz(&g, 0.0), None);
        let m = Texture::Material(Material::fig5(0.3));
        let f = expected_hz(&m, 40_000.0).unwrap();
        assert!((f - 28.811).abs() < 0.01, "{f}");
        let r = Texture::Random(RandomBurst {
            center_millihz: 40_000,
            spread_permille: 300,
            amplitude_permille: 1000,
            amplitude_spread_permille: 0,
            duty_permille: 400,
            seed: 1,
        });
        let f = expected_hz(&r, 0.0).unwrap();
        assert!((f - 38.770).abs() < 0.001, "{f}");
        assert_eq!(expected_hz(&Texture::constant_hz(80), 60_000.0), None);
        assert_eq!(expected_hz(&Texture::Off, 60_000.0), None);
    }
}
