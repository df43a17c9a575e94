//! Touch frame: one reading of every phase ([`super::plates::SEQUENCE`]) turned into what a 2D
//! controller acts on — lifted, landing, down at (x, y) µm, or an axis fault — in the order
//! the 1D stage uses: contact first (lift-off is no fault), then the rails, then the map.

use super::calibration::Affine;
use super::fault::{AxisFault, RailBands};
use super::pressure::{
    touch_resistance_ohm, Contact, ContactTracker, PressureConfig, PressureError,
};

/// The codes of one frame, each a 16-conversion sum, and the time its last conversion ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    /// X phase, read on Y+.
    pub x_code: u16,
    /// Y phase, read on X+.
    pub y_code: u16,
    /// Z1 phase, read on X+.
    pub z1_code: u16,
    /// Z2 phase, read on Y−.
    pub z2_code: u16,
    /// Time of the frame's last conversion, µs (wrapping, as [`crate::sample::Sample::t_us`]).
    pub t_us: u32,
}

/// What one frame says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reading {
    /// No finger: carrier off, no fault counted.
    Lifted,
    /// A finger pressing for fewer frames than the recovery run: the position, carrier off.
    Landing {
        /// µm.
        x_um: i32,
        /// µm.
        y_um: i32,
    },
    /// A finger down: render the scene at this position.
    Down {
        /// µm.
        x_um: i32,
        /// µm.
        y_um: i32,
        /// The contact's resistance, Ω (a firmer press reads less).
        r_touch_ohm: u32,
    },
    /// Pressed, but an axis reads a rail: carrier off, counted as a fault, and touch-down
    /// waits for a new recovery run.
    Fault(AxisFault),
}

/// The touch sensor's per-frame state: contact tracking, rail bands and the calibration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TouchSensor {
    tracker: ContactTracker,
    rails: RailBands,
    map: Affine,
}

impl TouchSensor {
    /// A sensor with no finger on it.
    pub fn new(
        pressure: PressureConfig,
        rails: RailBands,
        map: Affine,
    ) -> Result<Self, PressureError> {
        Ok(Self {
            tracker: ContactTracker::new(pressure)?,
            rails,
            map,
        })
    }

    /// The contact state after the last frame.
    pub fn contact(&self) -> Contact {
        self.tracker.contact()
    }

    /// Runs one frame.
    pub fn on_frame(&mut self, frame: &Frame) -> Reading {
        let cfg = *self.tracker.config();
        let r = touch_resistance_ohm(
            cfg.r_x_plate_ohm,
            frame.x_code,
            frame.z1_code,
            frame.z2_code,
            cfg.min_z1_code,
        );
        let was_lifted = self.tracker.contact() == Contact::Lifted;
        let contact = self.tracker.update(r);
        if contact == Contact::Lifted {
            return Reading::Lifted;
        }
        let (x_code, y_code) = match self.rails.check_frame(frame.x_code, frame.y_code) {
            Ok(codes) => codes,
            Err(fault) => {
                self.tracker.restart_run();
                // The first pressed frame after a lift, with a position phase at a rail: the
                // finger landed during the frame, after its X or Y phase read the floating
                // plate (still at the last phase's rail) and before its Z pair read the
                // contact. The phases disagree about contact, so the frame is no finger yet,
                // not a fault (board model: 10 of 20 landings across a frame read so). The run
                // starts again (Landing, 0 frames), so a rail on the next frame is a fault.
                if was_lifted {
                    return Reading::Lifted;
                }
                return Reading::Fault(fault);
            }
        };
        let (x_um, y_um) = self.map.map(x_code, y_code);
        match (contact, r) {
            (Contact::Down, Some(r_touch_ohm)) => Reading::Down {
                x_um,
                y_um,
                r_touch_ohm,
            },
            _ => Reading::Landing { x_um, y_um },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::controller::RECOVERY_SAMPLES;
    use crate::position::SensorFault;
    use crate::touch::calibration::CalPoint;
    use crate::touch::fault::Axis;

    /// 1 µm per code on both axes, origin at code 10 000 (hand-made calibration).
    fn sensor() -> TouchSensor {
        let p = |x_code, y_code, x_um, y_um| CalPoint {
            x_code,
            y_code,
            x_um,
            y_um,
        };
        let map = Affine::from_points(
            [
                p(10_000, 10_000, 0, 0),
                p(50_000, 10_000, 40_000, 0),
                p(10_000, 50_000, 0, 40_000),
            ],
            &RailBands::default(),
        )
        .unwrap();
        // The hand-worked network below has ideal drivers: R_x alone.
        let pressure = PressureConfig {
            r_x_plate_ohm: 600,
            ..PressureConfig::DEFAULT
        };
        TouchSensor::new(pressure, RailBands::default(), map).unwrap()
    }

    /// The hand-worked 1 000 Ω network of `pressure`'s tests at x code 16 384.
    const PRESSED: Frame = Frame {
        x_code: 16_384,
        y_code: 30_000,
        z1_code: 7_282,
        z2_code: 55_826,
        t_us: 0,
    };
    /// No contact: X+ at X−'s 0 V, Y− at Y+'s VDD; the floating plate reads anything.
    const LIFTED: Frame = Frame {
        x_code: 65_000,
        y_code: 3,
        z1_code: 4,
        z2_code: 65_510,
        t_us: 0,
    };

    #[test]
    fn lifted_landing_down_and_lift_off_in_one_frame() {
        let mut s = sensor();
        assert_eq!(s.on_frame(&LIFTED), Reading::Lifted);
        for _ in 1..RECOVERY_SAMPLES {
            assert_eq!(
                s.on_frame(&PRESSED),
                Reading::Landing {
                    x_um: 6_384,
                    y_um: 20_000
                }
            );
        }
        match s.on_frame(&PRESSED) {
            Reading::Down {
                x_um: 6_384,
                y_um: 20_000,
                r_touch_ohm,
            } => assert!((999..=1_001).contains(&r_touch_ohm)),
            other => panic!("{other:?}"),
        }
        assert_eq!(s.on_frame(&LIFTED), Reading::Lifted);
    }

    /// A pressed frame with Y at the high rail (an open Y− leaves the Y plate at Y+'s VDD, or a
    /// short to the supply): a fault naming Y, and touch-down starts its run again.
    #[test]
    fn a_rail_while_pressed_is_a_fault_and_restarts_the_run() {
        let mut s = sensor();
        for _ in 0..RECOVERY_SAMPLES {
            s.on_frame(&PRESSED);
        }
        assert!(matches!(s.on_frame(&PRESSED), Reading::Down { .. }));
        let bad = Frame {
            y_code: 65_000,
            ..PRESSED
        };
        assert_eq!(
            s.on_frame(&bad),
            Reading::Fault(AxisFault {
                axis: Axis::Y,
                fault: SensorFault::RailHigh
            })
        );
        for _ in 1..RECOVERY_SAMPLES {
            assert!(matches!(s.on_frame(&PRESSED), Reading::Landing { .. }));
        }
        assert!(matches!(s.on_frame(&PRESSED), Reading::Down { .. }));
    }

    /// A finger landing mid-frame: the X phase read the floating plate at a rail before the
    /// contact, the Z pair read the contact. That frame is no finger (no fault); the run starts
    /// on the next frame, and touch-down still takes RECOVERY_SAMPLES good frames. A rail on the
    /// frame after is a fault: only a landing's own frame is excused.
    #[test]
    fn a_landing_during_the_frame_is_no_fault_but_a_rail_after_it_is() {
        for rail in [0, 65_535] {
            // The Z pair of a firm press: R_x · x · (Z2/Z1 − 1) = 600 · x · ⅓ ≤ 200 Ω wherever
            // the rail puts x, so the contact reads pressed whatever X read.
            let straddled = Frame {
                x_code: rail,
                z1_code: 30_000,
                z2_code: 40_000,
                ..PRESSED
            };
            let mut s = sensor();
            assert_eq!(s.on_frame(&LIFTED), Reading::Lifted);
            assert_eq!(s.on_frame(&straddled), Reading::Lifted, "x code {rail}");
            for _ in 1..RECOVERY_SAMPLES {
                assert!(matches!(s.on_frame(&PRESSED), Reading::Landing { .. }));
            }
            assert!(matches!(s.on_frame(&PRESSED), Reading::Down { .. }));

            let mut s = sensor();
            assert_eq!(s.on_frame(&LIFTED), Reading::Lifted);
            assert_eq!(s.on_frame(&straddled), Reading::Lifted);
            assert!(
                matches!(
                    s.on_frame(&straddled),
                    Reading::Fault(AxisFault { axis: Axis::X, .. })
                ),
                "x code {rail}: a second rail frame must be a fault"
            );
        }
    }

    /// With no contact the floating plate's rails are not faults: lift-off is not a fault.
    #[test]
    fn rails_without_contact_are_lift_off() {
        let mut s = sensor();
        for x_code in [0, 65_535] {
            let f = Frame { x_code, ..LIFTED };
            assert_eq!(s.on_frame(&f), Reading::Lifted);
        }
    }
}
