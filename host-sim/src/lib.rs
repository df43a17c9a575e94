//! Host simulation (placeholder while the crate is written).
pub mod models;
