//! Region stage: which scene region lies under the finger, with hysteresis at the boundaries.
//!
//! Regions tile the substrate left to right, split at adjustable boundaries (fig. 11 of the SAW
//! display paper). A finger resting on a boundary sees the noisy position dither across it; the
//! tracker only leaves a region once the position is `hysteresis_um` past the boundary, so noise
//! smaller than that never chatters while a real crossing switches `hysteresis_um` late at most
//! (plus one sample of travel).

use heapless::Vec;

/// Most regions a scene may have.
pub const MAX_REGIONS: usize = 8;
/// Default half-width of the hysteresis band. With 16× oversampling and 3 LSB RMS conversion
/// noise the position noise is ≈ 12 µm RMS, so 100 µm is > 8 σ (no chatter in hours at 10 kHz)
/// and a crossing at 300 mm/s (30 µm per sample) still switches within 0.13 mm of the boundary.
pub const DEFAULT_HYSTERESIS_UM: u32 = 100;

/// Why a region layout was rejected. Each variant carries the values its sentence (`Display`)
/// names. Boundary `i` is where region `i` ends (a scene file's `region[i].until_mm`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum RegionError {
    /// No regions, or more than [`MAX_REGIONS`].
    BadCount {
        /// Regions asked for.
        regions: usize,
    },
    /// Boundaries must number one less than the regions.
    BoundaryCount {
        /// Regions asked for.
        regions: usize,
        /// Boundaries given.
        boundaries: usize,
    },
    /// Boundary `index` is not strictly greater than the one before it (unsorted or overlapping).
    Unsorted {
        /// Index of the offending boundary.
        index: u8,
        /// Where it is, µm.
        at_um: u32,
        /// Where the boundary before it is, µm.
        previous_um: u32,
    },
    /// Boundary `index` is at or beyond an end of the substrate.
    OutOfRange {
        /// Index of the offending boundary.
        index: u8,
        /// Where it is, µm.
        at_um: u32,
        /// Substrate length, µm.
        length_um: u32,
    },
    /// Region `index` is narrower than twice the hysteresis, so it could never be entered cleanly.
    TooNarrow {
        /// Index of the offending region.
        index: u8,
        /// Its width, µm.
        width_um: u32,
        /// Twice the hysteresis, µm.
        min_width_um: u32,
    },
    /// Hysteresis above 5 mm: the boundaries would be felt far from where they are drawn.
    HysteresisTooLarge {
        /// The hysteresis asked for, µm.
        hysteresis_um: u32,
    },
}

/// Largest hysteresis, µm.
const MAX_HYSTERESIS_UM: u32 = 5_000;

impl core::fmt::Display for RegionError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::fmt::Milli;
        let mm = |um: u32| Milli(um as u64);
        match *self {
            RegionError::BadCount { regions } => write!(
                f,
                "a scene has {regions} regions and needs 1 to {MAX_REGIONS}"
            ),
            RegionError::BoundaryCount {
                regions,
                boundaries,
            } => write!(
                f,
                "{regions} regions need {} boundaries, not {boundaries}",
                regions.saturating_sub(1)
            ),
            RegionError::Unsorted {
                index,
                at_um,
                previous_um,
            } => write!(
                f,
                "region {index} ends at {} mm, not after region {} ({} mm)",
                mm(at_um),
                index.saturating_sub(1),
                mm(previous_um)
            ),
            RegionError::OutOfRange {
                index,
                at_um,
                length_um,
            } => write!(
                f,
                "region {index} ends at {} mm, not strictly between 0 mm and the substrate's \
                 end at {} mm",
                mm(at_um),
                mm(length_um)
            ),
            RegionError::TooNarrow {
                index,
                width_um,
                min_width_um,
            } => write!(
                f,
                "region {index} is {} mm wide, narrower than twice the hysteresis ({} mm)",
                mm(width_um),
                mm(min_width_um)
            ),
            RegionError::HysteresisTooLarge { hysteresis_um } => write!(
                f,
                "hysteresis {} mm is above the limit of {} mm",
                mm(hysteresis_um),
                mm(MAX_HYSTERESIS_UM)
            ),
        }
    }
}

/// Validated boundaries along the substrate.
#[derive(Clone, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RegionMap {
    boundaries_um: Vec<i32, { MAX_REGIONS - 1 }>,
    hysteresis_um: i32,
}

impl RegionMap {
    /// `regions` regions split at `boundaries_um` (sorted, strictly inside `0..length_um`).
    pub fn new(
        regions: usize,
        boundaries_um: &[u32],
        length_um: u32,
        hysteresis_um: u32,
    ) -> Result<Self, RegionError> {
        if regions == 0 || regions > MAX_REGIONS {
            return Err(RegionError::BadCount { regions });
        }
        if boundaries_um.len() + 1 != regions {
            return Err(RegionError::BoundaryCount {
                regions,
                boundaries: boundaries_um.len(),
            });
        }
        if hysteresis_um > MAX_HYSTERESIS_UM {
            return Err(RegionError::HysteresisTooLarge { hysteresis_um });
        }
        let mut edges: Vec<i32, { MAX_REGIONS - 1 }> = Vec::new();
        let mut prev = 0u32;
        for (i, &b) in boundaries_um.iter().enumerate() {
            let index = i as u8;
            if b == 0 || b >= length_um {
                return Err(RegionError::OutOfRange {
                    index,
                    at_um: b,
                    length_um,
                });
            }
            if i > 0 && b <= prev {
                return Err(RegionError::Unsorted {
                    index,
                    at_um: b,
                    previous_um: prev,
                });
            }
            if b - prev < 2 * hysteresis_um {
                return Err(RegionError::TooNarrow {
                    index,
                    width_um: b - prev,
                    min_width_um: 2 * hysteresis_um,
                });
            }
            prev = b;
            // Cannot fail: length checked against MAX_REGIONS above.
            let _ = edges.push(b as i32);
        }
        if length_um - prev < 2 * hysteresis_um {
            return Err(RegionError::TooNarrow {
                index: boundaries_um.len() as u8,
                width_um: length_um - prev,
                min_width_um: 2 * hysteresis_um,
            });
        }
        Ok(Self {
            boundaries_um: edges,
            hysteresis_um: hysteresis_um as i32,
        })
    }

    /// Number of regions (at least one: the crate's own log line reads it, so no `is_empty`).
    pub(crate) fn len(&self) -> usize {
        self.boundaries_um.len() + 1
    }

    /// Boundaries, µm.
    pub fn boundaries_um(&self) -> &[i32] {
        &self.boundaries_um
    }

    /// The region containing `position_um`, without hysteresis.
    pub fn lookup(&self, position_um: i32) -> u8 {
        self.boundaries_um
            .iter()
            .filter(|&&b| position_um >= b)
            .count() as u8
    }

    /// The region after moving to `position_um` from `current`, with hysteresis.
    pub fn track(&self, current: u8, position_um: i32) -> u8 {
        let b = &self.boundaries_um;
        let h = self.hysteresis_um;
        // A region past the last one is the last one; `get` keeps the per-sample path free of
        // bounds checks (scripts/panic-check.sh).
        let mut r = (current as usize).min(b.len());
        while b.get(r).is_some_and(|&edge| position_um >= edge + h) {
            r += 1;
        }
        while r
            .checked_sub(1)
            .and_then(|i| b.get(i))
            .is_some_and(|&edge| position_um < edge - h)
        {
            r -= 1;
        }
        r as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> RegionMap {
        RegionMap::new(3, &[20_000, 40_000], 63_000, 100).unwrap()
    }

    #[test]
    fn lookup_and_track() {
        let m = map();
        assert_eq!(m.lookup(0), 0);
        assert_eq!(m.lookup(20_000), 1);
        assert_eq!(m.lookup(62_999), 2);
        // Inside the band nothing changes, in either direction.
        assert_eq!(m.track(0, 20_099), 0);
        assert_eq!(m.track(0, 20_100), 1);
        assert_eq!(m.track(1, 19_901), 1);
        assert_eq!(m.track(1, 19_899), 0);
        // The band's edges exactly: forward switches at b + h, back only below b − h.
        assert_eq!(m.track(1, 19_900), 1);
        assert_eq!(m.track(2, 39_900), 2);
        assert_eq!(m.track(2, 39_899), 1);
        assert_eq!(m.track(1, 40_099), 1);
        assert_eq!(m.track(1, 40_100), 2);
        // A jump over several regions lands in the right one.
        assert_eq!(m.track(0, 50_000), 2);
        assert_eq!(m.track(2, 100), 0);
    }

    #[test]
    fn a_region_past_the_last_is_the_last_and_never_panics() {
        // Three regions (0–2). The tracker used to index the boundaries with `current` and
        // panicked on 3+; now it starts from the last region and tracks from there.
        let m = map();
        assert_eq!(m.track(3, 50_000), 2);
        assert_eq!(m.track(200, 50_000), 2);
        assert_eq!(m.track(u8::MAX, 100), 0);
        assert_eq!(m.track(7, 30_000), 1);
    }

    #[test]
    fn bad_layouts_rejected() {
        assert_eq!(
            RegionMap::new(3, &[40_000, 20_000], 63_000, 100),
            Err(RegionError::Unsorted {
                index: 1,
                at_um: 20_000,
                previous_um: 40_000
            })
        );
        assert_eq!(
            RegionMap::new(3, &[20_000, 20_000], 63_000, 100),
            Err(RegionError::Unsorted {
                index: 1,
                at_um: 20_000,
                previous_um: 20_000
            })
        );
        assert_eq!(
            RegionMap::new(3, &[20_000], 63_000, 100),
            Err(RegionError::BoundaryCount {
                regions: 3,
                boundaries: 1
            })
        );
        assert_eq!(
            RegionMap::new(2, &[63_000], 63_000, 100),
            Err(RegionError::OutOfRange {
                index: 0,
                at_um: 63_000,
                length_um: 63_000
            })
        );
        assert_eq!(
            RegionMap::new(3, &[20_000, 20_150], 63_000, 100),
            Err(RegionError::TooNarrow {
                index: 1,
                width_um: 150,
                min_width_um: 200
            })
        );
        assert_eq!(
            RegionMap::new(0, &[], 63_000, 100),
            Err(RegionError::BadCount { regions: 0 })
        );
        assert_eq!(
            RegionMap::new(9, &[1, 2, 3, 4, 5, 6, 7, 8], 63_000, 0),
            Err(RegionError::BadCount { regions: 9 })
        );
    }

    /// Each refusal reads as one sentence, positions in mm as a scene file writes them.
    #[test]
    fn errors_read_as_sentences() {
        let cases = [
            (
                RegionError::BadCount { regions: 9 },
                "a scene has 9 regions and needs 1 to 8",
            ),
            (
                RegionError::BoundaryCount {
                    regions: 3,
                    boundaries: 1,
                },
                "3 regions need 2 boundaries, not 1",
            ),
            (
                RegionError::Unsorted {
                    index: 2,
                    at_um: 10_000,
                    previous_um: 30_000,
                },
                "region 2 ends at 10 mm, not after region 1 (30 mm)",
            ),
            (
                RegionError::OutOfRange {
                    index: 0,
                    at_um: 63_000,
                    length_um: 63_000,
                },
                "region 0 ends at 63 mm, not strictly between 0 mm and the substrate's end at \
                 63 mm",
            ),
            (
                RegionError::TooNarrow {
                    index: 1,
                    width_um: 150,
                    min_width_um: 200,
                },
                "region 1 is 0.15 mm wide, narrower than twice the hysteresis (0.2 mm)",
            ),
            (
                RegionError::HysteresisTooLarge {
                    hysteresis_um: 5_001,
                },
                "hysteresis 5.001 mm is above the limit of 5 mm",
            ),
        ];
        for (e, sentence) in cases {
            assert_eq!(std::format!("{e}"), sentence, "{e:?}");
        }
    }
}
