//! The RF level through the whole closed loop (rheostat/ADC model, core, timer model with the
//! DAC, the reference circuit): a line's triangle peaks on the line at 20–200 mm/s both ways and
//! is played in hardware steps, not the sample loop's; rectangles are flat as before; random
//! amplitude is drawn per burst inside its spread, uniform, never changing inside a burst; a
//! rail fault drops the level to 0 with the enables (`docs/rf-level.md`).

use host_sim::adc::{FaultKind, FaultWindow};
use host_sim::rf::permille_at_code;
use host_sim::sim::{self, SimParams, SimResult};
use host_sim::trajectory::Trajectory;
use saw_boards::rf_level::{triangle_plan, LevelTable};
use saw_boards::{BoardDef, NUCLEO_F446RE, NUCLEO_G474RE};
use saw_core::scene::default_config;
use saw_core::texture::{Envelope, RandomBurst, Texture};

const LINE_UM: u32 = 50_000;
const PULSE_US: u32 = 10_000;
/// ADC noise seeds each crossing runs with.
const SEEDS: std::ops::Range<u64> = 0..12;

/// One 12-bit LSB of the 100 mm rheostat, µm: below ~200 mm/s a sample's travel (2 µm at
/// 20 mm/s) is finer than the position the core measures (16 conversions at 2 LSB RMS leave
/// 0.5 LSB, ~12 µm RMS) and the 5 ms of velocity noise the lead multiplies, so the firing sample
/// is chosen by noise.
const LSB_UM: f64 = 100_000.0 / 4096.0;

/// The specification (docs/rf-level.md, the test's doc below): the peak within one sample of
/// travel of the line, or within the position's noise floor where that is coarser — taken as
/// 2 LSB (48.8 µm, 4 σ of the position's noise), on every crossing. Measured over 48 seeds on
/// both noise streams and both boards: worst 40.0 µm (the tabulated stream, −20 mm/s, seed 7),
/// 36.0 µm on the reference one. Without the lead the peak lands half the pulse late: 100 µm at
/// 20 mm/s, 1 mm at 200 mm/s.
const SPEC_FLOOR_UM: f64 = 2.0 * LSB_UM;

/// The spread of the peak at 20–60 mm/s, where the position's noise sets it: RMS at most
/// 16 µm (the position's ~12 µm RMS, with room for the lead's velocity noise and the spread of
/// 96 crossings), and 95 % of the crossings within 1.5 LSB (36.6 µm, 3 σ of the position's
/// noise). Measured over 48 seeds a case on both boards: RMS 12.4 µm (reference stream) and
/// 11.6 µm (tabulated), 95th percentile 24.0 and 22.0 µm; over [`SEEDS`] RMS 13.8 µm and 95th
/// percentile 30.0 µm (the percentile of 96 crossings moves by steps of the position's
/// quantisation from one seed set to another; the RMS is steadier). A lead 20 µm off at
/// 20 mm/s (a fifth of it) takes the RMS to ~19 µm.
const SLOW_RMS_UM: f64 = 16.0;
const SLOW_P95_UM: f64 = 1.5 * LSB_UM;

/// Snapshot: the worst distance of a triangle's peak from its line over [`SEEDS`] on the
/// reference noise stream, 40.06 µm (G474, +200 mm/s, seed 3: two samples of travel early), as
/// docs/rf-level.md and the README state it. Since each board runs its own acquisition and
/// window (issue #35) the G474 peaks within 18 µm at 20–60 mm/s (its lower noise) and within one
/// sample of travel at 200 mm/s on 11 of 12 seeds each way; the F446, unchanged: per speed 24 µm
/// at +20 and +60 mm/s, 32 at −20, 36 at −60, one sample of travel (20 µm) at 200 mm/s. Before,
/// with the F446's acquisition and window on both boards: 36.02 µm (G474, −60 mm/s, seed 4).
/// Not a specification: another noise realisation moves it (on the tabulated stream seed 7 at
/// −20 mm/s peaks 40 µm from the line).
const SNAPSHOT_WORST_UM: f64 = 40.064;
const SNAPSHOT_WORST_CASE: &str = "nucleo-g474re 200000 µm/s seed 3";

fn lines_config(envelope: Envelope, amplitude_permille: u16) -> saw_core::Config {
    let mut cfg = default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    let _ = cfg.scene.textures.push(Texture::Off);
    let _ = cfg.scene.lines.positions_um.push(LINE_UM);
    cfg.scene.lines.pulse_us = PULSE_US;
    cfg.scene.lines.envelope = envelope;
    cfg.scene.lines.amplitude_permille = amplitude_permille;
    cfg
}

/// One crossing of the line at `speed_um_s` (negative: downwards), starting 15 mm before it.
fn crossing(
    board: &'static BoardDef,
    cfg: saw_core::Config,
    speed_um_s: f64,
    seed: u64,
) -> SimResult {
    let from = LINE_UM as f64 - 15_000.0 * speed_um_s.signum();
    let s = 30_000.0 / speed_um_s.abs();
    let p = SimParams::new(
        board,
        Trajectory::Constant {
            from_um: from,
            speed_um_s,
        },
        s,
    )
    .with_config(cfg)
    .with_noise(2.0, seed)
    // The snapshot figure (40 µm over these 12 seeds) was measured on this noise stream; on
    // the tabulated one seed 7 at −20 mm/s peaks 40 µm from the line (docs/streaming.md).
    .with_reference_noise();
    sim::run(&p).unwrap()
}

/// The one line pulse of a run: (rise, fall) in timer clocks.
fn the_pulse(r: &SimResult) -> (u64, u64) {
    let p = r.waveform.pulses();
    assert_eq!(p.len(), 1, "one crossing, one pulse: {p:?}");
    (p[0].rise, p[0].fall)
}

/// The true finger position at timer-clock time `t`, µm.
fn true_um_at(r: &SimResult, t: u64) -> f64 {
    r.params
        .trajectory
        .state(r.waveform.clocks_to_s(t))
        .position_um
}

/// The level changes inside the pulse: (time, ‰ the finger gets).
fn drive_steps(r: &SimResult, rise: u64, fall: u64) -> Vec<(u64, f64)> {
    r.waveform
        .codes_within(rise, fall)
        .iter()
        .map(|e| (e.t, permille_at_code(e.code)))
        .collect()
}

/// One triangle crossing's outcome.
struct Crossing {
    case: String,
    speed_um_s: f64,
    /// Signed distance of the peak from the line (the true finger position then), µm.
    err_um: f64,
    /// What is wrong with the pulse's shape, if anything.
    shape: Result<(), String>,
}

macro_rules! ensure {
    ($c:expr, $($fmt:tt)+) => {
        if !$c {
            return Err(format!($($fmt)+));
        }
    };
}

/// The pulse's shape: its length the scene's, rising to the middle and falling after it, no step
/// larger than one table entry's, 0 at the end, one level per table entry. Returns the peak's
/// time.
fn triangle_shape(r: &SimResult, board: &BoardDef) -> Result<u64, String> {
    let clk = board.burst_timer_clk_hz as f64;
    let plan = triangle_plan(
        PULSE_US as u64 * board.rf_level.envelope_timer_clk_hz as u64 / 1_000_000,
        board.rf_level.envelope_timer_clk_hz,
    );
    // One entry of the table at full level: 1000 ‰ / (entries / 2), plus the table's 1 %.
    let max_step = 1000.0 / (plan.entries as f64 / 2.0) + 10.0;
    let (rise, fall) = the_pulse(r);
    let length_us = (fall - rise) as f64 / clk * 1e6;
    ensure!((length_us - PULSE_US as f64).abs() < 1.0, "{length_us} µs");
    let steps = drive_steps(r, rise, fall);
    let (peak_t, peak) = steps
        .iter()
        .copied()
        .fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    ensure!((peak - 1000.0).abs() < 10.0, "peak {peak} ‰");
    // Symmetric: the peak halfway (within one step), rising before, falling after.
    let half = (rise + fall) as f64 / 2.0;
    let step_clocks = (fall - rise) as f64 / plan.entries as f64;
    ensure!(
        ((peak_t as f64) - half).abs() <= step_clocks,
        "peak at {peak_t}, middle {half}"
    );
    for w in steps.windows(2) {
        let d = w[1].1 - w[0].1;
        ensure!(d.abs() <= max_step, "a step of {d:.1} ‰ at {}", w[1].0);
        ensure!(
            if w[1].0 <= peak_t { d > 0.0 } else { d < 0.0 },
            "not a triangle at {}",
            w[1].0
        );
    }
    ensure!(r.waveform.code_at(fall) == 0, "the envelope ends at 0");
    // The entries come one per step: the sample loop (100 µs) plays none of them.
    ensure!(steps.len() >= plan.entries - 1, "{} steps", steps.len());
    Ok(peak_t)
}

/// A triangle at 20, 60 and 200 mm/s, both ways, on both boards, over [`SEEDS`]: run once per
/// test binary, shared by the specification test and the snapshot.
fn triangle_crossings() -> &'static [Crossing] {
    static RUNS: std::sync::OnceLock<Vec<Crossing>> = std::sync::OnceLock::new();
    RUNS.get_or_init(|| {
        let mut runs = Vec::new();
        for board in [&NUCLEO_F446RE, &NUCLEO_G474RE] {
            for speed in [
                20_000.0, 60_000.0, 200_000.0, -20_000.0, -60_000.0, -200_000.0,
            ] {
                for seed in SEEDS {
                    let r = crossing(board, lines_config(Envelope::Triangular, 1000), speed, seed);
                    let shape = triangle_shape(&r, board);
                    let err_um = shape
                        .as_ref()
                        .map_or(f64::NAN, |&t| true_um_at(&r, t) - LINE_UM as f64);
                    runs.push(Crossing {
                        case: format!("{} {speed} µm/s seed {seed}", board.name),
                        speed_um_s: speed,
                        err_um,
                        shape: shape.map(|_| ()),
                    });
                }
            }
        }
        runs
    })
}

/// A triangle at 20, 60 and 200 mm/s, both ways, on both boards, over several noise seeds: its
/// shape ([`triangle_shape`]), and its peak on the line — within one sample of travel, or the
/// position's noise floor where that is coarser ([`SPEC_FLOOR_UM`]) on every crossing, and
/// within [`SLOW_P95_UM`] on 95 % of those at 20–60 mm/s.
#[test]
fn a_triangle_peaks_on_the_line_at_every_speed() {
    let mut slow_um = Vec::new();
    for c in triangle_crossings() {
        if let Err(e) = &c.shape {
            panic!("{}: {e}", c.case);
        }
        let one_sample_um = c.speed_um_s.abs() * 1e-4;
        let bound = one_sample_um.max(SPEC_FLOOR_UM);
        assert!(
            c.err_um.abs() <= bound,
            "{}: peak {:+.1} µm from the line, more than {bound:.1} µm",
            c.case,
            c.err_um
        );
        if c.speed_um_s.abs() < 100_000.0 {
            slow_um.push(c.err_um.abs());
        }
    }
    slow_um.sort_by(f64::total_cmp);
    let p95 = slow_um[slow_um.len() * 95 / 100];
    let rms = (slow_um.iter().map(|e| e * e).sum::<f64>() / slow_um.len() as f64).sqrt();
    eprintln!(
        "20–60 mm/s: {} crossings, RMS {rms:.2} µm, 95th percentile {p95:.2} µm, worst {:.2} µm",
        slow_um.len(),
        slow_um[slow_um.len() - 1]
    );
    assert!(
        rms <= SLOW_RMS_UM,
        "RMS at 20–60 mm/s {rms:.2} µm, above {SLOW_RMS_UM} µm"
    );
    assert!(
        p95 <= SLOW_P95_UM,
        "95th percentile at 20–60 mm/s {p95:.2} µm, above {SLOW_P95_UM:.1} µm"
    );
}

/// Snapshot, not a specification: the worst peak distance over [`SEEDS`] on the reference
/// stream is the figure docs/rf-level.md and the README quote. A failure here means the figure
/// moved (the noise model, the lead, the timer model): re-measure, update those docs and this
/// snapshot, and judge the change by the specification test above.
#[test]
fn snapshot_triangle_peak_worst_over_seeds_0_to_11() {
    let worst = triangle_crossings()
        .iter()
        .max_by(|a, b| a.err_um.abs().total_cmp(&b.err_um.abs()))
        .unwrap();
    eprintln!(
        "worst peak error: {:.3} µm ({})",
        worst.err_um.abs(),
        worst.case
    );
    assert!(
        (worst.err_um.abs() - SNAPSHOT_WORST_UM).abs() < 0.005 && worst.case == SNAPSHOT_WORST_CASE,
        "snapshot moved: worst {:.3} µm ({}), was {SNAPSHOT_WORST_UM} µm ({SNAPSHOT_WORST_CASE})",
        worst.err_um.abs(),
        worst.case
    );
}

/// A rectangle is flat at its level for the whole pulse, as before, and fires on the line.
#[test]
fn a_rectangle_is_flat_and_starts_on_the_line() {
    for speed in [20_000.0, -200_000.0] {
        let r = crossing(
            &NUCLEO_F446RE,
            lines_config(Envelope::Rectangular, 700),
            speed,
            1,
        );
        let (rise, fall) = the_pulse(&r);
        let steps = drive_steps(&r, rise, fall);
        assert_eq!(steps.len(), 1, "{steps:?}");
        assert!((steps[0].1 - 700.0).abs() < 7.0, "{} ‰", steps[0].1);
        let at_rise = true_um_at(&r, rise) - LINE_UM as f64;
        // Fired on the first sample past the line: within a sample and the position noise.
        assert!(
            at_rise * speed.signum() > -SPEC_FLOOR_UM && at_rise.abs() < 60.0,
            "{at_rise} µm"
        );
    }
}

fn random_config(amplitude_permille: u16, spread_permille: u16, seed: u64) -> saw_core::Config {
    let mut cfg = default_config();
    cfg.scene.boundaries_um.clear();
    cfg.scene.textures.clear();
    let _ = cfg.scene.textures.push(Texture::Random(RandomBurst {
        center_millihz: 200_000,
        spread_permille: 300,
        amplitude_permille,
        amplitude_spread_permille: spread_permille,
        duty_permille: 400,
        seed,
    }));
    cfg
}

/// The lowest level the table maps to `code` (the table is monotonic; several levels may share
/// a code where it is flat).
fn level_of_code(table: &LevelTable, code: u16) -> u16 {
    (0..=1000u16)
        .find(|&l| table.code(l) == code)
        .expect("a code the table gives")
}

/// Random amplitude over 10 000 bursts (three PRNG seeds): every burst's level inside
/// amplitude × (1 ± spread), uniform over it (ten bins, chi-square), and constant from the
/// burst's first edge to its last: a level is latched only at a period's start.
#[test]
fn random_amplitude_is_uniform_in_its_spread_and_latched_per_burst() {
    let (center, spread) = (600.0, 0.2);
    for seed in [1, 2, 3] {
        let p = SimParams::new(&NUCLEO_F446RE, Trajectory::Rest { at_um: 40_000.0 }, 52.0)
            .with_config(random_config(600, 200, seed))
            .with_noise(2.0, seed);
        let r = sim::run(&p).unwrap();
        let pulses = r.waveform.pulses();
        assert!(pulses.len() >= 10_000, "{} bursts", pulses.len());
        let table = NUCLEO_F446RE.rf_level.table;
        let mut bins = [0u32; 10];
        let mut levels = Vec::new();
        for q in &pulses[1..] {
            let steps = drive_steps(&r, q.rise, q.fall);
            assert_eq!(
                steps.len(),
                1,
                "a level change inside the burst at {}: {steps:?}",
                q.rise
            );
            // What the finger gets: the spread, give or take the table's 1 %.
            let got = steps[0].1;
            assert!(
                got >= center * (1.0 - spread) * 0.99 && got <= center * (1.0 + spread) * 1.01,
                "{got} ‰"
            );
            // What was drawn: the level whose code the DAC holds.
            let l = level_of_code(&table, r.waveform.code_at(q.rise)) as f64;
            assert!(
                l >= center * (1.0 - spread) && l <= center * (1.0 + spread),
                "{l} ‰"
            );
            levels.push(l);
            let x = ((l - center * (1.0 - spread)) / (2.0 * spread * center) * 10.0).floor();
            bins[(x.max(0.0) as usize).min(9)] += 1;
        }
        // Uniform: chi-square over 10 bins below the 0.1 % point of 9 degrees of freedom (27.9).
        let n = levels.len() as f64;
        let chi2: f64 = bins
            .iter()
            .map(|&b| (b as f64 - n / 10.0).powi(2) / (n / 10.0))
            .sum();
        assert!(chi2 < 27.9, "seed {seed}: chi2 {chi2:.1}, bins {bins:?}");
        // And not a constant: the levels spread over most of the range.
        let (lo, hi) = levels
            .iter()
            .fold((f64::MAX, 0.0f64), |a, &l| (a.0.min(l), a.1.max(l)));
        assert!(lo < center * 0.82 && hi > center * 1.18, "{lo}..{hi}");
    }
}

/// A rail fault mid-stroke, inside a triangle: the enables and the level drop to 0 together,
/// within one sample of the fault; the level stays 0 while the fault lasts.
#[test]
fn a_rail_fault_drops_the_level_with_the_enables() {
    for kind in [FaultKind::Open, FaultKind::Short] {
        let stroke = |faults: Vec<FaultWindow>| {
            SimParams::new(
                &NUCLEO_F446RE,
                Trajectory::Constant {
                    from_um: 35_000.0,
                    speed_um_s: 20_000.0,
                },
                1.0,
            )
            .with_config(lines_config(Envelope::Triangular, 1000))
            .with_noise(2.0, 1)
            .with_faults(faults)
        };
        // Where the pulse is without the fault; the rail goes 2 ms into it.
        let clean = sim::run(&stroke(vec![])).unwrap();
        let fault_at_s = clean.waveform.clocks_to_s(the_pulse(&clean).0) + 0.002;
        let p = stroke(vec![FaultWindow {
            kind,
            start_us: (fault_at_s * 1e6) as u64,
            end_us: ((fault_at_s + 0.1) * 1e6) as u64,
        }]);
        let r = sim::run(&p).unwrap();
        let t_fault = r.clocks((fault_at_s * 1e6) as u64);
        let p0 = r.waveform.pulses();
        assert_eq!(p0.len(), 1, "{p0:?}");
        assert!(p0[0].rise < t_fault, "the pulse began before the fault");
        let cut = p0[0].fall;
        let one_sample = r.clocks(r.sample_period_us as u64);
        assert!(
            cut >= t_fault && cut - t_fault <= one_sample,
            "cut {} clocks after the fault",
            cut - t_fault
        );
        assert!(r.waveform.code_at(t_fault - 1) > 0, "the envelope was up");
        assert_eq!(r.waveform.code_at(cut), 0, "level 0 with the enables");
        let later = r
            .waveform
            .codes_within(cut, r.clocks(((fault_at_s + 0.1) * 1e6) as u64));
        assert!(later.iter().all(|e| e.code == 0), "{later:?}");
    }
}
