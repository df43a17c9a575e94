//! Touch stage (issue #36): a 4-wire resistive overlay read as two rheostats, its pressure, its
//! calibration to µm and its faults — pure data and arithmetic, no I/O, no clock.
//!
//! - [`plates`]: the phase sequence (which terminal is driven high, low, left floating or
//!   converted), each phase's settling time from the plates' RC, and the frame rate that results;
//! - [`pressure`]: touch resistance from Z1/Z2, touch-down and lift-off with hysteresis;
//! - [`calibration`]: three-point affine calibration, raw codes → µm;
//! - [`fault`]: the per-axis rail checks, the 1D rule applied to each axis;
//! - [`frame`]: one frame of the four phases → lifted, landing, down at (x, y) µm, or a fault.
//!
//! Every code here is on the 1D stage's scale: the sum of 16 12-bit conversions
//! ([`crate::sample::CODE_FULL_SCALE`] = 65 536), so the rail margins and thresholds mean the
//! same thing on both sensors. `docs/touch.md` has the figures and their sources.

pub mod calibration;
pub mod fault;
pub mod frame;
pub mod plates;
pub mod pressure;
