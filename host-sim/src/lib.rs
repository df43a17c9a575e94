//! Host simulation of the SAW tactile display: the portable control core (`saw-core`) bound to
//! models of its hardware.
//!
//! - [`trajectory`]: the finger's motion; [`trajectory2d`]: on a 2D screen (issue #36);
//! - [`adc`]: the slide rheostat and the oversampling ADC, with noise and rail faults;
//! - [`touch`]: the 4-wire touch overlay (issue #36): plates, settling, pressure, noise;
//! - [`timer`]: the burst timer as an STM32 timer with (or without) preload, recording edges;
//! - [`sim`]: the closed loop, trajectory → ADC → controller → timer; [`sim2d`]: the 2D one,
//!   path → 4-wire overlay → touch sensor → 2D controller → timer (issue #36);
//! - [`metrics`]: f_b produced vs commanded, region switches, velocity error and delay;
//! - [`chart`]: a PNG of a run; [`chart2d`]: of a 2D run, the scene as a map;
//! - [`scenario`]: TOML scenario files with expectations;
//! - [`report`]: the human summary the CLI prints;
//! - [`soak`]: `host-sim soak`, random scenes, fingers and faults checked online for hours of use;
//! - [`cli`]: the simulator's command line ([`cli2d`]: its 2D run); [`door`]: the value parsers of every command's flags.

pub mod adc;
pub mod bench;
pub mod budget;
pub mod chart;
pub mod chart2d;
pub mod check;
pub mod cli;
pub mod cli2d;
pub mod door;
pub mod guard;
pub mod metrics;
pub mod models;
pub mod noise;
pub mod report;
pub mod rf;
pub mod scenario;
pub mod serve;
pub mod sim;
pub mod sim2d;
pub mod soak;
pub mod timer;
pub mod touch;
pub mod touch_budget;
pub mod trajectory;
pub mod trajectory2d;
