//! The human summary of a run: the board and motion, f_b per region, the tangible lines' pulses
//! (apart from every region's bursts), switches, velocity, faults and the gate.

use std::fmt::Write;

use crate::metrics::Metrics;
use crate::sim::RunHeader;

/// Switches listed in the summary; the rest are counted.
pub const SWITCHES_PRINTED: usize = 20;

/// Formats the summary of run `r` with metrics `m`.
pub fn summary(r: &RunHeader, m: &Metrics) -> String {
    let mut s = String::new();
    let p = &r.params;
    let _ = writeln!(
        s,
        "board {}: burst timer {} MHz, {}-bit, f_b ≤ {} Hz; sample period {} µs, {} conversions a sample, velocity window {} samples",
        p.board.name,
        r.timer.clock_hz as f64 / 1e6,
        r.timer.counter_bits,
        r.timer.max_burst_hz,
        r.sample_period_us,
        p.adc.oversample,
        p.board.velocity_window
    );
    let _ = writeln!(
        s,
        "trajectory: {} for {:.2} s; ADC noise {:.2} LSB RMS/conversion, offset {:.2} LSB, seed {}",
        p.trajectory.describe(),
        p.duration_s,
        p.adc.noise_lsb_rms,
        p.adc.offset_lsb,
        p.adc.seed
    );
    if let Some(first_us) = m.off_travel.first_us {
        let period_s = r.sample_period_us as f64 * 1e-6;
        let _ = writeln!(
            s,
            "warning: the finger is off the {} mm travel for {:.2} s of the {:.2} s ({:.1} % of the samples), first at t = {:.4} s",
            p.config.calibration.length_um as f64 / 1e3,
            m.off_travel.samples as f64 * period_s,
            p.duration_s,
            100.0 * m.off_travel.samples as f64 / m.samples.max(1) as f64,
            first_us as f64 * 1e-6
        );
    }
    let b: Vec<String> = p
        .config
        .scene
        .boundaries_um
        .iter()
        .map(|b| format!("{:.3}", *b as f64 / 1e3))
        .collect();
    let _ = writeln!(
        s,
        "scene: {} regions, boundaries [{}] mm, hysteresis {} µm",
        p.config.scene.textures.len(),
        b.join(", "),
        p.config.scene.hysteresis_um
    );
    let _ = writeln!(
        s,
        "\nburst frequency per region (measured from gate edges):"
    );
    let _ = writeln!(
        s,
        "  region  commanded    produced       error      duty   pulses  periods  time"
    );
    for g in &m.regions {
        let fmt_hz = |x: Option<f64>| x.map(|v| format!("{v:.4} Hz")).unwrap_or("—".into());
        // A motion- or chance-driven texture has no commanded f_b: its model's, marked "~".
        let (asked, error) = match (g.commanded_hz, g.expected_hz) {
            (None, Some(e)) => (
                format!("~{}", fmt_hz(Some(e))),
                g.produced_hz
                    .map(|p| format!("~{:+.2} %", 100.0 * (p - e) / e))
                    .unwrap_or("—".into()),
            ),
            _ => (
                fmt_hz(g.commanded_hz),
                g.error_pct
                    .map(|e| format!("{e:+.5} %"))
                    .unwrap_or("—".into()),
            ),
        };
        let _ = writeln!(
            s,
            "  {:>6}  {:>12}  {:>13}  {:>10}  {:>6}  {:>6}  {:>7}  {:.2} s",
            g.region,
            asked,
            fmt_hz(g.produced_hz),
            error,
            g.duty_pct
                .map(|d| format!("{d:.1} %"))
                .unwrap_or("—".into()),
            g.pulses,
            g.intervals,
            g.time_s
        );
    }
    lines(&mut s, r, m);
    let _ = writeln!(s, "\nregion switches: {}", m.switch_count);
    for w in m.switches.iter().take(SWITCHES_PRINTED) {
        let _ = writeln!(
            s,
            "  t = {:7.4} s  {} → {}  at {:7.3} mm (measured {}), boundary {:.3} mm, {:+.3} mm past",
            w.t_us as f64 * 1e-6,
            w.from,
            w.to,
            w.true_um / 1e3,
            w.meas_um
                .map(|x| format!("{:.3} mm", x as f64 / 1e3))
                .unwrap_or("—".into()),
            w.boundary_um / 1e3,
            w.past_um / 1e3
        );
    }
    if m.switch_count > SWITCHES_PRINTED {
        let _ = writeln!(s, "  … and {} more", m.switch_count - SWITCHES_PRINTED);
    }
    if let Some(worst) = m.switch_past_um.map(|(lo, hi)| lo.abs().max(hi.abs())) {
        let _ = writeln!(s, "  worst distance from boundary: {:.3} mm", worst / 1e3);
    }
    match &m.velocity {
        Some(v) => {
            let _ = writeln!(
                s,
                "\nvelocity: RMS error {:.2} mm/s at zero lag; best-fit delay {:.0} µs (in whole \
                 samples), RMS error {:.2} mm/s at that delay ({} samples)",
                v.rms_err_um_s / 1e3,
                v.delay_us,
                v.rms_err_at_delay_um_s / 1e3,
                v.samples
            );
        }
        None => {
            let _ = writeln!(s, "\nvelocity: no estimate");
        }
    }
    let _ = writeln!(
        s,
        "faults: {} onsets, {} samples under fault (controller counted {})",
        m.fault_onsets, m.fault_samples, r.telemetry.faults
    );
    let line_pulses: usize = m.line_pulses.iter().sum();
    let _ = writeln!(
        s,
        "gate: {} pulses{}, {} malformed (runt/doubled/stretched), {} gate actions",
        m.pulses,
        if m.line_pulses.is_empty() {
            String::new()
        } else {
            format!(" ({line_pulses} of them line pulses)")
        },
        m.malformed_pulses,
        r.telemetry.gate_actions
    );
    if m.stall.total_s > 0.0 {
        let _ = writeln!(
            s,
            "warning: the gate stalled: no burst edge for {:.3} s in all (longest {:.3} s) while \
             the core had bursts running{}",
            m.stall.total_s,
            m.stall.longest_s,
            if r.params.preload {
                ""
            } else {
                " (without preload a counter past a shortened ARR runs on to its wrap)"
            }
        );
    }
    let _ = writeln!(s, "samples: {}", m.samples);
    s
}

/// The tangible lines, when the scene has any: where they are and the pulses measured on the
/// gate line for each (none of them counted as a region's bursts), beside the core's own count
/// and the crossings it skipped to keep the duty cap.
fn lines(s: &mut String, r: &RunHeader, m: &Metrics) {
    let scene = &r.params.config.scene;
    if scene.lines.positions_um.is_empty() {
        return;
    }
    let at: Vec<String> = scene
        .lines
        .positions_um
        .iter()
        .map(|p| format!("{:.3}", *p as f64 / 1e3))
        .collect();
    let per: Vec<String> = m.line_pulses.iter().map(|n| n.to_string()).collect();
    let _ = writeln!(
        s,
        "\ntangible lines: {} at [{}] mm; {} pulses measured on the gate line (per line: {}); \
         the core fired {}, skipped {} crossings to keep the duty cap",
        at.len(),
        at.join(", "),
        m.line_pulses.iter().sum::<usize>(),
        per.join(", "),
        r.telemetry.line_pulses,
        r.telemetry.lines_skipped
    );
}
