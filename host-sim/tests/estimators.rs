//! Stability tests: every estimator of the bench, each at the place where estimators fail.
//!
//! Each test says what each method does there and asserts that the output stays bounded
//! (finite by construction: the trait returns integers) and recovers. The streams are made
//! deterministically (seeded ADC model, or exact integer ramps), no wall time is involved.

use host_sim::bench::measure::{errors, pool, replay};
use host_sim::bench::methods::{all, Method};
use host_sim::bench::scenario::{self, reference_spec, Input, Obs, Spec};
use host_sim::trajectory::{Piece, Trajectory};

const T_US: u32 = 100;
/// One 12-bit step of one conversion, summed 16 times: 16 codes ≈ 16.0 µm.
const STEP_UM: f64 = 16.02;

fn is(m: &Method, prefix: &str) -> bool {
    m.name.starts_with(prefix)
}

/// An exact integer ramp of `um_per_sample`, as a stream with timestamps `t(k)`.
fn ramp(n: usize, um_per_sample: i32, t: impl Fn(u32) -> u32) -> Vec<Obs> {
    (0..n as u32)
        .map(|k| Obs {
            t_us: t(k),
            input: Input::Position(20_000 + um_per_sample * k as i32),
            v_true: um_per_sample as f64 * 1e6 / T_US as f64,
            a_true: 0.0,
            scored: true,
        })
        .collect()
}

fn stream(trajectory: Trajectory, duration_s: f64, noise_lsb: f64, seed: u64) -> Vec<Obs> {
    let mut s = Spec::new(trajectory, duration_s, noise_lsb, 10_000);
    s.seed = seed;
    s.generate()
}

/// Samples after the last `None` before index `from` … until the output is within `tol` of the
/// truth for good (to the end of the stream); None if it never settles.
fn settle_samples(stream: &[Obs], out: &[Option<i32>], from: usize, tol: f64) -> Option<usize> {
    let bad = (from..stream.len()).rev().find(|&i| match out[i] {
        Some(v) => (v as f64 - stream[i].v_true).abs() > tol,
        None => stream[i].input != Input::Dropped,
    });
    match bad {
        None => Some(0),
        Some(i) if i + 1 < stream.len() => Some(i + 1 - from),
        Some(_) => None,
    }
}

/// Least-squares gain of the estimate against the truth over `from..`: Σ v̂·v / Σ v². An
/// estimator stuck at zero scores 0, one that tracks scores 1 whatever its noise (noise is
/// uncorrelated with v), so the bounds on worst error above cannot pass a dead estimator.
fn gain(stream: &[Obs], out: &[Option<i32>], from: usize) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (o, v) in stream.iter().zip(out).skip(from) {
        if let Some(v) = v {
            num += *v as f64 * o.v_true;
            den += o.v_true * o.v_true;
        }
    }
    num / den
}

fn max_abs(out: &[Option<i32>]) -> f64 {
    out.iter()
        .flatten()
        .map(|v| (*v as f64).abs())
        .fold(0.0, f64::max)
}

/// v → 0 with quantization: a noiseless ADC quantizes position to 16 µm steps, so at 1 mm/s a
/// step arrives every 16 ms and the rest between steps reads as zero speed. What each does:
/// - differences (diff1/4/16) and the short LSQ see 0 between steps and a spike of
///   16 µm / (window) at each step: bounded by one step per sample, 160 mm/s;
/// - long windows and the α-β filters average the staircase;
/// - the super-twisting differentiator chatters around each step;
/// - once the finger is still, every method reads exactly 0, except the I16F16 α-β, which may
///   stay inside its dead band (≤ 1.5 µm/s, see `AlphaBetaFixed`), and the super-twisting
///   differentiator, whose z₁ keeps chattering by λ₀·L·T_s per step (0.11 mm/s at L = 1 m/s²,
///   1.1 mm/s at 10 m/s²) around zero: it never comes to rest.
#[test]
fn v_to_zero_with_quantization() {
    let traj = Trajectory::Piecewise {
        pieces: vec![
            Piece {
                trajectory: Trajectory::Ramp {
                    from_um: 20_000.0,
                    v0_um_s: 5_000.0,
                    accel_um_s2: -50_000.0,
                    v_max_um_s: 5_000.0,
                },
                duration_s: 0.1,
            },
            Piece {
                trajectory: Trajectory::Rest { at_um: 20_250.0 },
                duration_s: 0.5,
            },
        ],
    };
    let s = stream(traj, 0.6, 0.0, 1);
    for m in all() {
        let out = replay(&m, &s, T_US);
        let peak = max_abs(&out);
        // Never more than one quantization step per sample (+ the STD's chatter allowance).
        let bound = STEP_UM * 1e6 / T_US as f64 + if is(&m, "std") { 20_000.0 } else { 0.0 };
        assert!(peak <= bound, "{}: peak {peak} µm/s > {bound}", m.name);
        // Still for the last 0.3 s: zero (dead band for the fixed-point filter).
        let tail = &out[3_000..];
        let worst_tail = max_abs(tail);
        let allowed = if is(&m, "abq16") {
            2.0
        } else if m.name == "std-L1e6" {
            2.0 * 1.1 * 1e6 * T_US as f64 * 1e-6
        } else if m.name == "std-L1e7" {
            2.0 * 1.1 * 1e7 * T_US as f64 * 1e-6
        } else {
            0.0
        };
        assert!(
            worst_tail <= allowed,
            "{}: |v| {worst_tail} µm/s at rest (allowed {allowed})",
            m.name
        );
        assert!(
            tail.iter().all(Option::is_some),
            "{}: no estimate at rest",
            m.name
        );
    }
}

/// Direction reversal, instant (a triangle at 100 mm/s, which no finger does: the worst case)
/// and smooth (a sine with 100 mm/s and 1 m/s² peaks). What each does at an instant reversal:
/// FIR methods (differences, LSQ, FOAW) slew from +v to −v over their window and never
/// overshoot; the α-β filters and the super-twisting differentiator are type-2 loops and
/// overshoot (the integral of the velocity error must come back to zero). Bounded by 2·v,
/// settled to 10 mm/s (plus the 16 µm quantization seen through the method's window) within a
/// window-dependent number of samples — except the super-twisting differentiator with
/// L = 1 m/s², which is slew-limited and cannot turn round within a 0.1 s leg.
#[test]
fn direction_reversal() {
    let tri = stream(
        Trajectory::Triangle {
            a_um: 20_000.0,
            b_um: 30_000.0,
            speed_um_s: 100_000.0,
        },
        0.15,
        0.0,
        2,
    );
    // Corner at 0.1 s = sample 1 000.
    for m in all() {
        let out = replay(&m, &tri, T_US);
        let peak = max_abs(&out[200..]);
        let overshoot_ok = if is(&m, "ab") || is(&m, "abq") || is(&m, "std") || is(&m, "med3+ab") {
            peak <= 200_000.0
        } else {
            peak <= 100_000.0 + STEP_UM * 1e6 / T_US as f64
        };
        assert!(overshoot_ok, "{}: peak {peak} µm/s at the reversal", m.name);
        // Quantization: a window of n samples reads the 16 µm staircase with an error up to
        // one step per window (diff1: 160 mm/s, forever).
        let tol = 10_000.0 + STEP_UM * 1e6 / (T_US as f64 * window_samples(&m) as f64);
        if m.name == "std-L1e6" {
            // Slew-limited to λ₀·L = 1.1 m/s²: turning from +100 to −100 mm/s takes 0.18 s, longer
            // than a 0.1 s leg of this triangle. It never settles here; it stays bounded (above)
            // and moves towards the new speed at its slew rate.
            let before = out[1_000].unwrap() as f64;
            let after = out[1_400].unwrap() as f64;
            let slew = 1.1e6 * 0.04;
            assert!(
                (before - after - slew).abs() < 0.2 * slew,
                "{}: {before} → {after}",
                m.name
            );
            continue;
        }
        let n = settle_samples(&tri, &out, 1_000, tol)
            .unwrap_or_else(|| panic!("{}: never settles after the reversal", m.name));
        let limit = settle_limit(&m);
        assert!(
            n <= limit,
            "{}: settles in {n} samples (limit {limit})",
            m.name
        );
    }
    // Smooth reversal, 2 LSB: error bounded by noise and lag·a for everything but the one-sample
    // differences, whose noise alone is ~115 mm/s RMS.
    let sine = stream(
        Trajectory::Sine {
            a_um: 20_000.0,
            b_um: 40_000.0,
            period_s: std::f64::consts::PI * 20_000.0 / 100_000.0,
        },
        0.6,
        2.0,
        3,
    );
    for m in all() {
        let out = replay(&m, &sine, T_US);
        let worst = sine
            .iter()
            .zip(&out)
            .skip(500)
            .filter_map(|(o, v)| v.map(|v| (v as f64 - o.v_true).abs()))
            .fold(0.0, f64::max);
        let bound = match m.name {
            "diff1" | "foaw-end-d24-n32" | "foaw-best-d12-n32" | "foaw-best-d24-n32"
            | "foaw-best-d32-n32" | "foaw-end-d48-n32" => 1_000_000.0,
            "diff4" => 250_000.0,
            _ => 100_000.0,
        };
        assert!(
            worst <= bound,
            "{}: worst {worst} µm/s on a smooth reversal",
            m.name
        );
        // The bounds above are at or above the sine's 100 mm/s peak: a zero output would pass
        // them. The gain cannot be passed that way.
        let g = gain(&sine, &out, 500);
        assert!(
            (0.98..=1.02).contains(&g),
            "{}: gain {g:.3} on the sine",
            m.name
        );
    }
}

/// The span, in samples, a method's estimate rests on (2 × its declared delay, at least 1).
fn window_samples(m: &Method) -> usize {
    let e = (m.build)(T_US);
    ((2 * e.group_delay_us() / T_US) as usize).max(1)
}

/// Samples to settle within 10 mm/s after an instant reversal: a window and a bit for FIR
/// methods, several time constants for the recursive ones.
fn settle_limit(m: &Method) -> usize {
    let e = (m.build)(T_US);
    let delay_samples = (e.group_delay_us() / T_US) as usize;
    if is(m, "foaw") || is(m, "med3+foaw") {
        // The window collapses at the corner: a few samples.
        40
    } else if is(m, "std") {
        200
    } else if is(m, "ab") || is(m, "abq") || is(m, "med3+ab") {
        4 * delay_samples + 20
    } else {
        // Windows: 2·delay + 1 samples span the window.
        2 * delay_samples + 4
    }
}

/// A sensor rail mid-stroke (open wiper for 3 ms at 50 mm/s): the controller resets the
/// estimator on the fault, so the first estimates after it come from clean samples only, after
/// each method's warm-up. Without the reset an estimator would differentiate the jump to 0 µm.
#[test]
fn sensor_rail_mid_stroke() {
    let mut spec = Spec::new(
        Trajectory::Constant {
            from_um: 10_000.0,
            speed_um_s: 50_000.0,
        },
        0.3,
        2.0,
        10_000,
    );
    spec.seed = 4;
    let mut s = spec.generate();
    // The fault: samples 1 000 .. 1 030 read the low rail (host_sim::adc's `FaultKind::Open`),
    // which the position stage reports as a fault.
    for o in &mut s[1_000..1_030] {
        o.input = Input::Fault;
    }
    for m in all() {
        let out = replay(&m, &s, T_US);
        assert!(out[1_000..1_030].iter().all(Option::is_none), "{}", m.name);
        let first = (1_030..s.len()).find(|&i| out[i].is_some()).unwrap();
        assert!(
            first - 1_030 <= 80,
            "{}: {} samples to resume",
            m.name,
            first - 1_030
        );
        let tol = match m.name {
            // FOAW: a noise sample outside the band collapses the window to a few samples.
            "diff1" => 700_000.0,
            _ if is(&m, "foaw") => 700_000.0,
            "diff4" => 200_000.0,
            _ if is(&m, "std") => 60_000.0,
            _ => 50_000.0,
        };
        let worst = (first..s.len())
            .filter_map(|i| out[i].map(|v| (v as f64 - s[i].v_true).abs()))
            .fold(0.0, f64::max);
        assert!(
            worst <= tol,
            "{}: worst {worst} µm/s after the fault",
            m.name
        );
        // The tolerances are at or above the 50 mm/s being measured: a zero output would pass
        // them. The mean over the stroke's last 0.1 s must be the speed (the super-twisting
        // differentiators restart from rest and slew up at λ₀·L: 45 ms to 50 mm/s at L = 1 m/s²).
        let after: Vec<f64> = out[2_000..].iter().flatten().map(|v| *v as f64).collect();
        let mean = after.iter().sum::<f64>() / after.len() as f64;
        assert!(
            (mean - 50_000.0).abs() <= 2_500.0,
            "{}: mean {mean} µm/s after the fault at 50 mm/s",
            m.name
        );
    }
    // Without the reset: the default differentiates the 30 mm jump to the rail.
    let mut no_reset = s.clone();
    for o in &mut no_reset[1_000..1_030] {
        o.input = Input::Position(0);
    }
    let lsq = all().into_iter().find(|m| m.name == "lsq32").unwrap();
    let out = replay(&lsq, &no_reset, T_US);
    assert!(
        max_abs(&out) > 1_000_000.0,
        "the jump to the rail reads as > 1 m/s"
    );
}

/// One outlier of +2 mm at 20 mm/s (noiseless, quantized). Linear methods pass it with their
/// largest weight (diff1: 2 mm / 100 µs = 20 m/s; lsq32: 6·31/(32·1023) → 114 mm/s) and forget it
/// after their window (α-β: decays over several delays). FOAW's windows collapse to 1 sample at
/// the spike: it reads 20 m/s like diff1. The median-of-3 wrappers never see it. The
/// super-twisting differentiator is slew-limited (z₁ moves ≤ λ₀·L·T_s per sample), so a single
/// spike moves it by a few mm/s only: robust here, for the same reason it cannot follow fast
/// speed changes.
#[test]
fn outlier_spike() {
    let mut s = ramp(2_000, 2, |k| k * T_US);
    if let Input::Position(x) = s[1_000].input {
        s[1_000].input = Input::Position(x + 2_000);
    }
    for m in all() {
        let out = replay(&m, &s, T_US);
        let worst = (1_000..s.len())
            .filter_map(|i| out[i].map(|v| (v as f64 - s[i].v_true).abs()))
            .fold(0.0, f64::max);
        if is(&m, "med3") {
            assert!(
                worst <= 1_000.0,
                "{}: the median let {worst} µm/s through",
                m.name
            );
        } else if is(&m, "std") {
            // Measured 2.0 mm/s (L = 1 m/s²) and 12.3 mm/s (L = 10 m/s²); noiseless, so the
            // bound is the larger plus 0.7 mm/s.
            assert!(worst <= 13_000.0, "{}: {worst} µm/s from one spike", m.name);
        } else {
            assert!(
                worst <= 2_000.0 * 1e6 / T_US as f64 + 1.0,
                "{}: {worst}",
                m.name
            );
            assert!(
                worst >= 10_000.0,
                "{}: a 2 mm spike must show ({worst})",
                m.name
            );
        }
        // The figures docs/estimators.md gives, worked by hand: diff1 and the collapsed FOAW
        // windows read 2 mm / 100 µs = 20 m/s; lsq32 weighs its newest sample by
        // 6·31/(32·1023) per period, 2 mm × 6·31/(32·1023) / 100 µs = 113.64 mm/s (output in
        // whole µm/s, hence ± 1).
        if m.name == "diff1" || is(&m, "foaw") {
            assert_eq!(worst, 20_000_000.0, "{}", m.name);
        }
        if m.name == "lsq32" {
            let want = 2_000.0 * 6.0 * 31.0 / (32.0 * 1023.0) / (T_US as f64 * 1e-6);
            assert!((worst - want).abs() <= 1.0, "lsq32: {worst} against {want}");
        }
        let n = settle_samples(&s, &out, 1_000, 5_000.0)
            .unwrap_or_else(|| panic!("{}: never recovers from the spike", m.name));
        let limit = if is(&m, "foaw") || is(&m, "med3+foaw") {
            80
        } else {
            settle_limit(&m) + 60
        };
        assert!(
            n <= limit,
            "{}: {n} samples to recover (limit {limit})",
            m.name
        );
    }
}

/// One dropped sample at 30 mm/s (exact ramp). Every estimator counts slots: it sees a step of
/// two periods and stays exact through it (`LsqSlope` fills the lost slot on the line between
/// its neighbours), with an estimate on every sample after the drop.
#[test]
fn dropped_sample() {
    let mut s = ramp(1_500, 3, |k| k * T_US);
    s[1_000].input = Input::Dropped;
    for m in all() {
        let out = replay(&m, &s, T_US);
        let tol = if is(&m, "std") {
            3_300.0
        } else if is(&m, "abq16") {
            2.0
        } else {
            0.5
        };
        for (i, v) in out.iter().enumerate().skip(700) {
            if i == 1_000 {
                continue;
            }
            match *v {
                Some(v) => assert!(
                    (v as f64 - 30_000.0).abs() <= tol,
                    "{} at {i}: {v} µm/s",
                    m.name
                ),
                None => panic!("{} at {i}: no estimate", m.name),
            }
        }
    }
}

/// Timestamps jittered by up to ±30 µs around a regular 10 kHz grid (the ADC is timer-triggered;
/// only the stamps are late or early). Every estimator rounds to the grid (the slot clock) and
/// gives exactly the jitter-free output. Beyond ±50 µs the slot count itself can be wrong:
/// outputs stay bounded.
#[test]
fn timestamp_jitter() {
    // Uniform jitter 0..=60 µm from a fixed LCG sequence.
    let mut state = 7u32;
    let jitter: Vec<u32> = (0..3_000)
        .map(|_| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 16) % 61
        })
        .collect();
    let clean = ramp(3_000, 3, |k| k * T_US);
    let jittered = ramp(3_000, 3, |k| k * T_US + 1_000 + jitter[k as usize] - 30);
    for m in all() {
        let a = replay(&m, &clean, T_US);
        let b = replay(&m, &jittered, T_US);
        assert_eq!(a[200..], b[200..], "{}: jitter changed the output", m.name);
    }
    // ±80 µs: slots miscounted now and then. Bounded by the slot arithmetic: a one-slot error on
    // a window of n slots mis-scales by at most 2× — diff1 can read 2 or ½ the speed, or hold.
    let wild = ramp(3_000, 3, |k| {
        k * T_US + 1_000 + jitter[k as usize] * 160 / 60 - 80
    });
    for m in all() {
        let out = replay(&m, &wild, T_US);
        let peak = max_abs(&out);
        assert!(
            peak <= 3.0 * 30_000.0,
            "{}: {peak} µm/s under ±80 µs jitter",
            m.name
        );
    }
}

/// Speeds where V/λ exceeds half the sample rate: for a fine grating (λ = 100 µm) at 1 m/s the
/// ridges pass at 10 kHz, twice the Nyquist rate of the 10 kHz loop. Velocity itself does not
/// alias — it is the rate of a smooth position — so every linear estimator stays exact and the
/// velocity-synthesis renderer gets the right f = V/λ; only a renderer that counts ridges from
/// sampled positions would miss crossings. The super-twisting differentiator is slew-limited
/// (z₁ moves at most λ₀·L per second): from rest it needs 1 m/s ÷ 1.1 m/s² ≈ 0.9 s (L = 1 m/s²) or
/// 91 ms (L = 10 m/s²) to reach 1 m/s, longer than the 60 ms the stroke lasts, so it reads too
/// low — bounded, never above V.
#[test]
fn speed_beyond_the_grating_nyquist_rate() {
    let s = stream(
        Trajectory::Constant {
            from_um: 1_500.0,
            speed_um_s: 1_000_000.0,
        },
        0.06,
        2.0,
        5,
    );
    for m in all() {
        let out = replay(&m, &s, T_US);
        let tail: Vec<f64> = out[100..].iter().flatten().map(|v| *v as f64).collect();
        assert!(!tail.is_empty(), "{}", m.name);
        let mean = tail.iter().sum::<f64>() / tail.len() as f64;
        if is(&m, "std") {
            assert!(
                mean < 700_000.0 && max_abs(&out) <= 1_050_000.0,
                "{}: {mean}",
                m.name
            );
        } else {
            assert!(
                (mean - 1_000_000.0).abs() < 20_000.0,
                "{}: mean {mean} µm/s at 1 m/s",
                m.name
            );
        }
    }
    // A ridge-counting renderer sampling positions at 10 kHz sees one 100 µm ridge per sample
    // here (V·T/λ = 1), the limit it can represent; the estimate gives f = V/λ directly. The
    // stream is what the test claims: positions advance 100 µm per sample (± the ADC's noise
    // and 16 µm steps, averaged over the stroke).
    let positions: Vec<f64> = s
        .iter()
        .filter_map(|o| match o.input {
            Input::Position(p) => Some(p as f64),
            _ => None,
        })
        .collect();
    let per_sample = (positions[positions.len() - 1] - positions[0]) / (positions.len() - 1) as f64;
    assert!(
        (per_sample - 100.0).abs() <= 1.0,
        "{per_sample} µm per sample"
    );
}

/// The 40 delay-probe streams the bench (`host-sim bench --seed base_seed`, "lag @20") makes:
/// 5 mm/s, then 0.5 m/s² up to 35 mm/s, 2 LSB, 10 kHz, scored only while the true speed passes
/// 15–25 mm/s accelerating.
fn delay_probe_streams(base_seed: u64) -> Vec<Vec<Obs>> {
    (0..40)
        .map(|i| {
            let (t, d) = scenario::delay_probe();
            let mut s = Spec::new(t, d, 2.0, 10_000);
            s.seed = base_seed.wrapping_mul(31).wrapping_add(200 + i);
            let mut st = s.generate();
            for o in &mut st {
                o.scored = (15_000.0..=25_000.0).contains(&o.v_true) && o.a_true > 0.0;
            }
            st
        })
        .collect()
}

/// The 2 streams of the bench's outliers-and-drops scenario ("outl+drop"): the reference motion
/// with ±2 mm single-sample outliers (p = 10⁻³) and dropped samples (p = 2·10⁻³), 2 LSB, 10 kHz.
fn outlier_streams(base_seed: u64) -> Vec<Vec<Obs>> {
    (0..2)
        .map(|i| {
            let mut s = reference_spec(0);
            s.seed = base_seed.wrapping_mul(31).wrapping_add(400 + i);
            s.outlier_prob = 1e-3;
            s.drop_prob = 2e-3;
            s.generate()
        })
        .collect()
}

fn method(name: &str) -> Method {
    all().into_iter().find(|m| m.name == name).unwrap()
}

/// Base seeds the bench figures below are measured over: the bench's default (2026), 1 and 2.
/// README.md and docs/estimators.md state the range, or the worst, over these three. Three, not
/// more, to keep this file under 10 s in debug (each seed costs about 1 s here). The stated
/// figures are worst-of-3, not bounds: seeds 3–7 (`host-sim bench --seed N`, measured once while
/// writing this) stay inside the 2 ms target but reach a lag of 1.57–1.70 ms, 24.1 mm/s with the
/// median (seed 5) and 180.5 mm/s without it (seed 3).
const BENCH_SEEDS: [u64; 3] = [2026, 1, 2];

/// Lag of the default estimator at 20 mm/s, pooled over each base seed's 40 delay-probe streams.
/// Expected (worked by hand, not by the code under test): the 32-sample least-squares slope is
/// centred (32 − 1)/2 = 15.5 samples back and the median of 3 adds one sample, 16.5 × 100 µs =
/// 1.65 ms. Measured 1.61–1.65 ms over the three seeds (1.65 ms on 2026, the bench's table);
/// asserted: each seed within 1.60–1.66 ms (the stated range ± 0.01 ms of rounding), their mean
/// within 0.03 ms of 1.65 ms (measured 1.633), and each under the 2 ms target.
#[test]
fn default_estimator_lag_at_20_mm_s() {
    let m = method(saw_core_default());
    let mut lags = Vec::new();
    for seed in BENCH_SEEDS {
        let parts: Vec<_> = delay_probe_streams(seed)
            .iter()
            .map(|s| errors(s, &replay(&m, s, T_US)))
            .collect();
        let lag_ms = pool(&parts).lag_us / 1_000.0;
        eprintln!("seed {seed}: lag {lag_ms:.3} ms");
        assert!(
            (1.60..=1.66).contains(&lag_ms) && lag_ms <= 2.0,
            "seed {seed}: lag {lag_ms:.3} ms, docs say 1.61–1.65"
        );
        lags.push(lag_ms);
    }
    let mean = lags.iter().sum::<f64>() / lags.len() as f64;
    eprintln!("mean lag over {} seeds: {mean:.3} ms", lags.len());
    assert!((mean - 1.65).abs() <= 0.03, "mean lag {mean:.3} ms");
}

/// Worst velocity error under single-sample ±2 mm outliers and dropped samples (the bench's
/// "outl+drop"), worst of the two streams per base seed, with and without the median. Measured
/// over the three seeds: default 21.0–22.1 mm/s (22.1 on 2026), `LsqSlope<32>` alone
/// 130.4–167.3 mm/s (130.4 on 2026); the median cuts the worst by 5.9–8.0× per seed. Asserted on
/// every seed: default ≤ 22.5 mm/s and bare slope ≤ 168 mm/s (the stated worst-of-3, 22.1 and
/// 167.3 mm/s, plus rounding), and at least 5.5× between them.
#[test]
fn median_keeps_outliers_out_of_the_slope() {
    let med = method(saw_core_default());
    let lsq = method("lsq32");
    let (mut worst_med, mut worst_lsq) = (0.0f64, 0.0f64);
    for seed in BENCH_SEEDS {
        let streams = outlier_streams(seed);
        let worst = |m: &Method| {
            streams
                .iter()
                .map(|s| errors(s, &replay(m, s, T_US)).worst_um_s / 1_000.0)
                .fold(0.0, f64::max)
        };
        let (w_med, w_lsq) = (worst(&med), worst(&lsq));
        eprintln!("seed {seed}: worst {w_med:.1} mm/s with the median, {w_lsq:.1} without");
        assert!(
            w_med <= 22.5,
            "seed {seed}: {w_med:.1} mm/s with the median"
        );
        assert!(
            w_lsq <= 168.0,
            "seed {seed}: {w_lsq:.1} mm/s without the median"
        );
        assert!(
            w_lsq >= 5.5 * w_med,
            "seed {seed}: {w_lsq:.1} against {w_med:.1}"
        );
        worst_med = worst_med.max(w_med);
        worst_lsq = worst_lsq.max(w_lsq);
    }
    eprintln!(
        "worst of {}: {worst_med:.1} mm/s with the median, {worst_lsq:.1} without",
        BENCH_SEEDS.len()
    );
}

/// The bench's name of the controller's default estimator, `Median3<LsqSlope<32>>`.
fn saw_core_default() -> &'static str {
    host_sim::bench::methods::DEFAULT
}
