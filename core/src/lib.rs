//! Portable control core of the SAW tactile display.
//!
//! One module per stage of the data flow — [`sample`] → [`position`] → [`velocity`] →
//! [`region`] → [`texture`] → [`burst`] → [`gate`] — tied together by the [`controller`].
//! The core names no chip, does no I/O and reads no clock: samples arrive with their timestamps,
//! and gate actions leave through the [`gate::BurstOutput`] port.
#![no_std]
#![deny(missing_docs)]
// The per-sample path must not panic (scripts/panic-check.sh checks the images; these keep the
// source so). Tests may unwrap and index. Not denied: clippy::arithmetic_side_effects (135 sites,
// nearly all bounded fixed-point arithmetic; release builds wrap instead of panicking, and the
// panics that stay — division by zero, i32::MIN / -1 — are what the image check catches).
#![cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::unreachable,
        clippy::todo,
        clippy::unimplemented,
        clippy::indexing_slicing
    )
)]

#[cfg(test)]
extern crate std;

#[macro_use]
mod fmt;

pub mod burst;
pub mod controller;
pub mod gate;
pub mod plane;
pub mod position;
pub mod region;
pub mod sample;
pub mod scene;
#[cfg(feature = "scene-file")]
pub mod scene_file;
pub mod texture;
pub mod touch;
pub mod velocity;

pub use controller::{ConfigError, Controller, Output, Telemetry};
pub use scene::{default_config, default_scene, Config, Scene};
