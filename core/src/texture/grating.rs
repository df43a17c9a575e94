//! Grating texture: a virtual grating of spatial period λ (Konyo et al.: f = V/λ, so the felt
//! spatial period does not depend on hand speed), rendered one of two ways.
//!
//! - [`GratingRender::PositionPhase`] (the default): one burst per ridge crossing, taken from the
//!   position itself. A ridge sits at every multiple of λ; crossing it fires one pulse lasting
//!   duty·λ/|V| (the time the finger needs to cover the ridge's share of the period). Velocity
//!   only sizes the pulse, so bursts land where the ridges are whatever the estimator's lag:
//!   measured 7–15 µm RMS at 20–200 mm/s against 63–344 µm for velocity synthesis
//!   (docs/estimators.md). A ridge that fired is disarmed until the finger is `rearm_um` clear
//!   of it, so noise on a ridge fires nothing and a real back-and-forth fires once per crossing.
//! - [`GratingRender::VelocitySynthesis`]: periodic bursts at f = |V|/λ on the burst timer. Its
//!   frequency is right but its phase is free, and the estimator's lag puts the bursts
//!   v × 3.3 ms behind the ridges. Below `min_speed_um_s` no bursts are made (at rest the
//!   velocity estimate is noise); the threshold has hysteresis (off below half of it).

use super::{SpreadParam, TextureError};

/// How a grating turns motion into bursts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GratingRender {
    /// One pulse per ridge crossing, placed by position (see the module doc).
    #[default]
    PositionPhase,
    /// Periodic bursts at f = |V|/λ (see the module doc).
    VelocitySynthesis,
}

/// Default re-arm distance of a ridge, µm: 8.7 σ of the position noise at 3 LSB with 16×
/// oversampling (11.5 µm), so a finger resting on a ridge never re-fires it.
pub const DEFAULT_REARM_UM: u32 = 100;

/// A grating region's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Grating {
    /// Spatial period λ, µm (grooved tile: ridge width + groove width).
    pub wavelength_um: u32,
    /// Duty of each burst, ‰ (the ridge's share of the period).
    pub duty_permille: u16,
    /// Velocity synthesis only: bursts start above this speed, µm/s, and stop below half of it.
    pub min_speed_um_s: u32,
    /// Drive amplitude, ‰ (tile-to-scene sets it from the skin model's A).
    pub amplitude_permille: u16,
    /// How bursts are made.
    pub render: GratingRender,
    /// Position phase only: distance the finger must move clear of a fired ridge before it can
    /// fire again, µm; below λ/2 so every ridge re-arms on the way to the next.
    pub rearm_um: u32,
}

impl Grating {
    /// A grating of period `wavelength_um`: position phase, 40 % duty, full drive, re-arm at
    /// 100 µm (or λ/4 for gratings finer than 0.4 mm); 15 mm/s start threshold should velocity
    /// synthesis be chosen (below it, noise at rest fires bursts: docs/estimators.md).
    pub const fn new(wavelength_um: u32) -> Self {
        let quarter = wavelength_um / 4;
        Self {
            wavelength_um,
            duty_permille: 400,
            min_speed_um_s: 15_000,
            amplitude_permille: 1000,
            render: GratingRender::PositionPhase,
            rearm_um: if quarter < DEFAULT_REARM_UM {
                quarter
            } else {
                DEFAULT_REARM_UM
            },
        }
    }

    /// Checks the parameters against a substrate of `length_um`.
    pub fn validate(&self, length_um: u32) -> Result<(), TextureError> {
        if self.wavelength_um == 0 || self.wavelength_um > length_um {
            return Err(TextureError::BadWavelength {
                wavelength_um: self.wavelength_um,
                length_um,
            });
        }
        if self.min_speed_um_s > 1_000_000 {
            return Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: self.min_speed_um_s,
            });
        }
        if self.amplitude_permille == 0 || self.amplitude_permille > 1000 {
            return Err(TextureError::BadSpread {
                param: SpreadParam::Amplitude,
                permille: self.amplitude_permille,
            });
        }
        if self.render == GratingRender::PositionPhase
            && self.rearm_um.saturating_mul(2) >= self.wavelength_um
        {
            return Err(TextureError::BadRearm {
                rearm_um: self.rearm_um,
                wavelength_um: self.wavelength_um,
            });
        }
        Ok(())
    }
}

/// Position-phase ridge tracking: which cell of the grating the finger is in and which ridge
/// is disarmed. Integer only: one division per sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct RidgeTracker {
    /// Cell index k of the last sample, position in [kλ, (k+1)λ).
    cell: Option<i32>,
    /// The ridge (index k, at kλ) that fired last and is not yet re-armed.
    disarmed: Option<i32>,
}

/// A ridge crossing seen on one sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Crossing {
    /// Ridge index k (the ridge at kλ).
    pub ridge: i32,
    /// Further ridges passed within the same sample (too fast for one pulse each).
    pub skipped: u32,
    /// Crossed moving towards +x.
    pub up: bool,
}

impl RidgeTracker {
    /// Forgets the finger's place (region change, fault).
    pub(crate) fn reset(&mut self) {
        *self = Self::default();
    }

    /// Updates with a position; returns the armed ridge crossed since the last sample, if any.
    /// On the first sample the nearest ridge, if within `rearm_um`, starts disarmed: arriving
    /// at rest on a ridge is not a crossing.
    pub(crate) fn update(
        &mut self,
        position_um: i32,
        wavelength_um: i32,
        rearm_um: i32,
    ) -> Option<Crossing> {
        let cell = position_um.div_euclid(wavelength_um);
        let offset = position_um - cell * wavelength_um;
        // The nearest ridge and the distance to it.
        let (near, dist) = if offset * 2 < wavelength_um {
            (cell, offset)
        } else {
            (cell + 1, wavelength_um - offset)
        };
        let mut crossing = None;
        match self.cell {
            None => {
                if dist <= rearm_um {
                    self.disarmed = Some(near);
                }
            }
            // Same cell: no ridge passed.
            Some(prev) if prev == cell => {}
            Some(prev) => {
                // Moving up the last ridge passed is `cell`'s lower edge; moving down, `prev`'s:
                // the higher cell's either way.
                let (ridge, passed) = (cell.max(prev), cell.abs_diff(prev));
                if self.disarmed != Some(ridge) || passed > 1 {
                    crossing = Some(Crossing {
                        ridge,
                        skipped: passed - 1,
                        // The cells differ here, so the higher one being `cell` means up.
                        up: ridge == cell,
                    });
                    self.disarmed = Some(ridge);
                }
            }
        }
        self.cell = Some(cell);
        if let Some(r) = self.disarmed {
            if r != near || dist > rearm_um {
                self.disarmed = None;
            }
        }
        crossing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn crossings(t: &mut RidgeTracker, path: impl Iterator<Item = i32>) -> (u32, u32) {
        let (mut fired, mut skipped) = (0, 0);
        for p in path {
            if let Some(c) = t.update(p, 1_000, 100) {
                fired += 1;
                skipped += c.skipped;
            }
        }
        (fired, skipped)
    }

    #[test]
    fn one_crossing_per_ridge_each_way() {
        let mut t = RidgeTracker::default();
        // Up from 0.5 mm to 10.5 mm at 7 µm per sample, then back down: 10 ridges each way.
        let up = (500..10_500).step_by(7);
        let down = (500..10_500).rev().step_by(7);
        assert_eq!(crossings(&mut t, up.chain(down)), (20, 0));
    }

    #[test]
    fn the_crossing_fires_on_the_sample_past_the_ridge() {
        let mut t = RidgeTracker::default();
        assert_eq!(t.update(850, 1_000, 100), None);
        assert_eq!(t.update(999, 1_000, 100), None);
        let c = t.update(1_000, 1_000, 100).map(|c| c.ridge);
        assert_eq!(c, Some(1));
        // Downwards the same ridge fires on the first sample below it, once re-armed.
        assert_eq!(t.update(1_200, 1_000, 100), None);
        assert_eq!(t.update(1_000, 1_000, 100), None);
        assert_eq!(t.update(999, 1_000, 100).map(|c| c.ridge), Some(1));
        // Negative positions (below the substrate's zero) use floor, not truncation.
        let mut t = RidgeTracker::default();
        t.update(-500, 1_000, 100);
        assert_eq!(t.update(-1_001, 1_000, 100).map(|c| c.ridge), Some(-1));
    }

    #[test]
    fn dither_on_a_ridge_fires_once_and_resting_there_never() {
        let dither = |i: i32| ((i * 37) % 181) - 90; // ±90 µm, inside the 100 µm re-arm
                                                     // Arriving from below: one crossing, then silence however long the dither lasts.
        let mut t = RidgeTracker::default();
        let path = (4_500..5_000)
            .step_by(10)
            .chain((0..20_000).map(|i| 5_000 + dither(i)));
        assert_eq!(crossings(&mut t, path), (1, 0));
        // Starting at rest on the ridge: nothing at all.
        let mut t = RidgeTracker::default();
        assert_eq!(
            crossings(&mut t, (0..20_000).map(|i| 5_000 + dither(i))),
            (0, 0)
        );
        // Beyond the re-arm distance and back is a real second crossing.
        let mut t = RidgeTracker::default();
        let path = [4_800, 5_010, 5_150, 4_990, 4_850, 5_020];
        assert_eq!(crossings(&mut t, path.into_iter()), (3, 0));
    }

    #[test]
    fn several_ridges_in_one_sample_fire_once_and_count_the_rest() {
        let mut t = RidgeTracker::default();
        // 3.5 mm per sample: three ridges per step.
        let (fired, skipped) = crossings(&mut t, (0..10).map(|i| 500 + i * 3_500));
        assert_eq!(fired, 9);
        // From 0.5 mm to 32 mm the finger passed ridges 1..=32: every one fired or was counted.
        assert_eq!(fired + skipped, 32);
    }

    /// Re-arming to the µm: a ridge that fired stays disarmed while the finger is within
    /// `rearm` (100 µm) of it, inclusive, and re-arms one µm further. Crossings say their
    /// direction, and a jump over two ridges fires even when the nearer one is disarmed.
    #[test]
    fn rearm_edge_direction_and_jumps() {
        for (away, fires_back) in [(1_100, false), (1_101, true)] {
            let mut t = RidgeTracker::default();
            assert_eq!(t.update(500, 1_000, 100), None);
            let up = t.update(1_000, 1_000, 100).unwrap();
            assert_eq!((up.ridge, up.up, up.skipped), (1, true, 0));
            assert_eq!(t.update(away, 1_000, 100), None);
            let back = t.update(999, 1_000, 100);
            assert_eq!(back.is_some(), fires_back, "away to {away} um");
            if let Some(c) = back {
                assert_eq!((c.ridge, c.up), (1, false));
            }
        }
        let mut t = RidgeTracker::default();
        t.update(500, 1_000, 100);
        t.update(1_000, 1_000, 100);
        // Ridge 1 is disarmed; one sample later the finger is at -0.5 mm: ridges 1 and 0.
        let c = t.update(-500, 1_000, 100).unwrap();
        assert_eq!((c.ridge, c.skipped, c.up), (1, 1, false));
    }

    #[test]
    fn validation() {
        let g = Grating::new(1_000);
        assert_eq!(g.rearm_um, 100);
        assert!(g.validate(63_000).is_ok());
        assert_eq!(Grating::new(200).rearm_um, 50);
        let bad = Grating { rearm_um: 500, ..g };
        assert_eq!(
            bad.validate(63_000),
            Err(TextureError::BadRearm {
                rearm_um: 500,
                wavelength_um: 1_000
            })
        );
        let synth = Grating {
            render: GratingRender::VelocitySynthesis,
            ..bad
        };
        assert!(synth.validate(63_000).is_ok());
        assert_eq!(
            Grating::new(0).validate(63_000),
            Err(TextureError::BadWavelength {
                wavelength_um: 0,
                length_um: 63_000
            })
        );
        // Each limit from both sides: a wavelength up to the substrate's length, a start
        // threshold up to 1 m/s, amplitude 1–1000 ‰, rearm below half a wavelength.
        assert!(Grating::new(63_000).validate(63_000).is_ok());
        assert_eq!(
            Grating::new(63_001).validate(63_000),
            Err(TextureError::BadWavelength {
                wavelength_um: 63_001,
                length_um: 63_000
            })
        );
        let speed = |min_speed_um_s| {
            Grating {
                min_speed_um_s,
                ..g
            }
            .validate(63_000)
        };
        assert_eq!(speed(1_000_000), Ok(()));
        assert_eq!(
            speed(1_000_001),
            Err(TextureError::BadSpeedThreshold {
                min_speed_um_s: 1_000_001
            })
        );
        let amp = |amplitude_permille| {
            Grating {
                amplitude_permille,
                ..g
            }
            .validate(63_000)
        };
        assert_eq!(amp(1), Ok(()));
        assert_eq!(amp(1_000), Ok(()));
        let bad_amp = |permille| {
            Err(TextureError::BadSpread {
                param: SpreadParam::Amplitude,
                permille,
            })
        };
        assert_eq!(amp(0), bad_amp(0));
        assert_eq!(amp(1_001), bad_amp(1_001));
        let rearm = |rearm_um| Grating { rearm_um, ..g }.validate(63_000);
        assert_eq!(rearm(499), Ok(()));
        assert_eq!(
            rearm(500),
            Err(TextureError::BadRearm {
                rearm_um: 500,
                wavelength_um: 1_000
            })
        );
    }
}
