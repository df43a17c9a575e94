//! Scenario files: a run described in TOML (trajectory segments, noise, faults) with the
//! expectations it must meet. `tests/scenarios/*.toml` are run by the system tests; the CLI runs
//! one with `--scenario FILE`.
//!
//! ```toml
//! name = "rail fault mid-stroke"
//! board = "nucleo-f446re"      # optional, default nucleo-f446re
//! seed = 7                     # optional
//! noise_lsb = 2.0              # per-conversion σ, 12-bit LSB RMS
//!
//! [[segment]]
//! kind = "move"                # rest | move | back_and_forth | sine | ramp
//! from_mm = 5.0
//! to_mm = 60.0
//! speed_mm_s = 50.0
//!
//! [[fault]]
//! kind = "open"                # open | short | dropout
//! start_s = 0.5
//! end_s = 0.6
//!
//! [expect]
//! region_sequence = [0, 1, 2]  # regions visited, repeats collapsed, faults skipped
//! min_switches = 2
//! max_switches = 2
//! gate_off_during_faults = true
//! fault_onsets = 1
//! burst_tolerance_pct = 0.1    # produced f_b vs commanded, every region with whole periods
//! max_switch_past_mm = 0.2     # how far past a boundary a switch may come
//! whole_pulses = true          # no runt, doubled or stretched pulse
//! ```

use std::path::Path;

use serde::Deserialize;

use crate::adc::{FaultKind, FaultWindow};
use crate::metrics::{self, Metrics};
use crate::sim::{self, SimParams, SimResult};
use crate::trajectory::{Piece, Trajectory};

/// One scenario file.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Human name.
    pub name: String,
    /// Board name (`saw_boards::by_name`).
    #[serde(default = "default_board")]
    pub board: String,
    /// PRNG seed of the ADC noise.
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// Per-conversion noise, 12-bit LSB RMS.
    #[serde(default = "default_noise")]
    pub noise_lsb: f64,
    /// Per-conversion offset, 12-bit LSB.
    #[serde(default)]
    pub offset_lsb: f64,
    /// Run time, s (default: the segments' total).
    pub duration_s: Option<f64>,
    /// Trajectory segments, played in order.
    #[serde(rename = "segment")]
    pub segments: Vec<Segment>,
    /// Sensor faults.
    #[serde(default, rename = "fault")]
    pub faults: Vec<Fault>,
    /// What must hold.
    #[serde(default)]
    pub expect: Expect,
}

fn default_board() -> String {
    saw_boards::NUCLEO_F446RE.name.to_string()
}
fn default_seed() -> u64 {
    1
}
fn default_noise() -> f64 {
    2.0
}

/// A trajectory segment, in mm, mm/s and s.
#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Segment {
    /// At rest.
    Rest {
        /// Position, mm.
        at_mm: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// From one point to another at constant speed (duration follows).
    Move {
        /// Start, mm.
        from_mm: f64,
        /// End, mm.
        to_mm: f64,
        /// Speed, mm/s (> 0).
        speed_mm_s: f64,
    },
    /// Triangle back and forth starting at `a_mm`.
    BackAndForth {
        /// First turning point, mm.
        a_mm: f64,
        /// Second turning point, mm.
        b_mm: f64,
        /// Speed, mm/s.
        speed_mm_s: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// Sine back and forth starting at `a_mm`.
    Sine {
        /// First turning point, mm.
        a_mm: f64,
        /// Second turning point, mm.
        b_mm: f64,
        /// Period, s.
        period_s: f64,
        /// Duration, s.
        duration_s: f64,
    },
    /// Constant acceleration to a speed limit.
    Ramp {
        /// Start, mm.
        from_mm: f64,
        /// Initial velocity, mm/s.
        v0_mm_s: f64,
        /// Acceleration, m/s².
        accel_m_s2: f64,
        /// Speed limit, mm/s.
        v_max_mm_s: f64,
        /// Duration, s.
        duration_s: f64,
    },
}

impl Segment {
    /// The segment as a trajectory piece.
    pub fn piece(&self) -> Piece {
        match *self {
            Segment::Rest { at_mm, duration_s } => Piece {
                trajectory: Trajectory::Rest { at_um: at_mm * 1e3 },
                duration_s,
            },
            Segment::Move {
                from_mm,
                to_mm,
                speed_mm_s,
            } => Piece {
                trajectory: Trajectory::Constant {
                    from_um: from_mm * 1e3,
                    speed_um_s: (to_mm - from_mm).signum() * speed_mm_s * 1e3,
                },
                duration_s: (to_mm - from_mm).abs() / speed_mm_s,
            },
            Segment::BackAndForth {
                a_mm,
                b_mm,
                speed_mm_s,
                duration_s,
            } => Piece {
                trajectory: Trajectory::Triangle {
                    a_um: a_mm * 1e3,
                    b_um: b_mm * 1e3,
                    speed_um_s: speed_mm_s * 1e3,
                },
                duration_s,
            },
            Segment::Sine {
                a_mm,
                b_mm,
                period_s,
                duration_s,
            } => Piece {
                trajectory: Trajectory::Sine {
                    a_um: a_mm * 1e3,
                    b_um: b_mm * 1e3,
                    period_s,
                },
                duration_s,
            },
            Segment::Ramp {
                from_mm,
                v0_mm_s,
                accel_m_s2,
                v_max_mm_s,
                duration_s,
            } => Piece {
                trajectory: Trajectory::Ramp {
                    from_um: from_mm * 1e3,
                    v0_um_s: v0_mm_s * 1e3,
                    accel_um_s2: accel_m_s2 * 1e6,
                    v_max_um_s: v_max_mm_s * 1e3,
                },
                duration_s,
            },
        }
    }
}

/// A sensor fault window, s.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fault {
    /// What happens.
    pub kind: FaultKind,
    /// Start, s.
    pub start_s: f64,
    /// End, s.
    pub end_s: f64,
}

/// Expectations; every field is optional.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expect {
    /// Regions visited in order (consecutive repeats collapsed, fault gaps skipped).
    pub region_sequence: Option<Vec<u8>>,
    /// At least this many region switches.
    pub min_switches: Option<usize>,
    /// At most this many region switches.
    pub max_switches: Option<usize>,
    /// The gate is off for the whole of every fault window (from the stale limit on, for a
    /// dropout).
    #[serde(default)]
    pub gate_off_during_faults: bool,
    /// Exactly this many fault onsets.
    pub fault_onsets: Option<usize>,
    /// Produced f_b within this many % of commanded, in every region with whole periods.
    pub burst_tolerance_pct: Option<f64>,
    /// Every switch comes at most this far past its boundary (and never before it), mm.
    pub max_switch_past_mm: Option<f64>,
    /// Every pulse is one of the planned settings, whole.
    #[serde(default)]
    pub whole_pulses: bool,
}

/// Why a scenario could not be run.
#[derive(Debug)]
pub enum ScenarioError {
    /// Reading the file failed.
    Io(std::io::Error),
    /// The TOML is malformed.
    Parse(toml::de::Error),
    /// Unknown board name.
    UnknownBoard(String),
    /// The simulation would not start.
    Sim(sim::SimError),
}

impl std::fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ScenarioError::Io(e) => write!(f, "io: {e}"),
            ScenarioError::Parse(e) => write!(f, "parse: {e}"),
            ScenarioError::UnknownBoard(b) => write!(f, "unknown board {b:?}"),
            ScenarioError::Sim(e) => write!(f, "sim: {e}"),
        }
    }
}

impl std::error::Error for ScenarioError {}

impl Scenario {
    /// Parses TOML text.
    pub fn from_toml(text: &str) -> Result<Self, ScenarioError> {
        toml::from_str(text).map_err(ScenarioError::Parse)
    }

    /// Reads and parses a file.
    pub fn from_file(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(ScenarioError::Io)?;
        Self::from_toml(&text)
    }

    /// The simulation parameters of this scenario (default scene).
    pub fn params(&self) -> Result<SimParams, ScenarioError> {
        let board = saw_boards::by_name(&self.board)
            .ok_or_else(|| ScenarioError::UnknownBoard(self.board.clone()))?;
        let trajectory = Trajectory::Piecewise {
            pieces: self.segments.iter().map(Segment::piece).collect(),
        };
        let duration_s = self.duration_s.or(trajectory.duration_s()).unwrap_or(1.0);
        let faults = self
            .faults
            .iter()
            .map(|f| FaultWindow {
                kind: f.kind,
                start_us: (f.start_s * 1e6).round() as u64,
                end_us: (f.end_s * 1e6).round() as u64,
            })
            .collect();
        Ok(SimParams::new(board, trajectory, duration_s)
            .with_noise(self.noise_lsb, self.seed)
            .with_offset(self.offset_lsb)
            .with_faults(faults))
    }

    /// Runs the scenario.
    pub fn run(&self) -> Result<(SimResult, Metrics), ScenarioError> {
        let r = sim::run(&self.params()?).map_err(ScenarioError::Sim)?;
        let m = metrics::compute(&r);
        Ok((r, m))
    }

    /// Checks the expectations; returns one line per failure (empty = pass).
    pub fn check(&self, r: &SimResult, m: &Metrics) -> Vec<String> {
        let e = &self.expect;
        let mut fails = Vec::new();
        if let Some(want) = &e.region_sequence {
            let got = region_sequence(r);
            if &got != want {
                fails.push(format!("region sequence {got:?}, expected {want:?}"));
            }
        }
        let n = m.switches.len();
        if let Some(min) = e.min_switches {
            if n < min {
                fails.push(format!("{n} region switches, expected ≥ {min}"));
            }
        }
        if let Some(max) = e.max_switches {
            if n > max {
                fails.push(format!("{n} region switches, expected ≤ {max}"));
            }
        }
        if let Some(k) = e.fault_onsets {
            if m.fault_onsets != k {
                fails.push(format!("{} fault onsets, expected {k}", m.fault_onsets));
            }
        }
        if e.gate_off_during_faults {
            let stale_us = r.params.config.stale_after_us as u64 + r.sample_period_us as u64;
            for f in &r.params.adc.faults {
                // The first sample inside the window reads the rail and must turn the line off.
                let period = r.sample_period_us as u64;
                let first_sample = f.start_us.div_ceil(period) * period;
                let from = match f.kind {
                    FaultKind::Dropout => f.start_us + stale_us,
                    FaultKind::Open | FaultKind::Short => first_sample,
                    // An offset is no fault the core can see unless it reaches a rail.
                    FaultKind::Spike { .. } | FaultKind::Drift { .. } => continue,
                };
                if from < f.end_us && r.waveform.high_within(r.clocks(from), r.clocks(f.end_us)) {
                    fails.push(format!(
                        "gate on during {:?} fault {:.4}–{:.4} s",
                        f.kind,
                        f.start_us as f64 * 1e-6,
                        f.end_us as f64 * 1e-6
                    ));
                }
            }
        }
        if let Some(tol) = e.burst_tolerance_pct {
            let mut checked = 0;
            for s in &m.regions {
                if let Some(err) = s.error_pct {
                    checked += 1;
                    if err.abs() > tol {
                        fails.push(format!(
                            "region {}: f_b {:.4} Hz vs {:.4} Hz commanded ({err:+.4} %)",
                            s.region,
                            s.produced_hz.unwrap_or(0.0),
                            s.commanded_hz.unwrap_or(0.0)
                        ));
                    }
                }
            }
            if checked == 0 {
                fails.push("no region had whole burst periods to measure".into());
            }
        }
        if let Some(max) = e.max_switch_past_mm {
            for s in &m.switches {
                if s.past_um > max * 1e3 || s.past_um < 0.0 {
                    fails.push(format!(
                        "switch {}→{} at {:.3} mm, {:+.3} mm past boundary {:.3} mm",
                        s.from,
                        s.to,
                        s.true_um / 1e3,
                        s.past_um / 1e3,
                        s.boundary_um / 1e3
                    ));
                }
            }
        }
        if e.whole_pulses && m.malformed_pulses > 0 {
            fails.push(format!(
                "{} of {} pulses malformed",
                m.malformed_pulses, m.pulses
            ));
        }
        if r.timer_protocol_errors > 0 {
            fails.push(format!(
                "{} gate actions made no sense to the timer",
                r.timer_protocol_errors
            ));
        }
        fails
    }
}

/// Regions visited in order, consecutive repeats collapsed, samples without a region skipped.
pub fn region_sequence(r: &SimResult) -> Vec<u8> {
    let mut seq: Vec<u8> = Vec::new();
    for t in &r.trace {
        if let Some(reg) = t.region {
            if seq.last() != Some(&reg) {
                seq.push(reg);
            }
        }
    }
    seq
}
