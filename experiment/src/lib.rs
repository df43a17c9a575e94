//! Experiments with people on the SAW display: what a lab runs and how it is analysed.
//!
//! - [`protocol`]: protocol files (TOML), checked at the door like scene files.
//! - [`design`]: the trial list a protocol and a subject imply (orders from a seed,
//!   counterbalanced across subjects).
//! - [`staircase`]: transformed up-down staircases (a state machine per track).
//! - [`runner`]: the state machine that owns order and progress: hands out the next
//!   presentation, takes the response, resumes from a log.
//! - [`exploration`]: what the finger did while a stimulus was explored, from the telemetry.
//! - [`observer`]: a simulated participant (Thurstonian, on the f_b the board produced).
//! - [`session`]: the append-only log and the CSV and sidecar rewritten from it.
//! - [`analysis`]: scale values, ANOVA, yardsticks, thresholds and fits — no I/O, results
//!   as data; [`dist`] the distributions it needs.
//!
//! The front ends (`saw experiment`, the panel, the Python module) only drive these.

pub mod analysis;
#[cfg(feature = "chart")]
pub mod chart;
pub mod dist;
pub mod exploration;
pub mod observer;
pub mod protocol;
pub mod runner;
pub mod session;
pub mod simulate;
pub mod staircase;
/// The fuzz bodies of the outside inputs (protocol files, analysis CSVs, session logs), shared
/// by the targets in `fuzz/` and the corpus replay test (docs/fuzzing.md).
pub mod testing;
