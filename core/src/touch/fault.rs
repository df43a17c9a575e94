//! Touch faults: the 1D stage's rail rule ([`crate::position`]) applied to each axis's
//! reading, so a broken or shorted terminal stops the carrier as an open wiper does.
//!
//! Only a pressed frame's positions are checked: with no contact the sensed plate floats and
//! its reading means nothing (that is lift-off, [`super::pressure`], not a fault). While
//! pressed, a reading in a rail band is a terminal that is open or shorted: an open X+ leaves
//! the X plate at X−'s 0 V (X at the low rail), an open X− leaves it at X+'s VDD (high rail),
//! an open sense wire leaves the ADC pin holding the charge of its last drive, and a short to
//! ground or supply pins the axis to that rail. The touch area must therefore lie inside the
//! bands, as the 1D calibration's ends must (the overlay's inactive border gives the room).

use crate::position::{CalibrationError, SensorFault, DEFAULT_RAIL_MARGIN_CODE};
use crate::sample::CODE_FULL_SCALE;

/// Which axis a reading belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Axis {
    /// Read in the X phase (on Y+).
    X,
    /// Read in the Y phase (on X+).
    Y,
}

/// A pressed frame whose axis reading carries no position.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AxisFault {
    /// The axis.
    pub axis: Axis,
    /// [`SensorFault::RailLow`] or [`SensorFault::RailHigh`], as the 1D stage names them.
    pub fault: SensorFault,
}

/// The rail bands of one axis: codes at or below `low`, or at or above `high`, are faults.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RailBands {
    low: u16,
    high: u16,
}

impl RailBands {
    /// The bands of `margin_code`, by the 1D rule (`PositionMapper::new`): the margin must be
    /// above 0 and below a quarter of full scale; low = margin, high = full scale − 1 − margin.
    /// Refused with the 1D stage's own error and sentence.
    pub fn new(margin_code: u16) -> Result<Self, CalibrationError> {
        let fs = CODE_FULL_SCALE;
        if margin_code == 0 || margin_code as u32 >= fs / 4 {
            return Err(CalibrationError::BadRailMargin {
                margin_code,
                limit_code: fs / 4,
            });
        }
        Ok(Self {
            low: margin_code,
            high: (fs - 1 - margin_code as u32) as u16,
        })
    }

    /// The highest code of the low band.
    pub fn low(&self) -> u16 {
        self.low
    }

    /// The lowest code of the high band.
    pub fn high(&self) -> u16 {
        self.high
    }

    /// True when `code` lies strictly between the bands.
    pub fn inside(&self, code: u16) -> bool {
        code > self.low && code < self.high
    }

    /// `code` if it carries a position, else the axis's fault.
    pub fn check(&self, axis: Axis, code: u16) -> Result<u16, AxisFault> {
        if code <= self.low {
            Err(AxisFault {
                axis,
                fault: SensorFault::RailLow,
            })
        } else if code >= self.high {
            Err(AxisFault {
                axis,
                fault: SensorFault::RailHigh,
            })
        } else {
            Ok(code)
        }
    }

    /// Both axes of a pressed frame, X first: the first fault, or both codes.
    pub fn check_frame(&self, x_code: u16, y_code: u16) -> Result<(u16, u16), AxisFault> {
        Ok((self.check(Axis::X, x_code)?, self.check(Axis::Y, y_code)?))
    }
}

impl Default for RailBands {
    /// The 1D stage's default margin, 1 % of full scale (655 codes).
    fn default() -> Self {
        Self {
            low: DEFAULT_RAIL_MARGIN_CODE,
            high: (CODE_FULL_SCALE - 1 - DEFAULT_RAIL_MARGIN_CODE as u32) as u16,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::position::{Calibration, PositionMapper};
    use crate::sample::Sample;

    /// The bands agree with the 1D stage's on every code: the same code is RailLow, RailHigh
    /// or a position in both, at the default margin and at another. (Seen failing with
    /// `<=` written `<` in `check`: code 655 then passed here and was RailLow in 1D.)
    #[test]
    fn bands_agree_with_the_1d_rule_on_every_code() {
        for margin in [DEFAULT_RAIL_MARGIN_CODE, 1_000] {
            let bands = RailBands::new(margin).unwrap();
            let mapper = PositionMapper::new(Calibration {
                rail_margin_code: margin,
                ..Calibration::default()
            })
            .unwrap();
            for code in 0..=u16::MAX {
                let one_d = mapper.position_um(&Sample { code, t_us: 0 }).err();
                let two_d = bands.check(Axis::Y, code).err().map(|f| f.fault);
                assert_eq!(one_d, two_d, "margin {margin} code {code}");
            }
        }
    }

    /// The thresholds as literals (1 % of 65 536 = 655; 65 535 − 655 = 64 880), from both
    /// sides, and the axis named in the fault.
    #[test]
    fn thresholds_and_axis() {
        let b = RailBands::default();
        assert_eq!(b, RailBands::new(655).unwrap());
        assert_eq!((b.low(), b.high()), (655, 64_880));
        let low = |axis| AxisFault {
            axis,
            fault: SensorFault::RailLow,
        };
        let high = |axis| AxisFault {
            axis,
            fault: SensorFault::RailHigh,
        };
        assert_eq!(b.check(Axis::X, 655), Err(low(Axis::X)));
        assert_eq!(b.check(Axis::X, 656), Ok(656));
        assert_eq!(b.check(Axis::Y, 64_879), Ok(64_879));
        assert_eq!(b.check(Axis::Y, 64_880), Err(high(Axis::Y)));
        // X is checked first; a good X and a bad Y name Y.
        assert_eq!(b.check_frame(0, 65_535), Err(low(Axis::X)));
        assert_eq!(b.check_frame(30_000, 65_535), Err(high(Axis::Y)));
        assert_eq!(b.check_frame(30_000, 20_000), Ok((30_000, 20_000)));
        // `inside` (the calibration's test) draws the same edges. (cargo-mutants' `>` → `>=`
        // and `<` → `<=` there survived the tests above.)
        assert!(!b.inside(655) && b.inside(656));
        assert!(b.inside(64_879) && !b.inside(64_880));
    }

    #[test]
    fn a_bad_margin_is_refused_with_the_1d_sentence() {
        let e = RailBands::new(0).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "rail_margin_code 0 must be above 0 and below 16384"
        );
        assert!(RailBands::new(16_384).is_err());
        assert!(RailBands::new(16_383).is_ok());
    }
}
