//! `saw experiment analyze` (being written: waits for the paired-comparison analysis).

use std::path::Path;

use crate::experiment::Method;
use crate::{Done, Failure};

/// Not yet.
pub fn analyze(
    _files: &[std::path::PathBuf],
    _method: Option<Method>,
    _output: Option<&Path>,
) -> Result<Done, Failure> {
    Err(Failure::input(
        "saw experiment analyze is not built yet".into(),
    ))
}
