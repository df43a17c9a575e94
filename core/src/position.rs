//! Position stage: ADC code → µm along the substrate by two-point calibration, and rail detection.
//!
//! The rheostat is a voltage divider; its wiper code is linear in position between the two
//! calibrated ends. A code at either rail means an open wiper (pulled down by the board's
//! resistor) or a short to the supply: the position is then unknown and the carrier must stop.

use crate::sample::{Sample, CODE_FULL_SCALE};

/// Substrate length of the seed's display: a 17 × 63 mm LiNbO3 plate.
pub const DEFAULT_LENGTH_UM: u32 = 63_000;
/// Codes within this distance of 0 or full scale are a rail (1 % of full scale).
pub const DEFAULT_RAIL_MARGIN_CODE: u16 = (CODE_FULL_SCALE / 100) as u16;
/// The calibrated ends must span at least a quarter of the ADC range: less means a mis-wired
/// rheostat or a calibration taken at the wrong points, and would leave > 60 µm per 12-bit LSB.
pub const MIN_SPAN_CODE: u16 = (CODE_FULL_SCALE / 4) as u16;

/// Two-point calibration of the slide rheostat.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Calibration {
    /// Code read with the slider at the start (0 µm) end.
    pub code_at_start: u16,
    /// Code read with the slider at the far end (`length_um`).
    pub code_at_end: u16,
    /// Travel between the two calibration points, µm.
    pub length_um: u32,
    /// Codes at or below `rail_margin_code`, or at or above full scale minus it, are rails.
    pub rail_margin_code: u16,
}

impl Default for Calibration {
    /// Ends at 2 % and 98 % of full scale: a rheostat with small end resistors, as on the bench.
    fn default() -> Self {
        Self {
            code_at_start: (CODE_FULL_SCALE * 2 / 100) as u16,
            code_at_end: (CODE_FULL_SCALE * 98 / 100) as u16,
            length_um: DEFAULT_LENGTH_UM,
            rail_margin_code: DEFAULT_RAIL_MARGIN_CODE,
        }
    }
}

/// Why a calibration was rejected. Each variant carries the values its sentence (`Display`)
/// names, in the scene file's terms (`code_at_start`, `code_at_end`, `rail_margin_code`, mm).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum CalibrationError {
    /// `code_at_end` ≤ `code_at_start`: the ends are swapped (or equal).
    EndsSwapped {
        /// `code_at_start`.
        code_at_start: u16,
        /// `code_at_end`.
        code_at_end: u16,
    },
    /// The ends are closer than [`MIN_SPAN_CODE`].
    EndsTooClose {
        /// `code_at_end − code_at_start`.
        span_code: u16,
        /// [`MIN_SPAN_CODE`].
        min_span_code: u16,
    },
    /// An end lies inside a rail band, so a reading there would be taken for a fault.
    EndInRail {
        /// The start end (low rail) rather than the far end (high rail).
        at_start: bool,
        /// The end's code.
        code: u16,
        /// The band's edge: codes at or below it (low rail), or at or above it (high rail).
        rail_code: u16,
    },
    /// `length_um` is zero or above 1 m.
    BadLength {
        /// The length asked for, µm.
        length_um: u32,
    },
    /// The rail margin is zero (no rail detection) or covers half the range.
    BadRailMargin {
        /// The margin asked for, codes.
        margin_code: u16,
        /// The first margin refused above zero, codes (a quarter of full scale).
        limit_code: u32,
    },
}

/// Longest substrate, µm.
const MAX_LENGTH_UM: u32 = 1_000_000;

impl core::fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::Milli;
        match *self {
            CalibrationError::EndsSwapped {
                code_at_start,
                code_at_end,
            } => write!(
                f,
                "code_at_end {code_at_end} must be above code_at_start {code_at_start}"
            ),
            CalibrationError::EndsTooClose {
                span_code,
                min_span_code,
            } => write!(
                f,
                "the ends are {span_code} codes apart, fewer than the {min_span_code} a \
                 calibration needs"
            ),
            CalibrationError::EndInRail {
                at_start: true,
                code,
                rail_code,
            } => write!(
                f,
                "code_at_start {code} is inside the low rail band (at or below {rail_code})"
            ),
            CalibrationError::EndInRail {
                at_start: false,
                code,
                rail_code,
            } => write!(
                f,
                "code_at_end {code} is inside the high rail band (at or above {rail_code})"
            ),
            CalibrationError::BadLength { length_um } => write!(
                f,
                "length {} mm must be above 0 mm and at most {} mm",
                Milli(length_um as u64),
                Milli(MAX_LENGTH_UM as u64)
            ),
            CalibrationError::BadRailMargin {
                margin_code,
                limit_code,
            } => write!(
                f,
                "rail_margin_code {margin_code} must be above 0 and below {limit_code}"
            ),
        }
    }
}

/// A sensor reading that carries no position.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum SensorFault {
    /// Code at the low rail: open wiper or short to ground.
    RailLow,
    /// Code at the high rail: short to the supply.
    RailHigh,
    /// No sample for longer than the stale limit.
    Stale,
}

/// A validated calibration with its per-sample constants precomputed (done once, at load).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionMapper {
    cal: Calibration,
    rail_low: u16,
    rail_high: u16,
    /// µm per code in Q16, so the per-sample map is one multiply and one shift.
    um_per_code_q16: u32,
}

impl PositionMapper {
    /// Validates `cal` and precomputes the map.
    pub fn new(cal: Calibration) -> Result<Self, CalibrationError> {
        let fs = CODE_FULL_SCALE;
        if cal.rail_margin_code == 0 || cal.rail_margin_code as u32 >= fs / 4 {
            return Err(CalibrationError::BadRailMargin {
                margin_code: cal.rail_margin_code,
                limit_code: fs / 4,
            });
        }
        if cal.length_um == 0 || cal.length_um > MAX_LENGTH_UM {
            return Err(CalibrationError::BadLength {
                length_um: cal.length_um,
            });
        }
        if cal.code_at_end <= cal.code_at_start {
            return Err(CalibrationError::EndsSwapped {
                code_at_start: cal.code_at_start,
                code_at_end: cal.code_at_end,
            });
        }
        let span = cal.code_at_end - cal.code_at_start;
        if span < MIN_SPAN_CODE {
            return Err(CalibrationError::EndsTooClose {
                span_code: span,
                min_span_code: MIN_SPAN_CODE,
            });
        }
        let rail_low = cal.rail_margin_code;
        let rail_high = (fs - 1 - cal.rail_margin_code as u32) as u16;
        if cal.code_at_start <= rail_low {
            return Err(CalibrationError::EndInRail {
                at_start: true,
                code: cal.code_at_start,
                rail_code: rail_low,
            });
        }
        if cal.code_at_end >= rail_high {
            return Err(CalibrationError::EndInRail {
                at_start: false,
                code: cal.code_at_end,
                rail_code: rail_high,
            });
        }
        // Rounded, so the far end maps to length_um within one µm.
        let um_per_code_q16 = (((cal.length_um as u64) << 16) + span as u64 / 2) / span as u64;
        Ok(Self {
            cal,
            rail_low,
            rail_high,
            um_per_code_q16: um_per_code_q16 as u32,
        })
    }

    /// The calibration this mapper was built from.
    pub fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// Substrate length, µm.
    pub fn length_um(&self) -> u32 {
        self.cal.length_um
    }

    /// Position in µm from the start end, clamped to the calibrated travel (readings just beyond
    /// an end are mechanical slack, not a fault), or the rail fault.
    pub fn position_um(&self, sample: &Sample) -> Result<i32, SensorFault> {
        let code = sample.code;
        if code <= self.rail_low {
            return Err(SensorFault::RailLow);
        }
        if code >= self.rail_high {
            return Err(SensorFault::RailHigh);
        }
        let offset = code as i32 - self.cal.code_at_start as i32;
        let um = ((offset as i64 * self.um_per_code_q16 as i64) >> 16) as i32;
        // max/min, not clamp: clamp panics when its bounds cross, and this runs per sample.
        Ok(um.max(0).min(self.cal.length_um as i32))
    }

    /// The code at which position `um` reads (inverse map, for host models and tests).
    pub fn code_at_um(&self, um: f32) -> f32 {
        let span = (self.cal.code_at_end - self.cal.code_at_start) as f32;
        self.cal.code_at_start as f32 + um / self.cal.length_um as f32 * span
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(code: u16) -> Sample {
        Sample { code, t_us: 0 }
    }

    #[test]
    fn ends_map_to_zero_and_length() {
        let m = PositionMapper::new(Calibration::default()).unwrap();
        let c = Calibration::default();
        assert_eq!(m.position_um(&s(c.code_at_start)), Ok(0));
        let end = m.position_um(&s(c.code_at_end)).unwrap();
        assert!((end - 63_000).abs() <= 1, "{end}");
        let mid = m
            .position_um(&s((c.code_at_start + c.code_at_end) / 2))
            .unwrap();
        assert!((mid - 31_500).abs() <= 2, "{mid}");
    }

    #[test]
    fn rails_are_faults() {
        let m = PositionMapper::new(Calibration::default()).unwrap();
        assert_eq!(m.position_um(&s(0)), Err(SensorFault::RailLow));
        assert_eq!(m.position_um(&s(65_535)), Err(SensorFault::RailHigh));
        assert_eq!(m.position_um(&s(65_520)), Err(SensorFault::RailHigh));
    }

    /// The rail bands of the default calibration, at each threshold from both sides. Expected
    /// values are literals from the documented thresholds, not from the mapper: the margin is 1 %
    /// of the 65 536-code full scale, 655 codes; a code at or below 655 is the low rail, and a
    /// code at or above 65 535 − 655 = 64 880 (the top code less the margin) is the high rail.
    /// Just inside, the reading is mechanical slack beyond the calibrated ends (1 310 and
    /// 64 225) and clamps to the ends, 0 and 63 000 µm.
    #[test]
    fn rail_thresholds_from_both_sides() {
        let m = PositionMapper::new(Calibration::default()).unwrap();
        assert_eq!(DEFAULT_RAIL_MARGIN_CODE, 655);
        assert_eq!(m.position_um(&s(655)), Err(SensorFault::RailLow));
        assert_eq!(m.position_um(&s(656)), Ok(0));
        assert_eq!(m.position_um(&s(64_879)), Ok(63_000));
        assert_eq!(m.position_um(&s(64_880)), Err(SensorFault::RailHigh));
        // The top of the real range: 16 conversions of 4095.
        assert_eq!(m.position_um(&s(65_520)), Err(SensorFault::RailHigh));
    }

    /// The bands follow the calibration's own margin, not the default: 1 000 codes.
    #[test]
    fn rail_thresholds_follow_the_margin() {
        let m = PositionMapper::new(Calibration {
            rail_margin_code: 1_000,
            ..Calibration::default()
        })
        .unwrap();
        assert_eq!(m.position_um(&s(1_000)), Err(SensorFault::RailLow));
        assert_eq!(m.position_um(&s(1_001)), Ok(0));
        assert_eq!(m.position_um(&s(64_534)), Ok(63_000));
        assert_eq!(m.position_um(&s(64_535)), Err(SensorFault::RailHigh));
    }

    /// An open wiper is pulled down by the board's resistor, but the ADC still reads its offset
    /// and noise: a few LSB of each conversion, so 3 – 40 codes of the 16-conversion sum. All of
    /// them are the low rail, not position 0.
    #[test]
    fn open_wiper_reading_a_few_codes_is_the_low_rail() {
        let m = PositionMapper::new(Calibration::default()).unwrap();
        for code in 3..=40 {
            assert_eq!(
                m.position_um(&s(code)),
                Err(SensorFault::RailLow),
                "code {code}"
            );
        }
    }

    #[test]
    fn bad_calibrations_rejected() {
        let ok = Calibration::default();
        let swapped = Calibration {
            code_at_start: ok.code_at_end,
            code_at_end: ok.code_at_start,
            ..ok
        };
        assert_eq!(
            PositionMapper::new(swapped),
            Err(CalibrationError::EndsSwapped {
                code_at_start: ok.code_at_end,
                code_at_end: ok.code_at_start
            })
        );
        let close = Calibration {
            code_at_end: ok.code_at_start + 1000,
            ..ok
        };
        assert_eq!(
            PositionMapper::new(close),
            Err(CalibrationError::EndsTooClose {
                span_code: 1000,
                min_span_code: MIN_SPAN_CODE
            })
        );
        let rail = Calibration {
            code_at_start: 10,
            ..ok
        };
        assert_eq!(
            PositionMapper::new(rail),
            Err(CalibrationError::EndInRail {
                at_start: true,
                code: 10,
                rail_code: DEFAULT_RAIL_MARGIN_CODE
            })
        );
        let len = Calibration { length_um: 0, ..ok };
        assert_eq!(
            PositionMapper::new(len),
            Err(CalibrationError::BadLength { length_um: 0 })
        );
    }

    /// Each refusal reads as one sentence naming the scene file's fields.
    #[test]
    fn errors_read_as_sentences() {
        let cases = [
            (
                CalibrationError::EndsSwapped {
                    code_at_start: 3000,
                    code_at_end: 100,
                },
                "code_at_end 100 must be above code_at_start 3000",
            ),
            (
                CalibrationError::EndsTooClose {
                    span_code: 1000,
                    min_span_code: 16_384,
                },
                "the ends are 1000 codes apart, fewer than the 16384 a calibration needs",
            ),
            (
                CalibrationError::EndInRail {
                    at_start: true,
                    code: 10,
                    rail_code: 655,
                },
                "code_at_start 10 is inside the low rail band (at or below 655)",
            ),
            (
                CalibrationError::EndInRail {
                    at_start: false,
                    code: 65_000,
                    rail_code: 64_880,
                },
                "code_at_end 65000 is inside the high rail band (at or above 64880)",
            ),
            (
                CalibrationError::BadLength {
                    length_um: 1_000_500,
                },
                "length 1000.5 mm must be above 0 mm and at most 1000 mm",
            ),
            (
                CalibrationError::BadRailMargin {
                    margin_code: 0,
                    limit_code: 16_384,
                },
                "rail_margin_code 0 must be above 0 and below 16384",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence, "{e:?}");
        }
    }
}
