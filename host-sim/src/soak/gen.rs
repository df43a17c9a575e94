//! Random scenes, trajectories and sensor faults for the system fuzz (`tests/tests/safety_fuzz.rs`)
//! and the soak ([`crate::soak`]): every texture kind, tangible lines with both envelopes, both
//! drive modes, random boundaries and caps; finger motions from rest to 2 m/s strokes; the ADC's
//! fault kinds; and scenes broken on purpose, which a load must refuse.
//!
//! The fuzz's generators ([`random_config`], [`random_trajectory`], [`random_faults`]) keep the
//! order of their draws: a fuzz seed's cases stay the same when code around them changes.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use saw_core::burst::{BurstCommand, SafetyLimits};
use saw_core::gate::DriveMode;
use saw_core::texture::{Envelope, Grating, GratingRender, Lines, Material, RandomBurst, Texture};
use saw_core::Config;

use crate::adc::{FaultKind, FaultWindow};
use crate::trajectory::{Piece, Trajectory};

/// A draw from `lo..hi` spread evenly over the decades (frequencies, speeds, durations).
pub fn log_uniform(rng: &mut ChaCha8Rng, lo: f64, hi: f64) -> f64 {
    lo * (hi / lo).powf(rng.random::<f64>())
}

/// A duty for a texture: usually within the cap (planned up to it), now and then above it (the
/// load must refuse it).
fn duty(rng: &mut ChaCha8Rng, cap: u16) -> u16 {
    if rng.random_bool(0.03) {
        rng.random_range(1..=1000)
    } else if rng.random_bool(0.3) {
        cap
    } else {
        rng.random_range(1..=cap)
    }
}

fn min_speed(rng: &mut ChaCha8Rng) -> u32 {
    if rng.random_bool(0.3) {
        0
    } else {
        rng.random_range(0..=40_000)
    }
}

/// One region's texture, of any kind, for a board whose f_b tops out at `max_hz`, under a duty
/// cap of `cap` ‰.
pub fn random_texture(rng: &mut ChaCha8Rng, max_hz: u32, cap: u16) -> Texture {
    match rng.random_range(0..11) {
        0 => Texture::Off,
        1 | 2 => Texture::Constant(BurstCommand {
            burst_millihz: (log_uniform(rng, 0.5, max_hz as f64) * 1000.0) as u32,
            duty_permille: duty(rng, cap),
        }),
        3..=6 => {
            let position = rng.random_bool(0.5);
            let wavelength_um = log_uniform(rng, 150.0, 12_000.0) as u32;
            Texture::Grating(Grating {
                wavelength_um,
                duty_permille: duty(rng, cap),
                min_speed_um_s: min_speed(rng),
                amplitude_permille: rng.random_range(1..=1000),
                render: if position {
                    // Position phase or the hybrid (position phase with predicted crossings).
                    if rng.random_bool(0.5) {
                        GratingRender::Hybrid
                    } else {
                        GratingRender::PositionPhase
                    }
                } else {
                    GratingRender::VelocitySynthesis
                },
                // Below half the period, as the position renderer requires.
                rearm_um: rng.random_range(0..wavelength_um.div_ceil(2)),
            })
        }
        7 | 8 => Texture::Material(Material {
            delta_mu: rng.random_range(0.0..1.5),
            normal_force_n: log_uniform(rng, 0.05, 5.0) as f32,
            // ω0 = √(k/m) from a few Hz to above every board's f_b limit (clamped).
            mass_kg: log_uniform(rng, 1e-5, 1e-2) as f32,
            stiffness_n_per_m: log_uniform(rng, 10.0, 1e5) as f32,
            duty_permille: duty(rng, cap),
            min_speed_um_s: min_speed(rng),
        }),
        _ => Texture::Random(RandomBurst {
            center_millihz: (log_uniform(rng, 1.0, max_hz as f64) * 1000.0) as u32,
            spread_permille: rng.random_range(0..=999),
            amplitude_permille: rng.random_range(1..=1000),
            amplitude_spread_permille: rng.random_range(0..=1000),
            duty_permille: duty(rng, cap),
            seed: rng.random(),
        }),
    }
}

/// Tangible lines (half the time none), pulses up to the on-time cap `max_on_time_us`.
pub fn random_lines(rng: &mut ChaCha8Rng, max_on_time_us: u32) -> Lines {
    let mut lines = Lines::default();
    if rng.random_bool(0.5) {
        return lines;
    }
    let mut p: Vec<u32> = (0..rng.random_range(1..=16))
        .map(|_| rng.random_range(1_000..62_000))
        .collect();
    p.sort();
    p.dedup();
    for x in p {
        // At most 16 positions, within the scene's capacity: a refusal is not possible here.
        let _ = lines.positions_um.push(x);
    }
    lines.pulse_us =
        log_uniform(rng, 50.0, max_on_time_us.max(50) as f64).min(max_on_time_us as f64) as u32;
    lines.envelope = if rng.random_bool(0.5) {
        Envelope::Triangular
    } else {
        Envelope::Rectangular
    };
    lines.amplitude_permille = rng.random_range(1..=1000);
    lines.hysteresis_um = rng.random_range(0..=2_000);
    lines
}

/// A scene of 1–8 regions at random boundaries with random textures, caps, lines, stale limit
/// and drive mode, on the default calibration. About 1 in 10 is refused at load (a duty above
/// its cap): callers count those as refusals.
pub fn random_config(rng: &mut ChaCha8Rng, max_hz: u32) -> Config {
    let mut cfg = saw_core::default_config();
    cfg.limits = SafetyLimits {
        max_duty_permille: if rng.random_bool(0.2) {
            rng.random_range(1..=1000)
        } else {
            rng.random_range(50..=600)
        },
        max_on_time_us: log_uniform(rng, 20.0, 100_000.0) as u32,
        // Full drive: the random textures draw amplitudes up to 1000 ‰ and must stay loadable.
        max_level_permille: 1000,
    };
    cfg.stale_after_us = rng.random_range(300..=10_000);
    let n = rng.random_range(1..=8usize);
    let mut b: Vec<u32> = (1..n).map(|_| rng.random_range(1_000..62_000)).collect();
    b.sort();
    cfg.scene.boundaries_um.clear();
    for x in b {
        // Fewer than the scene's region capacity: cannot be refused.
        let _ = cfg.scene.boundaries_um.push(x);
    }
    cfg.scene.hysteresis_um = rng.random_range(0..=300);
    // Lines only fire where no burst runs: scenes with lines get more bare regions.
    cfg.scene.lines = random_lines(rng, cfg.limits.max_on_time_us);
    let bare = if cfg.scene.lines.positions_um.is_empty() {
        0.0
    } else {
        0.4
    };
    cfg.scene.textures.clear();
    for _ in 0..n {
        let t = if rng.random_bool(bare) {
            Texture::Off
        } else {
            random_texture(rng, max_hz, cfg.limits.max_duty_permille)
        };
        let _ = cfg.scene.textures.push(t);
    }
    cfg.scene.drive = if rng.random_bool(0.5) {
        DriveMode::Standing
    } else {
        DriveMode::Progressive
    };
    cfg
}

/// One motion of the system fuzz: rest, strokes, sines, reversals, constant speed, ramps.
pub fn random_motion(rng: &mut ChaCha8Rng) -> Trajectory {
    let a = rng.random_range(500.0..62_500.0);
    let b = rng.random_range(500.0..62_500.0);
    let v = log_uniform(rng, 2_000.0, 400_000.0);
    match rng.random_range(0..6) {
        0 => Trajectory::Rest { at_um: a },
        1 => Trajectory::Triangle {
            a_um: a,
            b_um: b,
            speed_um_s: v,
        },
        2 => Trajectory::Sine {
            a_um: a,
            b_um: b,
            period_s: rng.random_range(0.05..1.0),
        },
        3 => Trajectory::Reversal {
            from_um: a,
            turn_um: b,
            speed_um_s: v,
        },
        4 => {
            // At most 24 mm in the 0.4 s run: stays on the substrate.
            let s = v.min(60_000.0);
            Trajectory::Constant {
                from_um: a,
                speed_um_s: if a < 31_500.0 { s } else { -s },
            }
        }
        _ => Trajectory::Ramp {
            from_um: 31_500.0,
            v0_um_s: 0.0,
            accel_um_s2: rng.random_range(-1e7..1e7),
            v_max_um_s: v,
        },
    }
}

/// A fuzz trajectory: one motion, or 2–4 pieces of them.
pub fn random_trajectory(rng: &mut ChaCha8Rng) -> Trajectory {
    if rng.random_bool(0.7) {
        return random_motion(rng);
    }
    let pieces = (0..rng.random_range(2..=4))
        .map(|_| Piece {
            trajectory: random_motion(rng),
            duration_s: rng.random_range(0.03..0.2),
        })
        .collect();
    Trajectory::Piecewise { pieces }
}

/// The fuzz's faults: up to two open, short or dropout windows in the first three quarters of
/// a run of `duration_us`.
pub fn random_faults(rng: &mut ChaCha8Rng, duration_us: u64) -> Vec<FaultWindow> {
    let n = [0, 0, 1, 1, 2][rng.random_range(0..5)];
    (0..n)
        .map(|_| {
            let start_us = rng.random_range(0..duration_us * 3 / 4);
            FaultWindow {
                kind: [FaultKind::Open, FaultKind::Short, FaultKind::Dropout]
                    [rng.random_range(0..3)],
                start_us,
                end_us: start_us + log_uniform(rng, 50.0, 40_000.0) as u64,
            }
        })
        .collect()
}

/// The soak's motions, as the issue names them (one piece of an episode's finger).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// Resting on the substrate.
    Rest,
    /// Creeping at 0.1–2 mm/s.
    Creep,
    /// Strokes back and forth at 20 mm/s to 2 m/s (2 m/s in a quarter of them).
    Stroke,
    /// A reversal at 10 m/s²: moving at up to 0.5 m/s, braking through zero and back.
    Reversal,
    /// Tremor: 20–500 µm at 6–12 Hz.
    Tremor,
    /// One of the fuzz's motions (sines, ramps, long reversals).
    Fuzz,
}

/// A piece of motion of `kind` on a travel of 63 mm.
pub fn soak_motion(rng: &mut ChaCha8Rng, kind: Motion) -> Trajectory {
    let at = rng.random_range(1_000.0..62_000.0);
    match kind {
        Motion::Rest => Trajectory::Rest { at_um: at },
        Motion::Creep => {
            let v = log_uniform(rng, 100.0, 2_000.0);
            // Heading for the far end: at most 2 mm/s × the piece stays on the travel.
            Trajectory::Constant {
                from_um: at,
                speed_um_s: if at < 31_500.0 { v } else { -v },
            }
        }
        Motion::Stroke => {
            let b = rng.random_range(1_000.0..62_000.0);
            let v = if rng.random_bool(0.25) {
                2_000_000.0
            } else {
                log_uniform(rng, 20_000.0, 2_000_000.0)
            };
            Trajectory::Triangle {
                a_um: at,
                b_um: b,
                speed_um_s: v,
            }
        }
        Motion::Reversal => {
            // 10 m/s² = 1e7 µm/s²: from v it stops after v²/2a (12.5 mm at 0.5 m/s) and is
            // back at the start, at −v, after 2v/a; the start keeps that inside the travel.
            let v = rng.random_range(50_000.0..500_000.0);
            let from = rng.random_range(14_000.0..49_000.0);
            let dir: f64 = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            Trajectory::Ramp {
                from_um: from,
                v0_um_s: dir * v,
                accel_um_s2: -dir * 1e7,
                v_max_um_s: v,
            }
        }
        Motion::Tremor => {
            let amp = log_uniform(rng, 20.0, 500.0);
            Trajectory::Sine {
                a_um: at,
                b_um: at + amp,
                period_s: 1.0 / rng.random_range(6.0..12.0),
            }
        }
        Motion::Fuzz => random_motion(rng),
    }
}

/// An episode's finger: pieces of 50–400 ms of every [`Motion`] until `duration_s` is covered
/// (the finger is lifted and set down between pieces: positions jump, as they do on a display).
pub fn soak_trajectory(rng: &mut ChaCha8Rng, duration_s: f64) -> Trajectory {
    const KINDS: [Motion; 6] = [
        Motion::Rest,
        Motion::Creep,
        Motion::Stroke,
        Motion::Reversal,
        Motion::Tremor,
        Motion::Fuzz,
    ];
    let mut pieces = Vec::new();
    let mut covered_s = 0.0;
    while covered_s < duration_s && pieces.len() < 64 {
        let kind = KINDS[rng.random_range(0..KINDS.len())];
        let d = rng.random_range(0.05..0.4);
        pieces.push(Piece {
            trajectory: soak_motion(rng, kind),
            duration_s: d,
        });
        covered_s += d;
    }
    Trajectory::Piecewise { pieces }
}

/// Fault kinds the soak injects, in the order its counters list them.
pub const SOAK_FAULTS: [&str; 7] = [
    "open",
    "short",
    "stale",
    "dropped",
    "spike",
    "drift",
    "spike-train",
];

/// The soak's sensor faults over an episode of `duration_us` sampled every `period_us`, with
/// `stale_after_us` the longest stale limit a scene may have (10 ms): 0–4 windows, each tagged
/// with its index in [`SOAK_FAULTS`]. Open and short wiper from one sample to 40 ms; stale gaps
/// longer than the stale limit; dropped samples (1–3 in a row, shorter than any limit);
/// single-sample spikes of ±50–3000 LSB; offset drift of ±2–400 LSB/s for 50 ms to 1 s; a train
/// of spikes every few samples.
pub fn soak_faults(
    rng: &mut ChaCha8Rng,
    duration_us: u64,
    period_us: u64,
    stale_after_us: u64,
) -> Vec<(usize, FaultWindow)> {
    let n = rng.random_range(0..=4);
    let mut out = Vec::new();
    for _ in 0..n {
        let tag = rng.random_range(0..SOAK_FAULTS.len());
        // On a sample's time, so a one-period window holds exactly one sample.
        let start_us = rng.random_range(0..duration_us / period_us) * period_us;
        let sign: i32 = if rng.random_bool(0.5) { 1 } else { -1 };
        let (kind, len_us) = match tag {
            0 => (
                FaultKind::Open,
                log_uniform(rng, period_us as f64, 40_000.0) as u64,
            ),
            1 => (
                FaultKind::Short,
                log_uniform(rng, period_us as f64, 40_000.0) as u64,
            ),
            2 => (
                FaultKind::Dropout,
                stale_after_us + log_uniform(rng, period_us as f64, 50_000.0) as u64,
            ),
            3 => (FaultKind::Dropout, period_us * rng.random_range(1..=3)),
            4 | 6 => (
                FaultKind::Spike {
                    offset_lsb: (sign * log_uniform(rng, 50.0, 3_000.0) as i32) as i16,
                },
                period_us,
            ),
            _ => (
                FaultKind::Drift {
                    lsb_per_s: sign * log_uniform(rng, 2.0, 400.0) as i32,
                },
                log_uniform(rng, 50_000.0, 1_000_000.0) as u64,
            ),
        };
        if tag == 6 {
            // A spike train: one-sample spikes every 2–20 samples for 2–10 spikes.
            let every = period_us * rng.random_range(2..=20);
            for i in 0..rng.random_range(2..=10u64) {
                let s = start_us + i * every;
                out.push((
                    tag,
                    FaultWindow {
                        kind,
                        start_us: s,
                        end_us: s + len_us,
                    },
                ));
            }
        } else {
            out.push((
                tag,
                FaultWindow {
                    kind,
                    start_us,
                    end_us: start_us + len_us.max(1),
                },
            ));
        }
    }
    out
}

/// Ways a scene is broken on purpose, each refused by the core's load (the names print in the
/// summary).
pub const BROKEN: [&str; 6] = [
    "duty above the cap",
    "boundaries out of order",
    "boundary past the travel",
    "stale limit below two samples",
    "one texture too few",
    "duty cap of 0",
];

/// `cfg` broken in one of the [`BROKEN`] ways (its index returned): the core must refuse it and
/// keep the scene it runs.
pub fn broken_config(rng: &mut ChaCha8Rng, cfg: &Config) -> (usize, Config) {
    let mut bad = cfg.clone();
    let mut how = rng.random_range(0..BROKEN.len());
    // Order needs two boundaries; fall back to the duty when the scene has fewer.
    if how == 1 && bad.scene.boundaries_um.len() < 2 {
        how = 0;
    }
    match how {
        0 => {
            let cap = bad.limits.max_duty_permille;
            let over = rng.random_range(cap.saturating_add(1).min(1000)..=1000);
            if cap >= 1000 {
                // No duty lies above a 100 % cap: one above 100 % instead.
                bad.limits.max_duty_permille = 1001;
            }
            let i = rng.random_range(0..bad.scene.textures.len().max(1));
            if let Some(t) = bad.scene.textures.get_mut(i) {
                *t = Texture::Constant(BurstCommand {
                    burst_millihz: 20_000,
                    duty_permille: over.max(1),
                });
            }
        }
        // A loaded scene's boundaries rise strictly: swapped, the first two fall.
        1 => bad.scene.boundaries_um.swap(0, 1),
        2 => {
            let len = bad.calibration.length_um;
            match bad.scene.boundaries_um.last_mut() {
                Some(b) => *b = len + rng.random_range(0..10_000),
                None => {
                    let _ = bad.scene.boundaries_um.push(len);
                    let _ = bad.scene.textures.push(Texture::Off);
                }
            }
        }
        3 => bad.stale_after_us = rng.random_range(0..200),
        4 => {
            let _ = bad.scene.textures.pop();
        }
        _ => bad.limits.max_duty_permille = 0,
    }
    (how, bad)
}
