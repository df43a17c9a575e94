//! Physical models behind the textures (see docs/models.md):
//!
//! - [`stick_slip`]: stick-slip frequency f_ss (Nara et al., eqs. 10–12, fig. 5).
//! - [`grooved`]: static skin deformation over a grooved tile (Taylor & Lederman, Appendix 1,
//!   eqs. 1–4) with three θ solvers.
//! - [`tile`]: grooved tile → grating region (λ = G + L, Konyo et al. eq. 1; amplitude from A).
//! - [`solvers`]: the θ solvers compared over the paper's tiles (iterations against accuracy).
//! - [`sandpaper`]: grit ↔ burst frequency through the scales of Nara et al., table 1.
//! - [`atan`]: atan choice for the f32 per-sample stick-slip path.
//! - [`cli`]: the `model …` and `tile-to-scene` subcommands (plain `&[String]` arguments).
//! - [`charts`]: `model charts`, the docs/charts/models-*.png charts and docs/models.md's tables.
//!
//! The data (curves, sweeps, table rows) live with their model; [`charts`] draws them and
//! [`cli`] parses flags and calls both: `cli` → `charts` → models, never back.

pub mod atan;
pub mod charts;
pub mod cli;
pub mod grooved;
pub mod sandpaper;
pub mod solvers;
pub mod stick_slip;
pub mod tile;
