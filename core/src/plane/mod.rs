//! The 2D plane (issue #36): position in µm on a plate, windows with a texture each, edges that
//! pulse when crossed and oriented gratings, built beside the 1D stages (which stay as they
//! are). See docs/plane.md.

pub mod geometry;
pub mod grating;

pub use geometry::{GeometryError, PointUm, Polygon, SegmentUm, MAX_VERTICES};
pub mod edges;
pub mod screen;
#[cfg(test)]
mod testing;
pub mod velocity;

pub use edges::{CompiledEdges, EdgeError, EdgePulse, EdgeTracker, Edges, MAX_EDGES};
pub use grating::{CompiledOriented, OrientedError, OrientedGrating};
pub use screen::{CompiledScreen, Place, Screen, ScreenError, ScreenTracker, Window};
pub use velocity::{PlaneVelocity, VelocityUmS};
