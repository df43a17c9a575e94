//! The analysis of what participants answered: no I/O, results as data (printing and charts
//! are the front ends').

pub mod input;
pub mod paired;
pub mod psychometric;
pub mod report;
pub mod scaling;
