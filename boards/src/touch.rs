//! 4-wire touch overlay pins of both Nucleos (issue #36): one GPIO per terminal, each also an
//! ADC input, and each board's conversion time for `saw_core::touch::plates::AdcTiming`.
//!
//! A terminal is driven high or low in some phases and converted (or left floating, analog
//! mode) in others, so every pin must be a plain GPIO and an ADC channel at once. Three are
//! converted (Y+ in the X phase, X+ in the Y and Z1 phases, Y− in Z2); X− is only driven, but
//! is on an ADC input too, so a plate-continuity check can read it later. All four are on ADC1
//! on both chips, the wiper's ADC, so one regular sequence reads the overlay; the overlay and
//! the slider share that ADC's time ("Sharing ADC1" in `docs/touch.md`).
//!
//! The pins are the same on both boards (one overlay cable fits both): PB0 (Arduino A3), and on
//! the morpho headers PC2, PC3 and PB1. Channels from the chips' data (DS10693 pin table:
//! PB0 ADC12_IN8, PB1 ADC12_IN9, PC2 ADC123_IN12, PC3 ADC123_IN13; DS12288: PB0 ADC1_IN15,
//! PB1 ADC1_IN12, PC2 ADC12_IN8, PC3 ADC12_IN9), checked against stm32-metapac 21's generated
//! chip metadata as `boards/README.md` checks the others. Not A4/A5: on the Nucleo-64 those
//! header pins are shared with PB9/PB8 through solder bridges (UM1724 and UM2505, "Solder
//! bridges" and the morpho tables of "Extension connectors": CN7-36 "PC1 or PB9", CN7-38
//! "PC0 or PB8"), so their use depends on how a board's bridges are set. None of the four is
//! one of the Nucleo's reserved pins ([`crate::is_reserved`]) or any pin the board plan uses.

use crate::{BoardDef, Family, Pin};

/// One overlay terminal's pin and its ADC channel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TouchPin {
    /// The pin, GPIO or analog mode (no alternate function).
    pub pin: Pin,
    /// The ADC that converts it, e.g. `"ADC1"`.
    pub adc: &'static str,
    /// Its input channel on that ADC.
    pub channel: u8,
}

/// The four terminals of the overlay on one board.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TouchPins {
    /// X+: high in the X phase; converted in the Y and Z1 phases.
    pub x_plus: TouchPin,
    /// X−: low in the X and Z phases; floating in Y.
    pub x_minus: TouchPin,
    /// Y+: converted in the X phase; high in the Y and Z phases.
    pub y_plus: TouchPin,
    /// Y−: low in the Y phase; converted in Z2; floating in X and Z1.
    pub y_minus: TouchPin,
}

impl TouchPins {
    /// The four pins, X+, X−, Y+, Y−.
    pub const fn pins(&self) -> [Pin; 4] {
        [
            self.x_plus.pin,
            self.x_minus.pin,
            self.y_plus.pin,
            self.y_minus.pin,
        ]
    }
}

const PC2: Pin = Pin {
    port: 'C',
    pin: 2,
    af: None,
    header: "morpho CN7-35",
};
const PC3: Pin = Pin {
    port: 'C',
    pin: 3,
    af: None,
    header: "morpho CN7-37",
};
const PB0: Pin = Pin {
    port: 'B',
    pin: 0,
    af: None,
    header: "A3 (CN8-4), morpho CN7-34",
};
const PB1: Pin = Pin {
    port: 'B',
    pin: 1,
    af: None,
    header: "morpho CN10-24",
};

/// NUCLEO-F446RE: X+ PC2 (ADC1_IN12), X− PC3 (ADC1_IN13), Y+ PB0 (ADC1_IN8), Y− PB1
/// (ADC1_IN9).
pub const NUCLEO_F446RE_TOUCH: TouchPins = TouchPins {
    x_plus: TouchPin {
        pin: PC2,
        adc: "ADC1",
        channel: 12,
    },
    x_minus: TouchPin {
        pin: PC3,
        adc: "ADC1",
        channel: 13,
    },
    y_plus: TouchPin {
        pin: PB0,
        adc: "ADC1",
        channel: 8,
    },
    y_minus: TouchPin {
        pin: PB1,
        adc: "ADC1",
        channel: 9,
    },
};

/// NUCLEO-G474RE: X+ PC2 (ADC1_IN8), X− PC3 (ADC1_IN9), Y+ PB0 (ADC1_IN15), Y− PB1
/// (ADC1_IN12).
pub const NUCLEO_G474RE_TOUCH: TouchPins = TouchPins {
    x_plus: TouchPin {
        pin: PC2,
        adc: "ADC1",
        channel: 8,
    },
    x_minus: TouchPin {
        pin: PC3,
        adc: "ADC1",
        channel: 9,
    },
    y_plus: TouchPin {
        pin: PB0,
        adc: "ADC1",
        channel: 15,
    },
    y_minus: TouchPin {
        pin: PB1,
        adc: "ADC1",
        channel: 12,
    },
};

/// The overlay's pins on `board`, by its name (the dual-ADC F446 plans share the F446's).
pub fn touch_pins(board: &BoardDef) -> Option<&'static TouchPins> {
    match board.name.as_bytes() {
        b"nucleo-f446re" => Some(&NUCLEO_F446RE_TOUCH),
        b"nucleo-g474re" => Some(&NUCLEO_G474RE_TOUCH),
        _ => None,
    }
}

/// One conversion on `board`'s ADC at its plan's sampling time, ns, rounded up: sampling plus
/// 12 cycles of conversion on the F446 (RM0390 §13.5, "Channel-wise programmable sampling
/// time") and 12.5 on the G474 (RM0440 §21.4.16), at the plan's ADC clock. F446: (56 + 12)
/// cycles at 22.5 MHz = 3 022.2 → 3 023 ns; G474: (47.5 + 12.5) at 37.5 MHz = 1 600 ns.
pub const fn conversion_ns(board: &BoardDef) -> u32 {
    let overhead_half_cycles = match board.family {
        Family::Stm32F4 => 24,
        Family::Stm32G4 => 25,
    };
    let half_cycles = (board.adc.sample_half_cycles + overhead_half_cycles) as u64;
    let den = 2 * board.adc.clk_hz as u64;
    if den == 0 {
        return u32::MAX;
    }
    let ns = (half_cycles * 1_000_000_000).div_ceil(den);
    if ns > u32::MAX as u64 {
        u32::MAX
    } else {
        ns as u32
    }
}

/// How a board's 2D image converts each phase of the overlay (the fields of
/// `saw_core::touch::plates::AdcTiming`, which host-sim's `sim2d::adc_timing` and the firmware's
/// build script build from this; saw-boards depends on nothing).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TouchAdc {
    /// One conversion, sampling included, ns ([`conversion_ns`]).
    pub conversion_ns: u32,
    /// Conversions summed per position phase (X, Y).
    pub conversions_position: u32,
    /// Conversions summed per pressure phase (Z1, Z2): pressure needs less precision than
    /// position (TI's TSC2101 recommends 8 bits for it), and each one taken off the last phase
    /// is one conversion less between the frame's last sample and the gate.
    pub conversions_pressure: u32,
    /// Conversions thrown away right after each switch, before the summed ones: the first
    /// conversion of a channel shares charge with the hold capacitor still holding the
    /// previous channel's voltage (`docs/touch.md`, "Why 1 nF").
    pub discard: u32,
}

impl TouchAdc {
    /// Ranks of one phase's regular sequence: the discarded conversions and the summed ones.
    pub const fn ranks(&self, position: bool) -> u32 {
        self.discard
            + if position {
                self.conversions_position
            } else {
                self.conversions_pressure
            }
    }
}

/// The regular sequence's length on both chips: 16 ranks (RM0390 §13.13.9 ADC_SQR1.L,
/// RM0440 §21.7.11 ADC_SQR1.L): one start converts a whole phase.
pub const MAX_RANKS: u32 = 16;

/// `board`'s 2D acquisition: its plan's conversion time; one discarded conversion, then 15
/// summed a position phase (the sequence's 16 ranks) and 4 a pressure phase. Both chips convert
/// a phase as one regular sequence of its channel, one DMA word a conversion.
pub const fn touch_adc(board: &BoardDef) -> TouchAdc {
    TouchAdc {
        conversion_ns: conversion_ns(board),
        conversions_position: 15,
        conversions_pressure: 4,
        discard: 1,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{is_reserved, ALL, NUCLEO_F446RE_DUAL, NUCLEO_F446RE_DUAL128};

    /// Every pin the board plan drives or reads, beside the overlay's.
    fn plan_pins(b: &BoardDef) -> [Pin; 6] {
        [
            b.carrier.pin,
            b.burst.pin,
            b.burst_b_pin,
            b.adc.pin,
            b.rf_arm_pin,
            b.rf_level.dac_pin,
        ]
    }

    /// No pin is used twice: the four terminals are distinct from each other, from every pin
    /// of the plan, and none is a Nucleo-reserved pin, on every board and plan.
    /// (Seen failing with X− set to PA1, the wiper: "PA1 twice".)
    #[test]
    fn no_pin_is_used_twice() {
        for b in ALL
            .iter()
            .chain([&NUCLEO_F446RE_DUAL, &NUCLEO_F446RE_DUAL128])
        {
            let touch = touch_pins(b).unwrap();
            let (plan, overlay) = (plan_pins(b), touch.pins());
            let mut all = [plan[0]; 10];
            all[..6].copy_from_slice(&plan);
            all[6..].copy_from_slice(&overlay);
            for (i, p) in all.iter().enumerate() {
                for q in &all[i + 1..] {
                    assert!(
                        !(p.port == q.port && p.pin == q.pin),
                        "{}: P{}{} twice",
                        b.name,
                        p.port,
                        p.pin
                    );
                }
            }
            for p in touch.pins() {
                assert!(
                    !is_reserved(&p),
                    "{}: P{}{} reserved",
                    b.name,
                    p.port,
                    p.pin
                );
                assert_eq!(p.af, None, "GPIO/analog, no alternate function");
                // A4/A5 share their header pin with PB8/PB9 through solder bridges.
                for (port, pin) in [('C', 0), ('C', 1), ('B', 8), ('B', 9)] {
                    assert!(
                        !p.is(port, pin),
                        "{}: P{port}{pin} is solder-bridge shared",
                        b.name
                    );
                }
            }
        }
    }

    /// The channels as the chips' data list them (stm32-metapac 21, ADC1's pin signals),
    /// written out here: F446 PB0 IN8, PB1 IN9, PC2 IN12, PC3 IN13; G474 PB0 IN15, PB1 IN12,
    /// PC2 IN8, PC3 IN9; and none is the wiper's channel (F446 IN1, G474 IN2).
    #[test]
    fn channels_match_the_chip_data_and_miss_the_wiper() {
        let chan = |t: &TouchPins| {
            [t.x_plus, t.x_minus, t.y_plus, t.y_minus]
                .map(|p| (p.adc, p.pin.port, p.pin.pin, p.channel))
        };
        assert_eq!(
            chan(&NUCLEO_F446RE_TOUCH),
            [
                ("ADC1", 'C', 2, 12),
                ("ADC1", 'C', 3, 13),
                ("ADC1", 'B', 0, 8),
                ("ADC1", 'B', 1, 9)
            ]
        );
        assert_eq!(
            chan(&NUCLEO_G474RE_TOUCH),
            [
                ("ADC1", 'C', 2, 8),
                ("ADC1", 'C', 3, 9),
                ("ADC1", 'B', 0, 15),
                ("ADC1", 'B', 1, 12)
            ]
        );
        for b in ALL {
            for p in touch_pins(b).unwrap().pins() {
                assert!(!p.is(b.adc.pin.port, b.adc.pin.pin));
            }
            let t = touch_pins(b).unwrap();
            for tp in [t.x_plus, t.x_minus, t.y_plus, t.y_minus] {
                assert_ne!(tp.channel, b.adc.channel, "{}", b.name);
            }
        }
    }

    /// Every phase fits one regular sequence (≤ 16 ranks) and sums at least one conversion, on
    /// every board; F446: 1 + 15 and 1 + 4 ranks (seen failing with 16 position conversions:
    /// 17 ranks).
    #[test]
    fn each_phase_is_one_regular_sequence() {
        for b in ALL {
            let t = touch_adc(b);
            for position in [true, false] {
                assert!(t.ranks(position) <= MAX_RANKS, "{}", b.name);
                assert!(t.ranks(position) > t.discard, "{}", b.name);
            }
        }
        let f = touch_adc(&crate::NUCLEO_F446RE);
        assert_eq!((f.ranks(true), f.ranks(false)), (16, 5));
        assert_eq!(f.conversion_ns, 3_023);
    }

    /// Hand-worked: F446 68 cycles / 22.5 MHz = 3 022.2 ns → 3 023; G474 60 / 37.5 MHz = 1 600.
    #[test]
    fn conversion_times_by_hand() {
        assert_eq!(conversion_ns(&crate::NUCLEO_F446RE), 3_023);
        assert_eq!(conversion_ns(&crate::NUCLEO_G474RE), 1_600);
        // The dual plan's 15 cycles: (15 + 12) / 22.5 MHz = 1 200 ns.
        assert_eq!(conversion_ns(&NUCLEO_F446RE_DUAL), 1_200);
    }
}
