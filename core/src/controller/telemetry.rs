//! What the controller reports: each sample's [`Output`] and the counters of [`Telemetry`].

use crate::gate::{DriveMode, Envelope, GateAction};
use crate::position::SensorFault;

/// What one sample produced (for logs, host analyses and the firmware's telemetry).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Output {
    /// Position, µm, when the sensor is healthy.
    pub position_um: Option<i32>,
    /// Velocity, µm/s, once the estimator has a full window, on a sample whose region reads
    /// it (its texture or the scene's lines); None where the region needs only the position
    /// (the estimator rests: `Controller::velocity_um_s` works it out when asked).
    pub velocity_um_s: Option<i32>,
    /// Region under the finger.
    pub region: Option<u8>,
    /// The action for the burst-timer port, when the line must change.
    pub action: Option<GateAction>,
    /// The new drive amplitude, ‰, when it changes.
    pub amplitude_permille: Option<u16>,
    /// The level's shape over the one-pulse of `action` (with every `Pulse`).
    pub envelope: Option<Envelope>,
    /// The drive mode, on the first sample after a scene loads.
    pub drive: Option<DriveMode>,
    /// The index of a line crossed on this sample (its pulse fired).
    pub line: Option<u8>,
    /// The sensor fault in force, if any.
    pub fault: Option<SensorFault>,
}

/// Counters for the low-rate telemetry log.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Telemetry {
    /// Samples processed.
    pub samples: u32,
    /// Fault onsets.
    pub faults: u32,
    /// Region switches.
    pub region_switches: u32,
    /// Gate actions issued.
    pub gate_actions: u32,
    /// Samples whose f_b was clamped to the board's limit.
    pub clamped: u32,
    /// Line pulses fired.
    pub line_pulses: u32,
    /// Line crossings dropped to keep the duty cap.
    pub lines_skipped: u32,
    /// Grating ridge pulses fired (position phase).
    pub ridge_pulses: u32,
    /// Ridge crossings without a pulse: several in one sample, faster than the board's f_b
    /// limit, or inside the duty cap's rest.
    pub ridges_skipped: u32,
    /// Last position, µm (−1 when unknown).
    pub position_um: i32,
    /// Last velocity, µm/s.
    pub velocity_um_s: i32,
    /// Region under the finger (255 when none).
    pub region: u8,
    /// The burst frequency f_b the line is producing, mHz: while periodic bursts run, the
    /// running timer period's frequency; else, while one-pulses keep firing (a position or
    /// hybrid grating's ridges, lines), their rate, 1 / the interval between the last two
    /// (at a constant speed V over a grating of period λ, V/λ); 0 when the line is off, the
    /// finger still (velocity 0), or no pulse has come for 1.5 × the last interval.
    pub burst_millihz: u32,
}
