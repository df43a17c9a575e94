//! The sections of a scene file besides its regions, each converted to the core's units:
//! `[substrate]`, `[limits]`, the top-level `hysteresis_mm` and `drive`, and `[lines]`. An
//! absent section gives the built-in default.

use toml::Spanned;

use crate::burst::SafetyLimits;
use crate::gate::DriveMode;
use crate::position::{Calibration, DEFAULT_RAIL_MARGIN_CODE};
use crate::region::DEFAULT_HYSTERESIS_UM;
use crate::texture::{Envelope, Lines};

use super::ctx::{milli, Ctx};
use super::spec::{Drive, EnvelopeSpec, Limits, LinesSpec, Substrate};
use super::SceneFileError;

/// `[substrate]` as a calibration.
pub(super) fn calibration(
    cx: &Ctx<'_>,
    substrate: Option<&Spanned<Substrate>>,
) -> Result<Calibration, SceneFileError> {
    let Some(s) = substrate else {
        return Ok(Calibration::default());
    };
    let s = s.get_ref();
    let length_mm = cx.range(&s.length_mm, "substrate.length_mm", 1.0, 1000.0)?;
    Ok(Calibration {
        code_at_start: *s.code_at_start.get_ref(),
        code_at_end: *s.code_at_end.get_ref(),
        length_um: milli(length_mm),
        rail_margin_code: s
            .rail_margin_code
            .as_ref()
            .map_or(DEFAULT_RAIL_MARGIN_CODE, |m| *m.get_ref()),
    })
}

/// `[limits]` as the carrier caps and the stale limit in µs.
pub(super) fn limits(
    cx: &Ctx<'_>,
    limits: Option<&Spanned<Limits>>,
) -> Result<(SafetyLimits, u32), SceneFileError> {
    let Some(l) = limits else {
        // 5 ms: the built-in default configuration's stale limit.
        return Ok((SafetyLimits::default(), 5_000));
    };
    let l = l.get_ref();
    let duty = cx.opt(
        &l.max_duty_percent,
        "limits.max_duty_percent",
        0.1,
        100.0,
        50.0,
    )?;
    let on = cx.opt(
        &l.max_on_time_ms,
        "limits.max_on_time_ms",
        0.001,
        1000.0,
        50.0,
    )?;
    let stale = cx.opt(&l.stale_after_ms, "limits.stale_after_ms", 0.2, 1000.0, 5.0)?;
    let level = cx.opt(
        &l.max_level_percent,
        "limits.max_level_percent",
        0.1,
        100.0,
        100.0,
    )?;
    let caps = SafetyLimits {
        max_duty_permille: (duty * 10.0).round() as u16,
        max_on_time_us: milli(on),
        max_level_permille: (level * 10.0).round() as u16,
    };
    Ok((caps, milli(stale)))
}

/// The top-level `hysteresis_mm` as the boundary band's half-width in µm.
pub(super) fn hysteresis_um(
    cx: &Ctx<'_>,
    hysteresis_mm: Option<&Spanned<f64>>,
) -> Result<u32, SceneFileError> {
    match hysteresis_mm {
        None => Ok(DEFAULT_HYSTERESIS_UM),
        Some(h) => {
            let um = milli(cx.range(h, "hysteresis_mm", 0.0, 5.0)?);
            #[cfg(feature = "fuzz-plant-hysteresis")]
            plant::hysteresis(um);
            Ok(um)
        }
    }
}

/// The top-level `drive`: standing waves unless the file asks for progressive ones.
pub(super) fn drive(drive: Option<&Spanned<Drive>>) -> DriveMode {
    match drive.map(|d| *d.get_ref()) {
        None | Some(Drive::Standing) => DriveMode::Standing,
        Some(Drive::Progressive) => DriveMode::Progressive,
    }
}

/// `[lines]`; none when the section is absent.
pub(super) fn lines(
    cx: &Ctx<'_>,
    lines: Option<&Spanned<LinesSpec>>,
) -> Result<Lines, SceneFileError> {
    let mut out = Lines::default();
    let Some(l) = lines else {
        return Ok(out);
    };
    let l = l.get_ref();
    // A 17th line is refused where it is written.
    let span_of_17th = l
        .positions_mm
        .get_ref()
        .get(16)
        .map_or(l.positions_mm.span(), |p| p.span());
    for p in l.positions_mm.get_ref() {
        let (p, span) = (*p.get_ref(), p.span());
        let um = (p * 1000.0).round();
        if !(p.is_finite() && um >= 0.0 && um <= u32::MAX as f64) {
            return Err(cx.err(
                span,
                "lines.positions_mm",
                format_args!(
                    "{p} mm is not a position: it must be a finite number of mm, at least 0"
                ),
            ));
        }
        out.positions_um.push(um as u32).map_err(|_| {
            cx.err(
                span_of_17th.clone(),
                "lines.positions_mm",
                "more than 16 lines",
            )
        })?;
    }
    #[cfg(feature = "fuzz-plant-lines")]
    plant::lines(&out.positions_um);
    out.pulse_us = milli(cx.opt(&l.pulse_ms, "lines.pulse_ms", 0.001, 1000.0, 10.0)?);
    out.envelope = match l.envelope {
        None | Some(EnvelopeSpec::Triangle) => Envelope::Triangular,
        Some(EnvelopeSpec::Rectangle) => Envelope::Rectangular,
    };
    out.amplitude_permille =
        cx.permille(&l.amplitude_percent, "lines.amplitude_percent", 0.1, 100.0)?;
    out.hysteresis_um = milli(cx.opt(&l.rearm_mm, "lines.rearm_mm", 0.0, 5.0, 0.2)?);
    Ok(out)
}

/// Planted panics (features `fuzz-plant-*`, never in a shipped build): bugs of the kind a
/// fuzzer should find, that the byte-level mutator did not find in 120 s (docs/fuzzing.md).
/// `scripts/fuzz.sh --plant <name>` builds one in and fails unless the fuzzer finds it.
#[cfg(any(feature = "fuzz-plant-hysteresis", feature = "fuzz-plant-lines"))]
mod plant {
    /// An index one past a 5-entry table for 1 µm in 5 (`hysteresis_um % 5 == 1`): reached only
    /// by a value whose µm count ends in 1 or 6 (`0.001`, `1.506`), which no shipped scene
    /// writes.
    #[cfg(feature = "fuzz-plant-hysteresis")]
    pub(super) fn hysteresis(um: u32) {
        // black_box: so the compiler cannot prove the index and refuse to build the plant.
        let table = core::hint::black_box([0u32; 5]);
        let slot = match um % 5 {
            1 => 5,
            r => r as usize,
        };
        core::hint::black_box(table[slot]);
    }

    /// An array one short of 6 lines: room for 5, filled with up to 6, so a scene with 6 or
    /// more lines (every position valid) overruns it.
    #[cfg(feature = "fuzz-plant-lines")]
    pub(super) fn lines(positions_um: &[u32]) {
        let mut first = core::hint::black_box([0u32; 5]);
        for (i, &p) in positions_um.iter().take(6).enumerate() {
            first[i] = p;
        }
        core::hint::black_box(first);
    }
}
