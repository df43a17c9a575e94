//! RF level: the drive level's map to DAC codes (the calibration table a user replaces for their
//! amplifier), the reference circuit it was drawn for, and the triangle envelope table the DMA
//! plays during a line pulse. `docs/rf-level.md` has the register design.
//!
//! Reference circuit (documented, not built here): DAC1_OUT1 on PA4 with its output buffer on
//! (usable 0.2 V … VDDA − 0.2 V, DS10693 / DS12288 DAC characteristics) → a 10 kΩ / 4.42 kΩ
//! divider → the gain pin of a linear-in-dB VGA (20 mV/dB over 45 dB from 50 mV, gain-up mode:
//! the AD8367's datasheet figures) in front of the RF power amplifier. The divider's lower
//! resistor holds the gain pin at 0 V (minimum gain) while PA4 is not driven: after a reset,
//! before the firmware runs, and after a panic releases the DAC.

use core::fmt;

/// DAC resolution (both chips' DAC1: 12 bits, right-aligned in DHR12R1).
pub const DAC_BITS: u32 = 12;
/// Largest DAC code.
pub const DAC_MAX_CODE: u16 = (1 << DAC_BITS) - 1;
/// Most entries of a triangle envelope table.
pub const MAX_ENVELOPE_ENTRIES: usize = 128;
/// Shortest step between envelope entries, ns: the DAC's settling time to 1 LSB (typ. 3 µs, max
/// 6 µs for a full-scale step; an envelope step is far smaller).
pub const MIN_ENVELOPE_STEP_NS: u64 = 4_000;

/// One calibration point: this level needs this DAC code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelPoint {
    /// Drive level, ‰ of full RF amplitude.
    pub permille: u16,
    /// DAC code that gives it.
    pub code: u16,
}

/// The level ‰ → DAC code map: points joined by straight lines, from level 0 to 1000 ‰.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LevelTable {
    pub points: &'static [LevelPoint],
}

/// Why a calibration table is refused. Each names the point, its value and the rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum LevelTableError {
    /// Fewer than two points.
    TooFewPoints { points: usize },
    /// The first point is not level 0.
    FirstNotZero { permille: u16 },
    /// The last point is not level 1000 ‰.
    LastNotFull { permille: u16 },
    /// A level not above the one before it.
    LevelNotIncreasing {
        index: usize,
        permille: u16,
        previous: u16,
    },
    /// A code below the one before it (the map must be monotonic).
    CodeDecreasing {
        index: usize,
        code: u16,
        previous: u16,
    },
    /// A code past the DAC's range.
    CodeOutOfRange { index: usize, code: u16 },
}

impl fmt::Display for LevelTableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFewPoints { points } => {
                write!(f, "level table: {points} points; it needs at least 2 (level 0 and 1000 ‰)")
            }
            Self::FirstNotZero { permille } => {
                write!(f, "level table: the first point is {permille} ‰; it must be 0 ‰")
            }
            Self::LastNotFull { permille } => {
                write!(f, "level table: the last point is {permille} ‰; it must be 1000 ‰")
            }
            Self::LevelNotIncreasing {
                index,
                permille,
                previous,
            } => write!(
                f,
                "level table point {index}: level {permille} ‰ must be above the previous point's {previous} ‰"
            ),
            Self::CodeDecreasing {
                index,
                code,
                previous,
            } => write!(
                f,
                "level table point {index}: code {code} is below the previous point's {previous}; the map must be monotonic"
            ),
            Self::CodeOutOfRange { index, code } => write!(
                f,
                "level table point {index}: code {code} is past the DAC's largest code {DAC_MAX_CODE}"
            ),
        }
    }
}

impl LevelTable {
    /// Checks the table: from 0 to 1000 ‰, levels strictly increasing, codes never decreasing
    /// and within the DAC.
    pub const fn check(&self) -> Result<(), LevelTableError> {
        let p = self.points;
        if p.len() < 2 {
            return Err(LevelTableError::TooFewPoints { points: p.len() });
        }
        if p[0].permille != 0 {
            return Err(LevelTableError::FirstNotZero {
                permille: p[0].permille,
            });
        }
        if p[p.len() - 1].permille != 1000 {
            return Err(LevelTableError::LastNotFull {
                permille: p[p.len() - 1].permille,
            });
        }
        let mut i = 0;
        while i < p.len() {
            if p[i].code > DAC_MAX_CODE {
                return Err(LevelTableError::CodeOutOfRange {
                    index: i,
                    code: p[i].code,
                });
            }
            if i > 0 {
                if p[i].permille <= p[i - 1].permille {
                    return Err(LevelTableError::LevelNotIncreasing {
                        index: i,
                        permille: p[i].permille,
                        previous: p[i - 1].permille,
                    });
                }
                if p[i].code < p[i - 1].code {
                    return Err(LevelTableError::CodeDecreasing {
                        index: i,
                        code: p[i].code,
                        previous: p[i - 1].code,
                    });
                }
            }
            i += 1;
        }
        Ok(())
    }

    /// DAC code for a level, ‰ (above 1000 ‰ reads as 1000 ‰). Straight lines between the
    /// points, rounded down: never above the code the next point asks.
    pub fn code(&self, permille: u16) -> u16 {
        let l = permille.min(1000);
        let p = self.points;
        // The segment that ends at the first point above `l` (the last segment at 1000 ‰). On
        // a checked table p[0] is 0 ‰ and levels rise; an unchecked one gets a code, no panic.
        let hi = p
            .partition_point(|q| q.permille <= l)
            .min(p.len().saturating_sub(1))
            .max(1);
        let (Some(a), Some(b)) = (p.get(hi - 1), p.get(hi)) else {
            return p.first().map_or(0, |q| q.code);
        };
        let span = b.permille.saturating_sub(a.permille) as u32;
        if span == 0 {
            return a.code;
        }
        let rise = b.code.saturating_sub(a.code) as u32;
        let run = l.saturating_sub(a.permille) as u32;
        a.code + (rise * run / span) as u16
    }
}

/// The reference circuit's table (see the module doc): 2 dB apart from −42 dB to full level, so
/// straight lines between them miss the VGA's exponential curve by under 1 % of the level.
/// Levels below 6 ‰ (−44.4 dB) are under the VGA's floor once the DAC buffer's 0.2 V is
/// divided down: the circuit gives 6 ‰ for all of them, and 0 ‰ maps to code 0.
pub const REFERENCE_TABLE: LevelTable = LevelTable {
    points: &[
        LevelPoint {
            permille: 0,
            code: 0,
        },
        LevelPoint {
            permille: 7,
            code: 356,
        },
        LevelPoint {
            permille: 8,
            code: 450,
        },
        LevelPoint {
            permille: 10,
            code: 607,
        },
        LevelPoint {
            permille: 13,
            code: 792,
        },
        LevelPoint {
            permille: 16,
            code: 938,
        },
        LevelPoint {
            permille: 20,
            code: 1095,
        },
        LevelPoint {
            permille: 25,
            code: 1252,
        },
        LevelPoint {
            permille: 32,
            code: 1425,
        },
        LevelPoint {
            permille: 40,
            code: 1582,
        },
        LevelPoint {
            permille: 50,
            code: 1739,
        },
        LevelPoint {
            permille: 63,
            code: 1902,
        },
        LevelPoint {
            permille: 79,
            code: 2061,
        },
        LevelPoint {
            permille: 100,
            code: 2227,
        },
        LevelPoint {
            permille: 126,
            code: 2389,
        },
        LevelPoint {
            permille: 158,
            code: 2548,
        },
        LevelPoint {
            permille: 200,
            code: 2714,
        },
        LevelPoint {
            permille: 251,
            code: 2874,
        },
        LevelPoint {
            permille: 316,
            code: 3036,
        },
        LevelPoint {
            permille: 398,
            code: 3198,
        },
        LevelPoint {
            permille: 501,
            code: 3360,
        },
        LevelPoint {
            permille: 631,
            code: 3522,
        },
        LevelPoint {
            permille: 794,
            code: 3684,
        },
        LevelPoint {
            permille: 1000,
            code: 3846,
        },
    ],
};
const _: () = assert!(REFERENCE_TABLE.check().is_ok());

/// The reference circuit, as numbers a plant model can use (host-sim draws the RF amplitude the
/// finger gets from a DAC code with it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReferenceCircuit {
    /// DAC reference and supply, mV.
    pub vdda_mv: u32,
    /// The buffered DAC output's floor and headroom, mV (it cannot swing closer to the rails).
    pub buffer_margin_mv: u32,
    /// Divider: gain-pin voltage = DAC voltage × num / den.
    pub divider_num: u32,
    pub divider_den: u32,
    /// VGA gain-pin voltage at full gain, mV, its slope, mV/dB, and its span, dB.
    pub vga_full_mv: u32,
    pub vga_mv_per_db: u32,
    pub vga_span_db: u32,
}

/// The circuit [`REFERENCE_TABLE`] was drawn for.
pub const REFERENCE_CIRCUIT: ReferenceCircuit = ReferenceCircuit {
    vdda_mv: 3_300,
    buffer_margin_mv: 200,
    divider_num: 4_420,
    divider_den: 14_420,
    vga_full_mv: 950,
    vga_mv_per_db: 20,
    vga_span_db: 45,
};

/// How a triangle envelope is played: `entries` table entries, one every `step_clocks` of the
/// envelope timer (TIM8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnvelopePlan {
    pub entries: usize,
    pub step_clocks: u32,
}

/// The plan for a pulse of `pulse_clocks` envelope-timer clocks at `clk_hz`: as many entries as
/// fit (at most [`MAX_ENVELOPE_ENTRIES`], at least [`MIN_ENVELOPE_STEP_NS`] apart), an even
/// number so the peak falls on a step, at least 2. The step is rounded down, so the last entry
/// (level 0) is latched before the pulse ends and the envelope timer stops with it (at most
/// `entries` clocks early).
pub fn triangle_plan(pulse_clocks: u64, clk_hz: u32) -> EnvelopePlan {
    let min_step = (clk_hz as u64 * MIN_ENVELOPE_STEP_NS)
        .div_ceil(1_000_000_000)
        .max(1);
    let fit = (pulse_clocks / min_step).min(MAX_ENVELOPE_ENTRIES as u64) as usize;
    let entries = (fit & !1).max(2);
    let step = pulse_clocks / entries as u64;
    EnvelopePlan {
        entries,
        step_clocks: step.clamp(1, u16::MAX as u64 + 1) as u32,
    }
}

/// Level of entry `k` of an `entries`-entry triangle peaking at `peak_permille`, ‰: the
/// triangle sampled at the end of step k + 1, so the last entry is 0 and the middle one the peak.
pub fn triangle_level(peak_permille: u16, k: usize, entries: usize) -> u16 {
    let n = entries as u32;
    let x2 = 2 * (k as u32 + 1);
    let rise = if x2 <= n {
        x2
    } else {
        (2 * n).saturating_sub(x2)
    };
    (peak_permille as u32 * rise / n) as u16
}

/// Fills `out[..plan.entries]` with the DAC codes of a triangle peaking at `peak_permille`.
pub fn triangle(table: &LevelTable, peak_permille: u16, plan: &EnvelopePlan, out: &mut [u16]) {
    let n = plan.entries.min(out.len());
    for (k, slot) in out[..n].iter_mut().enumerate() {
        *slot = table.code(triangle_level(peak_permille, k, plan.entries));
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::string::ToString;

    macro_rules! p {
        ($l:expr, $c:expr) => {
            LevelPoint {
                permille: $l,
                code: $c,
            }
        };
    }

    #[test]
    fn each_rule_is_refused_with_point_value_and_rule() {
        let cases: [(&'static [LevelPoint], &str); 6] = [
            (&[p!(0, 0)], "1 points; it needs at least 2"),
            (
                &[p!(1, 0), p!(1000, 9)],
                "first point is 1 ‰; it must be 0 ‰",
            ),
            (
                &[p!(0, 0), p!(999, 9)],
                "last point is 999 ‰; it must be 1000 ‰",
            ),
            (
                &[p!(0, 0), p!(500, 5), p!(400, 6), p!(1000, 9)],
                "point 2: level 400 ‰ must be above the previous point's 500 ‰",
            ),
            (
                &[p!(0, 0), p!(500, 7), p!(1000, 6)],
                "point 2: code 6 is below the previous point's 7",
            ),
            (
                &[p!(0, 0), p!(1000, 4096)],
                "point 1: code 4096 is past the DAC's largest code 4095",
            ),
        ];
        for (points, words) in cases {
            let e = LevelTable { points }.check().unwrap_err().to_string();
            assert!(e.contains(words), "{points:?} gave {e:?}");
        }
        assert_eq!(
            LevelTable {
                points: &[p!(0, 0), p!(1000, 4095)]
            }
            .check(),
            Ok(())
        );
        // Monotonic, not strictly: a flat run (levels under a VGA's floor share a code) passes.
        assert_eq!(
            LevelTable {
                points: &[p!(0, 0), p!(5, 300), p!(7, 300), p!(1000, 4095)]
            }
            .check(),
            Ok(())
        );
    }

    #[test]
    fn code_follows_the_points_and_never_overshoots() {
        let t = LevelTable {
            points: &[p!(0, 100), p!(100, 1100), p!(1000, 2000)],
        };
        assert_eq!(t.code(0), 100);
        assert_eq!(t.code(50), 600);
        assert_eq!(t.code(100), 1100);
        assert_eq!(t.code(550), 1550);
        assert_eq!(t.code(1000), 2000);
        assert_eq!(t.code(u16::MAX), 2000);
        assert_eq!(t.code(99), 1090);
        assert_eq!(t.code(101), 1101);
        // Unchecked tables get a code, never a panic.
        for bad in [
            LevelTable { points: &[] },
            LevelTable {
                points: &[p!(0, 7)],
            },
            LevelTable {
                points: &[p!(0, 9), p!(0, 5), p!(10, 1)],
            },
        ] {
            for l in [0, 5, 1000] {
                let _ = bad.code(l);
            }
        }
        assert_eq!(
            LevelTable {
                points: &[p!(0, 7)]
            }
            .code(500),
            7
        );
        // Monotonic over every level of the reference table.
        let codes: std::vec::Vec<u16> = (0..=1000).map(|l| REFERENCE_TABLE.code(l)).collect();
        assert!(codes.windows(2).all(|w| w[0] <= w[1]));
        assert_eq!(codes[1000], 3846);
    }

    #[test]
    fn triangle_rises_to_the_peak_halfway_and_ends_at_zero() {
        let plan = EnvelopePlan {
            entries: 8,
            step_clocks: 1,
        };
        let levels: std::vec::Vec<u16> = (0..8).map(|k| triangle_level(800, k, 8)).collect();
        assert_eq!(levels, [200, 400, 600, 800, 600, 400, 200, 0]);
        let mut out = [0u16; 8];
        triangle(&REFERENCE_TABLE, 800, &plan, &mut out);
        assert_eq!(out[3], REFERENCE_TABLE.code(800));
        assert_eq!(out[7], 0);
    }

    #[test]
    fn plan_keeps_entries_apart_and_covers_the_pulse() {
        // 10 ms at 180 MHz: 128 entries of 14 062.5 clocks, rounded down: the last entry is
        // latched 64 clocks before the pulse ends, not after.
        let a = triangle_plan(1_800_000, 180_000_000);
        assert_eq!(a.entries, 128);
        assert_eq!(a.step_clocks, 14_062);
        // 100 µs at 150 MHz: 4 µs apart → 25 fit, 24 (even) used.
        let b = triangle_plan(15_000, 150_000_000);
        assert_eq!(b.entries, 24);
        assert_eq!(b.step_clocks, 625);
        // Shorter than two steps: still 2 entries.
        assert_eq!(triangle_plan(100, 150_000_000).entries, 2);
        // 10 s at 180 MHz: the step stops at the 16-bit counter's 65 536 clocks (the firmware
        // prescales such pulses first).
        assert_eq!(
            triangle_plan(1_800_000_000, 180_000_000).step_clocks,
            65_536
        );
    }
}
