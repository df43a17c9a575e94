//! Finger trajectories: position (µm) and true velocity (µm/s) as closed-form functions of time.
//!
//! Positions are along the substrate from its start end. Trajectories are not clamped to the
//! substrate: a scene that drives the finger past an end is the caller's mistake, and the ADC
//! model clamps the reading like the real rheostat does.

use serde::Deserialize;

/// A finger motion. Time `t_s` starts at 0 at the beginning of the trajectory.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Trajectory {
    /// At rest at `at_um`.
    Rest {
        /// Position, µm.
        at_um: f64,
    },
    /// Constant speed from `from_um` (negative speed moves towards the start end).
    Constant {
        /// Start position, µm.
        from_um: f64,
        /// Speed, µm/s.
        speed_um_s: f64,
    },
    /// Back and forth between `a_um` and `b_um` at constant speed (a triangle wave), starting at
    /// `a_um` heading for `b_um`.
    Triangle {
        /// First turning point (start), µm.
        a_um: f64,
        /// Second turning point, µm.
        b_um: f64,
        /// Speed, µm/s (> 0).
        speed_um_s: f64,
    },
    /// Back and forth between `a_um` and `b_um` as a sine, starting at `a_um` at rest.
    Sine {
        /// First turning point (start), µm.
        a_um: f64,
        /// Second turning point, µm.
        b_um: f64,
        /// Full period (there and back), s.
        period_s: f64,
    },
    /// One reversal: from `from_um` to `turn_um` at `speed_um_s`, then back forever.
    Reversal {
        /// Start position, µm.
        from_um: f64,
        /// Turning point, µm.
        turn_um: f64,
        /// Speed, µm/s (> 0).
        speed_um_s: f64,
    },
    /// Constant acceleration from `v0_um_s` until the speed reaches `v_max_um_s` (magnitude),
    /// then constant speed.
    Ramp {
        /// Start position, µm.
        from_um: f64,
        /// Initial velocity, µm/s.
        v0_um_s: f64,
        /// Acceleration, µm/s² (10 m/s² = 1e7).
        accel_um_s2: f64,
        /// Speed limit, µm/s (> 0).
        v_max_um_s: f64,
    },
    /// Pieces played one after another, each for its duration with its own time origin.
    Piecewise {
        /// (trajectory, duration in s).
        pieces: Vec<Piece>,
    },
}

/// One piece of a piecewise trajectory.
#[derive(Clone, Debug, PartialEq, Deserialize)]
pub struct Piece {
    /// The motion of this piece.
    pub trajectory: Trajectory,
    /// How long it lasts, s.
    pub duration_s: f64,
}

/// A triangle's (position µm, velocity µm/s) at `t` ≥ 0 s: [`Trajectory::state`] and
/// [`Trajectory::states_into`] share it, so a block gives the very same values.
#[inline(always)]
fn triangle_at(a_um: f64, b_um: f64, speed_um_s: f64, t: f64) -> (f64, f64) {
    match triangle_legs(a_um, b_um, speed_um_s) {
        None => (a_um, 0.0),
        Some((dir, leg_s)) => {
            let phase = triangle_phase(t, leg_s);
            triangle_in_phase(a_um, b_um, speed_um_s, dir, leg_s, phase, t)
        }
    }
}

/// A moving triangle's direction from `a_um` to `b_um` (±1) and the time one leg takes, s
/// (None when it stands still).
#[inline(always)]
fn triangle_legs(a_um: f64, b_um: f64, speed_um_s: f64) -> Option<(f64, f64)> {
    let span = (b_um - a_um).abs();
    if span == 0.0 || speed_um_s <= 0.0 {
        None
    } else {
        Some(((b_um - a_um).signum(), span / speed_um_s))
    }
}

/// The leg (0, 1, …) `t` ≥ 0 s falls in: rounded `t / leg_s`, truncated. It never decreases as
/// `t` grows (the division is correctly rounded), so two times in the same leg have every time
/// between them in it too.
#[inline(always)]
fn triangle_phase(t: f64, leg_s: f64) -> u64 {
    (t / leg_s) as u64
}

/// A triangle's (position µm, velocity µm/s) at `t` s in leg `phase` ([`triangle_phase`]).
#[inline(always)]
fn triangle_in_phase(
    a_um: f64,
    b_um: f64,
    speed_um_s: f64,
    dir: f64,
    leg_s: f64,
    phase: u64,
    t: f64,
) -> (f64, f64) {
    let within = t - phase as f64 * leg_s;
    if phase.is_multiple_of(2) {
        (a_um + dir * speed_um_s * within, dir * speed_um_s)
    } else {
        (b_um - dir * speed_um_s * within, -dir * speed_um_s)
    }
}

/// Position and velocity at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State {
    /// Position, µm.
    pub position_um: f64,
    /// Velocity, µm/s.
    pub velocity_um_s: f64,
}

impl Trajectory {
    /// Position and velocity at `t_s` ≥ 0.
    pub fn state(&self, t_s: f64) -> State {
        let t = t_s.max(0.0);
        let (position_um, velocity_um_s) = match self {
            Trajectory::Rest { at_um } => (*at_um, 0.0),
            Trajectory::Constant {
                from_um,
                speed_um_s,
            } => (from_um + speed_um_s * t, *speed_um_s),
            Trajectory::Triangle {
                a_um,
                b_um,
                speed_um_s,
            } => triangle_at(*a_um, *b_um, *speed_um_s, t),
            Trajectory::Sine {
                a_um,
                b_um,
                period_s,
            } => {
                let mid = (a_um + b_um) / 2.0;
                let amp = (b_um - a_um) / 2.0;
                let w = 2.0 * std::f64::consts::PI / period_s;
                (mid - amp * (w * t).cos(), amp * w * (w * t).sin())
            }
            Trajectory::Reversal {
                from_um,
                turn_um,
                speed_um_s,
            } => {
                let dir = (turn_um - from_um).signum();
                let t_turn = (turn_um - from_um).abs() / speed_um_s;
                if t < t_turn {
                    (from_um + dir * speed_um_s * t, dir * speed_um_s)
                } else {
                    (turn_um - dir * speed_um_s * (t - t_turn), -dir * speed_um_s)
                }
            }
            Trajectory::Ramp {
                from_um,
                v0_um_s,
                accel_um_s2,
                v_max_um_s,
            } => {
                let a = *accel_um_s2;
                let vmax = v_max_um_s.abs();
                let v_unclamped = v0_um_s + a * t;
                if a == 0.0 || v_unclamped.abs() <= vmax {
                    (from_um + v0_um_s * t + 0.5 * a * t * t, v_unclamped)
                } else {
                    // Time at which |v| reaches vmax in the direction of the acceleration.
                    let v_end = vmax * a.signum();
                    let t_sat = ((v_end - v0_um_s) / a).max(0.0);
                    let x_sat = from_um + v0_um_s * t_sat + 0.5 * a * t_sat * t_sat;
                    (x_sat + v_end * (t - t_sat), v_end)
                }
            }
            Trajectory::Piecewise { pieces } => {
                let mut start = 0.0;
                for (i, p) in pieces.iter().enumerate() {
                    if t < start + p.duration_s || i + 1 == pieces.len() {
                        let s = p.trajectory.state(t - start);
                        return s;
                    }
                    start += p.duration_s;
                }
                (0.0, 0.0)
            }
        };
        State {
            position_um,
            velocity_um_s,
        }
    }

    /// The states at the sample times (`k0` + i) × `period_us` µs for i in 0..`n`, into `out`
    /// (cleared first): what [`Self::state`] gives at each, with the kind matched once for the
    /// block (the closed loop's default triangle in a loop the compiler keeps free of the
    /// match and the call).
    pub fn states_into(&self, k0: u64, period_us: u32, n: usize, out: &mut Vec<State>) {
        out.clear();
        let t_s = |i: usize| ((k0 + i as u64) * period_us as u64) as f64 * 1e-6;
        match self {
            Trajectory::Triangle {
                a_um,
                b_um,
                speed_um_s,
            } => {
                let (a_um, b_um, speed_um_s) = (*a_um, *b_um, *speed_um_s);
                let legs = triangle_legs(a_um, b_um, speed_um_s);
                let phases = legs.filter(|_| n > 0).map(|(_, leg_s)| {
                    let phase = |i| triangle_phase(t_s(i).max(0.0), leg_s);
                    (phase(0), phase(n - 1))
                });
                match (legs, phases) {
                    // The whole block in one leg (the phase never decreases): no division a
                    // sample, the same values.
                    (Some((dir, leg_s)), Some((first, last))) if first == last => {
                        out.extend((0..n).map(|i| {
                            let t = t_s(i).max(0.0);
                            let (position_um, velocity_um_s) =
                                triangle_in_phase(a_um, b_um, speed_um_s, dir, leg_s, first, t);
                            State {
                                position_um,
                                velocity_um_s,
                            }
                        }))
                    }
                    _ => out.extend((0..n).map(|i| {
                        let (position_um, velocity_um_s) =
                            triangle_at(a_um, b_um, speed_um_s, t_s(i).max(0.0));
                        State {
                            position_um,
                            velocity_um_s,
                        }
                    })),
                }
            }
            _ => out.extend((0..n).map(|i| self.state(t_s(i)))),
        }
    }

    /// Total duration for a piecewise trajectory, None for the unbounded kinds.
    pub fn duration_s(&self) -> Option<f64> {
        match self {
            Trajectory::Piecewise { pieces } => Some(pieces.iter().map(|p| p.duration_s).sum()),
            _ => None,
        }
    }

    /// Short name for reports.
    pub fn describe(&self) -> String {
        match self {
            Trajectory::Rest { at_um } => format!("rest at {:.3} mm", at_um / 1e3),
            Trajectory::Constant {
                from_um,
                speed_um_s,
            } => format!(
                "constant {:.1} mm/s from {:.3} mm",
                speed_um_s / 1e3,
                from_um / 1e3
            ),
            Trajectory::Triangle {
                a_um,
                b_um,
                speed_um_s,
            } => format!(
                "back-and-forth (triangle) {:.1}–{:.1} mm at {:.1} mm/s",
                a_um / 1e3,
                b_um / 1e3,
                speed_um_s / 1e3
            ),
            Trajectory::Sine {
                a_um,
                b_um,
                period_s,
            } => format!(
                "back-and-forth (sine) {:.1}–{:.1} mm, period {:.2} s",
                a_um / 1e3,
                b_um / 1e3,
                period_s
            ),
            Trajectory::Reversal {
                from_um,
                turn_um,
                speed_um_s,
            } => format!(
                "reversal {:.1} → {:.1} mm and back at {:.1} mm/s",
                from_um / 1e3,
                turn_um / 1e3,
                speed_um_s / 1e3
            ),
            Trajectory::Ramp {
                from_um,
                v0_um_s,
                accel_um_s2,
                v_max_um_s,
            } => format!(
                "ramp from {:.1} mm, v0 {:.1} mm/s, a {:.2} m/s², vmax {:.1} mm/s",
                from_um / 1e3,
                v0_um_s / 1e3,
                accel_um_s2 / 1e6,
                v_max_um_s / 1e3
            ),
            Trajectory::Piecewise { pieces } => format!("{} pieces", pieces.len()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block of states is what the state at each time gives, bit for bit, for every kind
    /// (the triangle's own loop and the others'), from a block that starts mid-run.
    #[test]
    fn a_block_of_states_is_the_state_at_each_time() {
        let kinds = [
            Trajectory::Triangle {
                a_um: 1_500.0,
                b_um: 61_500.0,
                speed_um_s: 60_000.0,
            },
            Trajectory::Triangle {
                a_um: 40_000.0,
                b_um: 10_000.0,
                speed_um_s: 333_333.3,
            },
            Trajectory::Sine {
                a_um: 0.0,
                b_um: 63_000.0,
                period_s: 0.7,
            },
            Trajectory::Ramp {
                from_um: 1_000.0,
                v0_um_s: 0.0,
                accel_um_s2: 2e6,
                v_max_um_s: 60_000.0,
            },
        ];
        let mut out = Vec::new();
        for tr in &kinds {
            for (k0, period_us) in [(0, 100), (123_457, 100), (7, 50)] {
                tr.states_into(k0, period_us, 3_000, &mut out);
                assert_eq!(out.len(), 3_000);
                for (i, s) in out.iter().enumerate() {
                    let t_s = ((k0 + i as u64) * period_us as u64) as f64 * 1e-6;
                    let want = tr.state(t_s);
                    assert_eq!(
                        s.position_um.to_bits(),
                        want.position_um.to_bits(),
                        "{tr:?}"
                    );
                    assert_eq!(s.velocity_um_s.to_bits(), want.velocity_um_s.to_bits());
                }
            }
        }
    }

    /// Blocks short enough that most lie in one leg (which skip the per-sample division)
    /// and some straddle a turn give the state at each time, bit for bit: legs that end on a
    /// sample time and between two.
    #[test]
    fn blocks_within_a_leg_are_the_state_at_each_time() {
        let kinds = [
            // A leg of 1 s: turns on sample times.
            Trajectory::Triangle {
                a_um: 1_500.0,
                b_um: 61_500.0,
                speed_um_s: 60_000.0,
            },
            // A leg of 0.090000009 s: turns between samples.
            Trajectory::Triangle {
                a_um: 40_000.0,
                b_um: 10_000.0,
                speed_um_s: 333_333.3,
            },
        ];
        let mut out = Vec::new();
        for tr in &kinds {
            let (mut k0, mut turns) = (0u64, 0);
            for n in (0..4_000).map(|b| 17 + (b * 7) % 50) {
                tr.states_into(k0, 100, n, &mut out);
                assert_eq!(out.len(), n);
                for (i, s) in out.iter().enumerate() {
                    let t_s = ((k0 + i as u64) * 100) as f64 * 1e-6;
                    let want = tr.state(t_s);
                    assert_eq!(
                        s.position_um.to_bits(),
                        want.position_um.to_bits(),
                        "{tr:?} at {t_s} s"
                    );
                    assert_eq!(s.velocity_um_s.to_bits(), want.velocity_um_s.to_bits());
                }
                let first = out.first().map(|s| s.velocity_um_s);
                turns += usize::from(out.last().map(|s| s.velocity_um_s) != first);
                k0 += n as u64;
            }
            // The blocks cover 16 s: turns inside blocks were checked.
            assert!(turns > 10, "{turns} blocks straddle a turn");
        }
    }

    #[test]
    fn triangle_turns_at_the_ends() {
        let t = Trajectory::Triangle {
            a_um: 1_000.0,
            b_um: 11_000.0,
            speed_um_s: 10_000.0,
        };
        assert_eq!(t.state(0.0).position_um, 1_000.0);
        assert!((t.state(0.5).position_um - 6_000.0).abs() < 1e-6);
        assert!((t.state(1.5).position_um - 6_000.0).abs() < 1e-6);
        assert_eq!(t.state(1.5).velocity_um_s, -10_000.0);
    }

    #[test]
    fn ramp_saturates() {
        let r = Trajectory::Ramp {
            from_um: 0.0,
            v0_um_s: 0.0,
            accel_um_s2: 1e7,
            v_max_um_s: 100_000.0,
        };
        // 10 m/s² reaches 100 mm/s after 10 ms, 0.5 mm travelled.
        let s = r.state(0.02);
        assert_eq!(s.velocity_um_s, 100_000.0);
        assert!((s.position_um - (500.0 + 1_000.0)).abs() < 1e-6);
    }

    #[test]
    fn piecewise_and_reversal() {
        let p = Trajectory::Piecewise {
            pieces: vec![
                Piece {
                    trajectory: Trajectory::Rest { at_um: 5.0 },
                    duration_s: 1.0,
                },
                Piece {
                    trajectory: Trajectory::Reversal {
                        from_um: 5.0,
                        turn_um: 15.0,
                        speed_um_s: 10.0,
                    },
                    duration_s: 3.0,
                },
            ],
        };
        assert_eq!(p.state(0.5).position_um, 5.0);
        assert!((p.state(2.0).position_um - 15.0).abs() < 1e-9);
        assert!((p.state(3.0).position_um - 5.0).abs() < 1e-9);
        assert_eq!(p.duration_s(), Some(4.0));
    }
}
