//! The reader's context: turns a byte span of the file into a located [`SceneFileError`], and
//! range-checks values so that a refusal names the field where it was written.

extern crate std;

use core::ops::Range;
use std::string::ToString;

use toml::Spanned;

use super::SceneFileError;

/// The file being read: its name for messages, its text to find lines and columns in.
pub(super) struct Ctx<'a> {
    pub(super) file: &'a str,
    pub(super) text: &'a str,
}

impl Ctx<'_> {
    /// An error at `span` (its start gives the 1-based line and column), naming `field`.
    pub(super) fn err(
        &self,
        span: Range<usize>,
        field: &str,
        message: impl ToString,
    ) -> SceneFileError {
        let start = span.start.min(self.text.len());
        let before = &self.text[..start];
        let line = before.matches('\n').count() + 1;
        let column = start - before.rfind('\n').map(|i| i + 1).unwrap_or(0) + 1;
        SceneFileError {
            file: self.file.to_string(),
            line,
            column,
            field: field.to_string(),
            message: message.to_string(),
        }
    }

    /// `v` within `lo ..= hi`, else an error naming `field` at its span.
    pub(super) fn range(
        &self,
        v: &Spanned<f64>,
        field: &str,
        lo: f64,
        hi: f64,
    ) -> Result<f64, SceneFileError> {
        let x = *v.get_ref();
        let u = unit(field);
        if !x.is_finite() {
            return Err(self.err(
                v.span(),
                field,
                format_args!("{x} is not a number; it must be from {lo}{u} to {hi}{u}"),
            ));
        }
        if !(lo <= x && x <= hi) {
            return Err(self.err(
                v.span(),
                field,
                format_args!("{x}{u} is outside the allowed {lo}{u} to {hi}{u}"),
            ));
        }
        Ok(x)
    }

    /// An optional value: `default` when absent, else checked as [`Ctx::range`] does.
    pub(super) fn opt(
        &self,
        v: &Option<Spanned<f64>>,
        field: &str,
        lo: f64,
        hi: f64,
        default: f64,
    ) -> Result<f64, SceneFileError> {
        v.as_ref()
            .map_or(Ok(default), |v| self.range(v, field, lo, hi))
    }

    /// A percentage as ‰: within `lo ..= 100`, `default` (in %) when absent.
    pub(super) fn permille(
        &self,
        v: &Option<Spanned<f64>>,
        field: &str,
        lo: f64,
        default: f64,
    ) -> Result<u16, SceneFileError> {
        Ok((self.opt(v, field, lo, 100.0, default)? * 10.0).round() as u16)
    }
}

/// The unit a field's name ends in, as a message shows it after a number (" mm", " %"); empty
/// for a dimensionless field (`delta_mu`).
pub(super) fn unit(field: &str) -> &'static str {
    const UNITS: [(&str, &str); 10] = [
        ("_percent", " %"),
        ("_mm_s", " mm/s"),
        ("_n_per_m", " N/m"),
        ("_mm", " mm"),
        ("_um", " µm"),
        ("_ms", " ms"),
        ("_hz", " Hz"),
        ("_pa", " Pa"),
        ("_g", " g"),
        ("_n", " N"),
    ];
    UNITS
        .iter()
        .find(|(suffix, _)| field.ends_with(suffix))
        .map_or("", |(_, u)| u)
}

/// A value in mm, ms or Hz as the whole µm, µs or mHz the core counts in. Callers range-check
/// first: the cast saturates rather than fails.
pub(super) fn milli(x: f64) -> u32 {
    (x * 1000.0).round() as u32
}
