//! Touch pressure: the contact's resistance from the Z1/Z2 pair, and touch-down / lift-off
//! with hysteresis. Lift-off is not a fault: it ends the touch at once; touch-down waits for
//! the 1D stage's recovery run of good frames.
//!
//! With Y+ high and X− low the current runs Y+ → Y plate → contact → X plate → X−. X+ hangs off
//! the X plate at the contact, so it reads the drop across R_x·x (Z1); Y− hangs off the Y plate
//! there, so it reads that plus the drop across the contact (Z2). Their ratio is
//! Z2/Z1 = (R_touch + R_x·x)/(R_x·x), hence R_touch = R_x · x · (Z2/Z1 − 1) with x the X
//! reading as a fraction of full scale (TI TSC2101 data sheet, "Measuring touch pressure",
//! eq. 1: R_TOUCH = R_X-plate · (X-position/4096) · (Z2/Z1 − 1); the same in TSC2046/ADS7846
//! and Microchip's SAM9 touchscreen controller, "4-wire pressure measurement method"). The ratio
//! needs no reference and no Y plate figure; only R_x, which the panel's data sheet or an
//! ohmmeter gives.

use crate::controller::RECOVERY_SAMPLES;
use crate::position::DEFAULT_RAIL_MARGIN_CODE;
use crate::sample::CODE_FULL_SCALE;
use core::fmt;

/// The contact's resistance, Ω, from the X position code and the Z1/Z2 codes (all on one
/// scale, the 16-conversion sum), rounded to the nearest ohm and saturated at `u32::MAX`.
/// `None` when Z1 is at or below `min_z1_code`: no current reaches X+, so no contact (lift-off,
/// not a fault). Z2 ≤ Z1 (a firm press inside the noise) reads 0 Ω.
pub fn touch_resistance_ohm(
    r_x_plate_ohm: u32,
    x_code: u16,
    z1_code: u16,
    z2_code: u16,
    min_z1_code: u16,
) -> Option<u32> {
    if z1_code <= min_z1_code || z1_code == 0 {
        return None;
    }
    let diff = z2_code.saturating_sub(z1_code) as u128;
    // ≤ 2^32 · 2^16 · 2^16 = 2^64 over ≤ 2^17 · 2^16: no overflow in u128, whatever R_x.
    let num = r_x_plate_ohm as u128 * x_code as u128 * diff;
    let den = CODE_FULL_SCALE as u128 * z1_code as u128;
    let r = (num + den / 2) / den;
    Some(u32::try_from(r).unwrap_or(u32::MAX))
}

/// Thresholds of touch-down and lift-off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PressureConfig {
    /// X plate resistance as the formula needs it, Ω: the plate X+ to X−
    /// ([`super::plates::PlateRc::r_x_plate_ohm`]) plus both drivers' output resistance. The
    /// X reading spans the drivers' drops too (the code is (R_drive + R_x·x)/(R_x + 2·R_drive)
    /// of full scale), and the Z1 leg holds R_drive + R_x·x, so R_x + 2·R_drive makes the
    /// formula exact; the bare plate would read the contact low by R_x/(R_x + 2·R_drive), 14 %
    /// with 50 Ω drivers on 600 Ω (the CP3BT26 data sheet §16.2.3 counts the same drops).
    pub r_x_plate_ohm: u32,
    /// A frame at or below this contact resistance counts toward touch-down, Ω.
    pub touch_ohm: u32,
    /// A frame above this contact resistance (or with no contact) is lift-off, Ω. Above
    /// `touch_ohm`: between the two the state holds, so a finger easing its press does not
    /// chatter the carrier.
    pub lift_ohm: u32,
    /// Z1 at or below this code is no contact: the 1D stage's low rail band (1 % of full
    /// scale), the same rule that calls an open wiper.
    pub min_z1_code: u16,
}

impl PressureConfig {
    /// Touch-down at 1.5 kΩ, lift-off above 3 kΩ, on the default 600 Ω X plate and 50 Ω
    /// drivers (700 Ω, [`super::plates::PlateRc::DEFAULT`]). Finger
    /// contact on a 4-wire panel runs from a few hundred ohms (a firm press) to kilo-ohms (a
    /// light one); these are starting figures to set on the panel with `host-sim`'s model and
    /// then on a real finger (`docs/touch.md`).
    pub const DEFAULT: PressureConfig = PressureConfig {
        r_x_plate_ohm: 700,
        touch_ohm: 1_500,
        lift_ohm: 3_000,
        min_z1_code: DEFAULT_RAIL_MARGIN_CODE,
    };

    /// Checks the thresholds.
    pub fn validate(self) -> Result<Self, PressureError> {
        if !(MIN_PLATE_OHM..=MAX_PLATE_OHM).contains(&self.r_x_plate_ohm) {
            return Err(PressureError::PlateOutOfRange {
                r_x_plate_ohm: self.r_x_plate_ohm,
            });
        }
        if self.touch_ohm == 0 || self.lift_ohm > MAX_LIFT_OHM {
            return Err(PressureError::ThresholdOutOfRange {
                touch_ohm: self.touch_ohm,
                lift_ohm: self.lift_ohm,
            });
        }
        if self.lift_ohm <= self.touch_ohm {
            return Err(PressureError::NoHysteresis {
                touch_ohm: self.touch_ohm,
                lift_ohm: self.lift_ohm,
            });
        }
        if self.min_z1_code == 0 || self.min_z1_code as u32 >= CODE_FULL_SCALE / 4 {
            return Err(PressureError::BadMinZ1 {
                min_z1_code: self.min_z1_code,
            });
        }
        Ok(self)
    }
}

impl Default for PressureConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

const MIN_PLATE_OHM: u32 = 50;
const MAX_PLATE_OHM: u32 = 10_000;
const MAX_LIFT_OHM: u32 = 1_000_000;

/// Why pressure thresholds were refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum PressureError {
    /// `r_x_plate_ohm` outside 50 to 10 000 Ω.
    PlateOutOfRange {
        /// The value given, Ω.
        r_x_plate_ohm: u32,
    },
    /// `touch_ohm` is zero or `lift_ohm` above 1 MΩ.
    ThresholdOutOfRange {
        /// The touch-down threshold, Ω.
        touch_ohm: u32,
        /// The lift-off threshold, Ω.
        lift_ohm: u32,
    },
    /// `lift_ohm` is not above `touch_ohm`.
    NoHysteresis {
        /// The touch-down threshold, Ω.
        touch_ohm: u32,
        /// The lift-off threshold, Ω.
        lift_ohm: u32,
    },
    /// `min_z1_code` is zero or a quarter of full scale or more.
    BadMinZ1 {
        /// The value given.
        min_z1_code: u16,
    },
}

impl fmt::Display for PressureError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            PressureError::PlateOutOfRange { r_x_plate_ohm } => write!(
                f,
                "r_x_plate_ohm {r_x_plate_ohm} Ω is outside the accepted \
                 {MIN_PLATE_OHM} to {MAX_PLATE_OHM} Ω"
            ),
            PressureError::ThresholdOutOfRange {
                touch_ohm,
                lift_ohm,
            } => write!(
                f,
                "touch_ohm {touch_ohm} Ω must be above 0 and lift_ohm {lift_ohm} Ω at most \
                 {MAX_LIFT_OHM} Ω"
            ),
            PressureError::NoHysteresis {
                touch_ohm,
                lift_ohm,
            } => write!(
                f,
                "lift_ohm {lift_ohm} Ω must be above touch_ohm {touch_ohm} Ω"
            ),
            PressureError::BadMinZ1 { min_z1_code } => write!(
                f,
                "min_z1_code {min_z1_code} must be above 0 and below {}",
                CODE_FULL_SCALE / 4
            ),
        }
    }
}

/// Whether a finger is on the overlay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Contact {
    /// No finger (or too light a press): the carrier is off, and no fault is counted.
    Lifted,
    /// Pressed for `run` good frames, fewer than [`RECOVERY_SAMPLES`]: positions read, the
    /// carrier still off (the 1D stage's recovery rule: a bouncing contact must not flash it).
    Landing {
        /// Consecutive good frames so far, 1 ..= RECOVERY_SAMPLES − 1.
        run: u16,
    },
    /// Pressed for at least [`RECOVERY_SAMPLES`] good frames in a row and not lifted since.
    Down,
}

/// Touch-down and lift-off from one contact resistance per frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ContactTracker {
    cfg: PressureConfig,
    state: Contact,
}

impl ContactTracker {
    /// A tracker with no finger on the overlay.
    pub fn new(cfg: PressureConfig) -> Result<Self, PressureError> {
        Ok(Self {
            cfg: cfg.validate()?,
            state: Contact::Lifted,
        })
    }

    /// The thresholds.
    pub fn config(&self) -> &PressureConfig {
        &self.cfg
    }

    /// The state after the last frame.
    pub fn contact(&self) -> Contact {
        self.state
    }

    /// One frame's contact resistance (`None`: no contact). Lift-off acts on the frame that
    /// shows it; touch-down needs [`RECOVERY_SAMPLES`] frames in a row at or below
    /// `touch_ohm`. While down, resistances up to `lift_ohm` keep it down.
    pub fn update(&mut self, r_touch_ohm: Option<u32>) -> Contact {
        let r = r_touch_ohm.unwrap_or(u32::MAX);
        self.state = match self.state {
            Contact::Down if r <= self.cfg.lift_ohm => Contact::Down,
            Contact::Down => Contact::Lifted,
            Contact::Lifted | Contact::Landing { .. } if r > self.cfg.touch_ohm => Contact::Lifted,
            Contact::Lifted => Self::landed(1),
            Contact::Landing { run } => Self::landed(run.saturating_add(1)),
        };
        self.state
    }

    /// A frame that was pressed but whose position is faulty: the run of good frames starts
    /// again (as the 1D stage's fault does), and a finger that was down is down no longer.
    /// The caller turns the carrier off for the fault.
    pub fn restart_run(&mut self) {
        if self.state != Contact::Lifted {
            self.state = Contact::Landing { run: 0 };
        }
    }

    fn landed(run: u16) -> Contact {
        if run >= RECOVERY_SAMPLES {
            Contact::Down
        } else {
            Contact::Landing { run }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Codes of a resistor network worked by hand, not by the function: R_x = 600 Ω,
    /// R_y = 400 Ω, the finger at x = ¼, y = ½ with 1 000 Ω of contact. X phase: x · 65 536 =
    /// 16 384. Z phase: the path is R_y·(1 − y) = 200, the contact 1 000, R_x·x = 150, in all
    /// 1 350 Ω; X+ reads 150/1350 · 65 536 = 7 281.8 → 7 282, Y− reads 1150/1350 · 65 536 =
    /// 55 826.0 → 55 826. The formula must give back the 1 000 Ω within the codes' rounding
    /// (½ code of Z1 is 0.007 % of it: ±1 Ω).
    #[test]
    fn resistance_of_a_hand_worked_network() {
        let r = touch_resistance_ohm(600, 16_384, 7_282, 55_826, DEFAULT_RAIL_MARGIN_CODE);
        let r = r.unwrap();
        assert!((999..=1_001).contains(&r), "{r}");
        // A firmer press, 200 Ω: total 550 Ω, Z1 = 150/550 · 65 536 = 17 873.5 → 17 873,
        // Z2 = 350/550 · 65 536 = 41 704.7 → 41 705.
        let r = touch_resistance_ohm(600, 16_384, 17_873, 41_705, 655).unwrap();
        assert!((199..=201).contains(&r), "{r}");
    }

    /// Rounded to the nearest ohm, halves up, by hand: R_x = 3 Ω at x = ½ with Z2/Z1 = 2 is
    /// 3 · ½ · 1 = 1.5 → 2 Ω; with Z2/Z1 = 1.8, 1.2 → 1 Ω. (Seen failing with the rounding
    /// term dropped, cargo-mutants' `den / 2` → `den % 2`: 1.5 floored to 1.)
    #[test]
    fn rounds_to_the_nearest_ohm() {
        assert_eq!(touch_resistance_ohm(3, 32_768, 1_000, 2_000, 655), Some(2));
        assert_eq!(touch_resistance_ohm(3, 32_768, 1_000, 1_800, 655), Some(1));
    }

    #[test]
    fn no_current_through_x_plus_is_no_contact() {
        assert_eq!(touch_resistance_ohm(600, 30_000, 0, 65_520, 655), None);
        assert_eq!(touch_resistance_ohm(600, 30_000, 655, 65_000, 655), None);
        assert!(touch_resistance_ohm(600, 30_000, 656, 65_000, 655).is_some());
        // Z2 below Z1 (noise on a firm press) is 0 Ω, not a wrap to 4 GΩ.
        assert_eq!(
            touch_resistance_ohm(600, 30_000, 20_000, 19_990, 655),
            Some(0)
        );
        // Extremes saturate rather than overflow: 2^32 Ω · 65 535/65 536 · 64 879/656 is far
        // past u32.
        assert_eq!(
            touch_resistance_ohm(u32::MAX, u16::MAX, 656, u16::MAX, 655),
            Some(u32::MAX)
        );
    }

    fn tracker() -> ContactTracker {
        ContactTracker::new(PressureConfig::DEFAULT).unwrap()
    }

    /// Touch-down after exactly 16 frames at or below 1 500 Ω (RECOVERY_SAMPLES, the 1D rule);
    /// the 15th is still landing.
    #[test]
    fn touch_down_waits_for_the_recovery_run() {
        let mut t = tracker();
        for run in 1..=15 {
            assert_eq!(t.update(Some(1_500)), Contact::Landing { run });
        }
        assert_eq!(t.update(Some(1_500)), Contact::Down);
        assert_eq!(RECOVERY_SAMPLES, 16);
    }

    /// Lift-off acts on the first frame above 3 000 Ω, or with no contact: one frame.
    #[test]
    fn lift_off_acts_within_one_frame() {
        for lifted in [Some(3_001), None] {
            let mut t = tracker();
            for _ in 0..16 {
                t.update(Some(800));
            }
            assert_eq!(t.contact(), Contact::Down);
            assert_eq!(t.update(lifted), Contact::Lifted, "{lifted:?}");
        }
    }

    /// Between 1 500 and 3 000 Ω the state holds: down stays down, lifted stays lifted.
    /// (Seen failing with the lift test on `touch_ohm` instead of `lift_ohm`: a press easing to
    /// 2 000 Ω then read as lift-off.)
    #[test]
    fn hysteresis_holds_the_state_between_the_thresholds() {
        let mut t = tracker();
        for _ in 0..16 {
            t.update(Some(1_000));
        }
        for r in [1_501, 2_000, 3_000] {
            assert_eq!(t.update(Some(r)), Contact::Down, "{r}");
        }
        let mut t = tracker();
        for r in [1_501, 2_000, 3_000] {
            assert_eq!(t.update(Some(r)), Contact::Lifted, "{r}");
        }
    }

    /// A bounce (one frame light) while landing starts the run again, as the 1D recovery does.
    #[test]
    fn a_bounce_while_landing_restarts_the_run() {
        let mut t = tracker();
        for _ in 0..10 {
            t.update(Some(1_000));
        }
        assert_eq!(t.update(Some(2_000)), Contact::Lifted);
        assert_eq!(t.update(Some(1_000)), Contact::Landing { run: 1 });
        // A position fault restarts it too, and takes a finger that was down back to landing.
        for _ in 0..20 {
            t.update(Some(1_000));
        }
        t.restart_run();
        assert_eq!(t.contact(), Contact::Landing { run: 0 });
        assert_eq!(t.update(Some(1_000)), Contact::Landing { run: 1 });
    }

    #[test]
    fn bad_thresholds_are_refused_with_a_sentence() {
        let cases = [
            (
                PressureConfig {
                    lift_ohm: 1_500,
                    ..PressureConfig::DEFAULT
                },
                "lift_ohm 1500 Ω must be above touch_ohm 1500 Ω",
            ),
            (
                PressureConfig {
                    r_x_plate_ohm: 20_000,
                    ..PressureConfig::DEFAULT
                },
                "r_x_plate_ohm 20000 Ω is outside the accepted 50 to 10000 Ω",
            ),
            (
                PressureConfig {
                    touch_ohm: 0,
                    ..PressureConfig::DEFAULT
                },
                "touch_ohm 0 Ω must be above 0 and lift_ohm 3000 Ω at most 1000000 Ω",
            ),
            (
                PressureConfig {
                    min_z1_code: 0,
                    ..PressureConfig::DEFAULT
                },
                "min_z1_code 0 must be above 0 and below 16384",
            ),
        ];
        for (cfg, sentence) in cases {
            let e = ContactTracker::new(cfg).unwrap_err();
            assert_eq!(std::format!("{e}"), sentence);
        }
        // Each limit from both sides (cargo-mutants' `>` → `>=` / `==` on lift_ohm's and
        // `/ 4` → `* 4` on min_z1_code's survived the cases above).
        let with = |lift_ohm, min_z1_code| PressureConfig {
            lift_ohm,
            min_z1_code,
            ..PressureConfig::DEFAULT
        };
        assert!(with(1_000_000, 655).validate().is_ok());
        assert!(with(1_000_001, 655).validate().is_err());
        assert!(with(3_000, 16_383).validate().is_ok());
        assert!(with(3_000, 16_384).validate().is_err());
    }
}
