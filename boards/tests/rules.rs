//! One test per consistency rule of [`BoardDef::is_consistent`] and [`ClockPlan::is_valid`]:
//! each starts from a real board (both, where the rule applies to both), breaks exactly that one
//! rule with a struct-update copy and checks the copy is refused while the unbroken board (or a
//! sibling copy exactly on the limit) is accepted. The expected clock figures are worked by hand,
//! never computed with the getter under test.
//!
//! Limits come from the reference manuals: RM0390 (STM32F446) §6.3.2 RCC_PLLCFGR (PLLM 2..=63,
//! PLLN 50..=432, PLLP ∈ {2,4,6,8}, VCO output 100–432 MHz), §6.3.3 RCC_CFGR (HPRE, PPRE1/2:
//! PCLK1 ≤ 45 MHz, PCLK2 ≤ 90 MHz), §6.2 (timer clock = PCLK if the APB prescaler is 1, else
//! 2 × PCLK); RM0440 (STM32G474) §7.4.4 RCC_PLLCFGR (PLLM 1..=16, PLLN 8..=127,
//! PLLR ∈ {2,4,6,8}, VCO input 2.66–16 MHz, VCO output 96–344 MHz), §7.4.3 RCC_CFGR, §7.2 (same
//! timer clock rule). The F446 PLL input window (0.95–2.1 MHz) is the datasheet's (DS10693), the
//! RM0390 PLLM text says 1–2 MHz; the code keeps the datasheet figures.
//!
//! Where a limit is a product (VCO = input × N) or must leave the bus dividers exact, "one Hz
//! past" is not reachable; those tests use the nearest refused value that breaks only that rule.
//! A few copies necessarily break two rules (noted at the test): carrier divider 1 (≥ 2 and even),
//! a 16-bit burst timer (32-bit and 1 Hz fits), a carrier clock off a 15 MHz multiple (with the
//! ADC clock off a 10 kHz multiple) and an inexact ADC trigger rate (with the same divisibility).

use saw_boards::*;

const F446: BoardDef = NUCLEO_F446RE;
const G474: BoardDef = NUCLEO_G474RE;

/// A GPIO/analog pin for the tests (AF and connector do not matter to the rules).
const fn pin(port: char, pin: u8) -> Pin {
    Pin {
        port,
        pin,
        af: None,
        header: "test",
    }
}

/// The F446 clock plan with another PLL chain (buses as on the board: AHB /1, APB1 /4, APB2 /2).
fn f446(osc_hz: u32, pll_m: u32, pll_n: u32, pll_out_div: u32, sysclk_hz: u32) -> ClockPlan {
    ClockPlan {
        osc_hz,
        pll_m,
        pll_n,
        pll_out_div,
        sysclk_hz,
        ..F446.clocks
    }
}

/// The G474 clock plan with another PLL chain (buses as on the board: all /1).
fn g474(osc_hz: u32, pll_m: u32, pll_n: u32, pll_out_div: u32, sysclk_hz: u32) -> ClockPlan {
    ClockPlan {
        osc_hz,
        pll_m,
        pll_n,
        pll_out_div,
        sysclk_hz,
        ..G474.clocks
    }
}

/// `b` moved onto the clock plan `c`, with `c`'s timer clocks worked out by hand by the caller.
fn retimed(b: &BoardDef, c: ClockPlan, apb1_timer_hz: u32, apb2_timer_hz: u32) -> BoardDef {
    let tim = |bus| match bus {
        Bus::Apb1 => apb1_timer_hz,
        Bus::Apb2 => apb2_timer_hz,
    };
    BoardDef {
        clocks: c,
        sysclk_hz: c.sysclk_hz,
        carrier: PwmTimer {
            clk_hz: tim(b.carrier.bus),
            ..b.carrier
        },
        carrier_timer_clk_hz: tim(b.carrier.bus),
        burst: PwmTimer {
            clk_hz: tim(b.burst.bus),
            ..b.burst
        },
        burst_timer_clk_hz: tim(b.burst.bus),
        adc: AdcDef {
            trigger_timer_clk_hz: tim(b.adc.trigger_bus),
            ..b.adc
        },
        ..*b
    }
}

// ---------------------------------------------------------------------------------------------
// Clock getters, hand-worked.

/// F446: 8 MHz / 4 = 2 MHz → ×180 = 360 MHz → /2 = 180 MHz; APB1 45 MHz (timers 90), APB2 90 (180).
#[test]
fn f446_clock_tree_hand_worked() {
    let c = F446.clocks;
    assert_eq!(c.vco_in_hz(), 2_000_000);
    assert_eq!(c.vco_out_hz(), 360_000_000);
    assert_eq!(c.pll_sysclk_hz(), 180_000_000);
    assert_eq!(c.hclk_hz(), 180_000_000);
    assert_eq!(c.pclk1_hz(), 45_000_000);
    assert_eq!(c.pclk2_hz(), 90_000_000);
    assert_eq!(c.apb1_timer_hz(), 90_000_000);
    assert_eq!(c.apb2_timer_hz(), 180_000_000);
    assert_eq!(c.timer_clk_hz(Bus::Apb1), 90_000_000);
    assert_eq!(c.timer_clk_hz(Bus::Apb2), 180_000_000);
}

/// G474: 24 MHz / 6 = 4 MHz → ×75 = 300 MHz → /2 = 150 MHz; every bus /1, every timer 150 MHz.
#[test]
fn g474_clock_tree_hand_worked() {
    let c = G474.clocks;
    assert_eq!(c.vco_in_hz(), 4_000_000);
    assert_eq!(c.vco_out_hz(), 300_000_000);
    assert_eq!(c.pll_sysclk_hz(), 150_000_000);
    assert_eq!(c.hclk_hz(), 150_000_000);
    assert_eq!(c.pclk1_hz(), 150_000_000);
    assert_eq!(c.pclk2_hz(), 150_000_000);
    assert_eq!(c.apb1_timer_hz(), 150_000_000);
    assert_eq!(c.apb2_timer_hz(), 150_000_000);
    assert_eq!(c.timer_clk_hz(Bus::Apb1), 150_000_000);
    assert_eq!(c.timer_clk_hz(Bus::Apb2), 150_000_000);
}

/// AHB /2 halves HCLK; an APB at /1 gives timers PCLK, at /2, /8, /16 it gives timers 2 × PCLK.
#[test]
fn bus_prescalers_and_timer_doubling_hand_worked() {
    // F446 180 MHz, AHB /2 = 90 MHz, APB1 /2 = 45 MHz (timers 90), APB2 /1 = 90 MHz (timers 90).
    let c = ClockPlan {
        ahb_div: 2,
        apb1_div: 2,
        apb2_div: 1,
        ..F446.clocks
    };
    assert!(c.is_valid());
    assert_eq!(c.hclk_hz(), 90_000_000);
    assert_eq!((c.pclk1_hz(), c.apb1_timer_hz()), (45_000_000, 90_000_000));
    assert_eq!((c.pclk2_hz(), c.apb2_timer_hz()), (90_000_000, 90_000_000));
    // G474 150 MHz, APB1 /8 = 18.75 MHz (timers 37.5), APB2 /16 = 9.375 MHz (timers 18.75).
    let c = ClockPlan {
        apb1_div: 8,
        apb2_div: 16,
        ..G474.clocks
    };
    assert!(c.is_valid());
    assert_eq!((c.pclk1_hz(), c.apb1_timer_hz()), (18_750_000, 37_500_000));
    assert_eq!((c.pclk2_hz(), c.apb2_timer_hz()), (9_375_000, 18_750_000));
    assert_eq!(c.timer_clk_hz(Bus::Apb1), 37_500_000);
    assert_eq!(c.timer_clk_hz(Bus::Apb2), 18_750_000);
}

/// Carrier registers: F446 180 MHz / 12 (ARR 11, CCR 6), G474 150 MHz / 10 (ARR 9, CCR 5).
#[test]
fn carrier_registers_hand_worked() {
    assert_eq!(F446.carrier_hz(), 15_000_000);
    assert_eq!((F446.carrier_arr(), F446.carrier_ccr()), (11, 6));
    assert_eq!(G474.carrier_hz(), 15_000_000);
    assert_eq!((G474.carrier_arr(), G474.carrier_ccr()), (9, 5));
}

/// 32-bit burst counter max 4 294 967 295; 1 Hz at PSC 0 = 90 M (F446) / 150 M (G474) ticks.
#[test]
fn burst_counter_hand_worked() {
    assert_eq!(F446.burst_counter_max(), 4_294_967_295);
    assert_eq!(G474.burst_counter_max(), 4_294_967_295);
    assert_eq!(F446.burst_ticks_at_min_hz(), 90_000_000);
    assert_eq!(G474.burst_ticks_at_min_hz(), 150_000_000);
    let b16 = BoardDef {
        burst_timer_bits: 16,
        ..F446
    };
    assert_eq!(b16.burst_counter_max(), 65_535);
}

/// ADC trigger at 10 kHz: F446 TIM3 90 MHz → (PSC 0, ARR 8 999), G474 150 MHz → (0, 14 999).
#[test]
fn adc_trigger_hand_worked() {
    assert_eq!(F446.adc_trigger_psc_arr(), (0, 8_999));
    assert_eq!(F446.adc_trigger_hz(), 10_000);
    assert_eq!(G474.adc_trigger_psc_arr(), (0, 14_999));
    assert_eq!(G474.adc_trigger_hz(), 10_000);
}

/// Two triggers per sample (two 8-conversion bursts) double the trigger rate and stay consistent.
#[test]
fn two_triggers_per_sample_double_the_trigger_rate() {
    for (b, psc_arr) in [(F446, (0, 4_499)), (G474, (0, 7_499))] {
        let two = BoardDef {
            adc: AdcDef {
                triggers_per_sample: 2,
                ..b.adc
            },
            ..b
        };
        assert_eq!(two.adc_trigger_psc_arr(), psc_arr, "{}", b.name);
        assert_eq!(two.adc_trigger_hz(), 20_000, "{}", b.name);
        assert!(two.is_consistent(), "{}", b.name);
    }
}

/// At 1 kHz the 90 000 ticks of a 90 MHz trigger clock need PSC 1, ARR 44 999 (exactly 1 kHz).
#[test]
fn adc_trigger_uses_the_prescaler_past_16_bits() {
    let b = BoardDef {
        sample_rate_hz: 1_000,
        ..F446
    };
    assert_eq!(b.adc_trigger_psc_arr(), (1, 44_999));
    assert_eq!(b.adc_trigger_hz(), 1_000);
    assert!(!b.is_consistent(), "the sample rate is fixed at 10 kHz");
}

/// 65 535 and 65 536 ticks still fit PSC 0 (ARR 65 534 / 65 535); 65 537 needs PSC 1, ARR 32 767.
#[test]
fn adc_trigger_prescaler_boundary() {
    let at = |clk: u32| BoardDef {
        sample_rate_hz: 1_000,
        adc: AdcDef {
            trigger_timer_clk_hz: clk,
            ..F446.adc
        },
        ..F446
    };
    assert_eq!(at(65_535_000).adc_trigger_psc_arr(), (0, 65_534));
    assert_eq!(at(65_535_000).adc_trigger_hz(), 1_000);
    assert_eq!(at(65_536_000).adc_trigger_psc_arr(), (0, 65_535));
    assert_eq!(at(65_536_000).adc_trigger_hz(), 1_000);
    assert_eq!(at(65_537_000).adc_trigger_psc_arr(), (1, 32_767));
    // 65 537 000 / (2 × 32 768) = 1000.015… → 1 000 (truncated).
    assert_eq!(at(65_537_000).adc_trigger_hz(), 1_000);
}

// ---------------------------------------------------------------------------------------------
// ClockPlan::is_valid, one rule at a time.

/// The shipped plans are valid (the baseline every broken copy below differs from).
#[test]
fn shipped_plans_are_valid() {
    assert!(F446.clocks.is_valid());
    assert!(G474.clocks.is_valid());
}

/// PLLP/PLLR must be 2, 4, 6 or 8: /1, /3 and /10 are refused, /2 and /8 accepted.
#[test]
fn pll_output_divider_must_be_2_4_6_or_8() {
    // F446, 2 MHz PLL input: ×90 = 180 MHz VCO (in range) /1; ×180 = 360 MHz /3, /10; ×216 /8.
    assert!(!f446(8_000_000, 4, 90, 1, 180_000_000).is_valid());
    assert!(!f446(8_000_000, 4, 180, 3, 120_000_000).is_valid());
    assert!(!f446(8_000_000, 4, 180, 10, 36_000_000).is_valid());
    assert!(f446(8_000_000, 4, 216, 8, 54_000_000).is_valid());
    // G474, 4 MHz PLL input: ×40 = 160 MHz /1; ×75 = 300 MHz /3; /8 = 37.5 MHz.
    assert!(!g474(24_000_000, 6, 40, 1, 160_000_000).is_valid());
    assert!(!g474(24_000_000, 6, 75, 3, 100_000_000).is_valid());
    assert!(g474(24_000_000, 6, 75, 8, 37_500_000).is_valid());
}

/// PLLM below the minimum is refused: F446 PLLM 1 (RM0390: 2..=63), G474 PLLM 0 (no panic).
#[test]
fn pll_m_below_minimum_is_refused() {
    // A 2 MHz external clock in bypass mode with PLLM 1 keeps the PLL input at 2 MHz: only the
    // PLLM rule is broken. PLLM 2 from 4 MHz is the same chain and accepted.
    assert!(!f446(2_000_000, 1, 180, 2, 180_000_000).is_valid());
    assert!(f446(4_000_000, 2, 180, 2, 180_000_000).is_valid());
    assert!(!g474(24_000_000, 0, 75, 2, 150_000_000).is_valid());
    assert!(g474(16_000_000, 1, 8, 2, 64_000_000).is_valid());
}

/// G474 PLLM 17 is refused, 16 accepted (RM0440: 1..=16), both giving a 2.8 MHz PLL input.
#[test]
fn pll_m_above_maximum_is_refused() {
    // 47.6 MHz / 17 = 2.8 MHz and 44.8 MHz / 16 = 2.8 MHz; ×60 = 168 MHz VCO, /2 = 84 MHz.
    assert!(!g474(47_600_000, 17, 60, 2, 84_000_000).is_valid());
    assert!(g474(44_800_000, 16, 60, 2, 84_000_000).is_valid());
}

/// PLLN below the minimum is refused: F446 49 (50 accepted), G474 7 (8 accepted).
#[test]
fn pll_n_below_minimum_is_refused() {
    // F446: 8.4 MHz / 4 = 2.1 MHz; ×49 = 102.9 MHz VCO (in range), ×50 = 105 MHz; APB1 /2.
    let f = |n, sys| ClockPlan {
        apb1_div: 2,
        apb2_div: 1,
        ..f446(8_400_000, 4, n, 2, sys)
    };
    assert!(!f(49, 51_450_000).is_valid());
    assert!(f(50, 52_500_000).is_valid());
    // G474: 16 MHz / 1; ×7 = 112 MHz VCO (in range), ×8 = 128 MHz.
    assert!(!g474(16_000_000, 1, 7, 2, 56_000_000).is_valid());
    assert!(g474(16_000_000, 1, 8, 2, 64_000_000).is_valid());
}

/// PLLN above the maximum is refused: F446 433 (432 accepted), G474 128 (127 accepted).
#[test]
fn pll_n_above_maximum_is_refused() {
    // F446: 19.2 MHz / 20 = 0.96 MHz; ×433 = 415.68 MHz VCO (in range) /4; ×432 = 414.72 MHz /4.
    assert!(!f446(19_200_000, 20, 433, 4, 103_920_000).is_valid());
    assert!(f446(19_200_000, 20, 432, 4, 103_680_000).is_valid());
    // G474: 13.4 MHz / 5 = 2.68 MHz; ×128 = 343.04 MHz VCO (in range) /4; ×127 = 340.36 MHz /4.
    assert!(!g474(13_400_000, 5, 128, 4, 85_760_000).is_valid());
    assert!(g474(13_400_000, 5, 127, 4, 85_090_000).is_valid());
}

/// A PLLM that leaves a fractional PLL input is refused (8 MHz / 7, 24 MHz / 7).
#[test]
fn pll_m_must_divide_the_oscillator() {
    // F446: 8 MHz / 7 = 1 142 857.14 Hz; the truncated chain ×312 /2 would claim 178 285 692 Hz.
    assert!(!f446(8_000_000, 7, 312, 2, 178_285_692).is_valid());
    // G474: 24 MHz / 7 = 3 428 571.43 Hz; truncated ×80 /2 = 137 142 840 Hz.
    assert!(!g474(24_000_000, 7, 80, 2, 137_142_840).is_valid());
}

/// F446 PLL input: 0.95 MHz and 2.1 MHz accepted, 949 999 Hz and 2 100 001 Hz refused (DS10693).
#[test]
fn f446_pll_input_limits() {
    // 7.6 MHz / 8 = 950 000 Hz, ×400 = 380 MHz, /4 = 95 MHz.
    assert!(f446(7_600_000, 8, 400, 4, 95_000_000).is_valid());
    // 7 599 992 Hz / 8 = 949 999 Hz, ×400 = 379 999 600 Hz, /4 = 94 999 900 Hz.
    assert!(!f446(7_599_992, 8, 400, 4, 94_999_900).is_valid());
    // 8.4 MHz / 4 = 2.1 MHz, ×96 = 201.6 MHz, /2 = 100.8 MHz.
    assert!(f446(8_400_000, 4, 96, 2, 100_800_000).is_valid());
    // 8 400 004 Hz / 4 = 2 100 001 Hz, ×96 = 201 600 096 Hz, /2 = 100 800 048 Hz.
    assert!(!f446(8_400_004, 4, 96, 2, 100_800_048).is_valid());
}

/// G474 PLL input: 2.66 and 16 MHz accepted, 2 659 999 and 16 000 001 Hz refused (RM0440 §7.4.4).
#[test]
fn g474_pll_input_limits() {
    // 10.64 MHz / 4 = 2.66 MHz, ×40 = 106.4 MHz, /2 = 53.2 MHz.
    assert!(g474(10_640_000, 4, 40, 2, 53_200_000).is_valid());
    // 10 639 996 Hz / 4 = 2 659 999 Hz, ×40 = 106 399 960 Hz, /2 = 53 199 980 Hz.
    assert!(!g474(10_639_996, 4, 40, 2, 53_199_980).is_valid());
    // 16 MHz / 1, ×8 = 128 MHz, /2 = 64 MHz.
    assert!(g474(16_000_000, 1, 8, 2, 64_000_000).is_valid());
    // 16 000 001 Hz / 1, ×8 = 128 000 008 Hz, /2 = 64 000 004 Hz.
    assert!(!g474(16_000_001, 1, 8, 2, 64_000_004).is_valid());
}

/// F446 VCO: 100 MHz and 432 MHz accepted; 10 Hz under / 12 Hz over refused (RM0390 §6.3.2).
#[test]
fn f446_vco_output_limits() {
    // 2 MHz ×50 = 100 MHz /2 = 50 MHz; 2 MHz ×216 = 432 MHz /4 = 108 MHz.
    assert!(f446(8_000_000, 4, 50, 2, 50_000_000).is_valid());
    assert!(f446(8_000_000, 4, 216, 4, 108_000_000).is_valid());
    // Nearest refused VCOs that keep every divider exact (VCO = input × N, PLLP even):
    // 4 444 444 Hz / 4 = 1 111 111 Hz ×90 = 99 999 990 Hz, /6 = 16 666 665 Hz (buses /1).
    let below = ClockPlan {
        apb1_div: 1,
        apb2_div: 1,
        ..f446(4_444_444, 4, 90, 6, 16_666_665)
    };
    assert!(!below.is_valid());
    // 5 837 838 Hz / 3 = 1 945 946 Hz ×222 = 432 000 012 Hz, /6 = 72 000 002 Hz (APB1 /2, APB2 /1).
    let above = ClockPlan {
        apb1_div: 2,
        apb2_div: 1,
        ..f446(5_837_838, 3, 222, 6, 72_000_002)
    };
    assert!(!above.is_valid());
}

/// G474 VCO: 96 MHz and 344 MHz accepted; 6 Hz under / 4 Hz over refused (RM0440 §7.4.4).
#[test]
fn g474_vco_output_limits() {
    // 4 MHz ×24 = 96 MHz /2 = 48 MHz; 4 MHz ×86 = 344 MHz /4 = 86 MHz.
    assert!(g474(24_000_000, 6, 24, 2, 48_000_000).is_valid());
    assert!(g474(24_000_000, 6, 86, 4, 86_000_000).is_valid());
    // 10 666 666 Hz ×9 = 95 999 994 Hz /2 = 47 999 997 Hz.
    assert!(!g474(10_666_666, 1, 9, 2, 47_999_997).is_valid());
    // 8 390 244 Hz ×41 = 344 000 004 Hz /4 = 86 000 001 Hz.
    assert!(!g474(8_390_244, 1, 41, 4, 86_000_001).is_valid());
}

/// A VCO the output divider does not divide exactly is refused (364 MHz / 6, 304 MHz / 6).
#[test]
fn pll_output_divider_must_divide_the_vco() {
    // F446: 2 MHz ×182 = 364 MHz /6 = 60.666… MHz (APB1 /2, APB2 /1 keep the buses legal).
    let c = ClockPlan {
        apb1_div: 2,
        apb2_div: 1,
        ..f446(8_000_000, 4, 182, 6, 60_666_666)
    };
    assert!(!c.is_valid());
    // G474: 4 MHz ×76 = 304 MHz /6 = 50.666… MHz.
    assert!(!g474(24_000_000, 6, 76, 6, 50_666_666).is_valid());
}

/// A stated SYSCLK the PLL chain does not produce is refused.
#[test]
fn stated_sysclk_must_match_the_pll_chain() {
    assert!(!ClockPlan {
        sysclk_hz: 168_000_000,
        ..F446.clocks
    }
    .is_valid());
    assert!(!ClockPlan {
        sysclk_hz: 170_000_000,
        ..G474.clocks
    }
    .is_valid());
}

/// SYSCLK: F446 180 MHz and G474 170 MHz accepted; 180 000 008 Hz / 170 000 004 Hz refused.
#[test]
fn sysclk_maximum() {
    assert!(F446.clocks.is_valid());
    // G474 4 MHz ×85 = 340 MHz /2 = 170 MHz.
    assert!(g474(24_000_000, 6, 85, 2, 170_000_000).is_valid());
    // Nearest refused SYSCLKs with AHB /2 (so HCLK stays legal) and exact bus dividers:
    // F446 4 044 944 Hz / 2 = 2 022 472 Hz ×178 = 360 000 016 Hz /2 = 180 000 008 Hz.
    let f = ClockPlan {
        ahb_div: 2,
        ..f446(4_044_944, 2, 178, 2, 180_000_008)
    };
    assert!(!f.is_valid());
    // G474 14 166 667 Hz ×24 = 340 000 008 Hz /2 = 170 000 004 Hz.
    let g = ClockPlan {
        ahb_div: 2,
        ..g474(14_166_667, 1, 24, 2, 170_000_004)
    };
    assert!(!g.is_valid());
}

/// The AHB prescaler must be one HPRE encodes: a power of two up to 512 but not 32. /3, /32
/// and /1024 refused, /16, /64 and /512 accepted.
#[test]
fn ahb_prescaler_power_of_two_up_to_512() {
    assert!(!ClockPlan {
        ahb_div: 3,
        ..F446.clocks
    }
    .is_valid());
    assert!(!ClockPlan {
        ahb_div: 3,
        ..G474.clocks
    }
    .is_valid());
    // 16.384 MHz → 102.4 MHz SYSCLK, divisible by 1024: only the prescaler range decides.
    let f = f446(16_384_000, 8, 100, 2, 102_400_000);
    let g = g474(16_384_000, 4, 50, 2, 102_400_000);
    for c in [f, g] {
        assert!(ClockPlan { ahb_div: 512, ..c }.is_valid());
        assert!(ClockPlan { ahb_div: 16, ..c }.is_valid());
        assert!(ClockPlan { ahb_div: 64, ..c }.is_valid());
        assert!(!ClockPlan { ahb_div: 32, ..c }.is_valid());
        assert!(!ClockPlan { ahb_div: 1024, ..c }.is_valid());
        assert!(!ClockPlan { ahb_div: 0, ..c }.is_valid());
    }
}

/// APB1 and APB2 prescalers must be powers of two up to 16: /6 and /32 refused, /16 accepted.
#[test]
fn apb_prescalers_power_of_two_up_to_16() {
    for c in [F446.clocks, G474.clocks] {
        assert!(!ClockPlan { apb1_div: 6, ..c }.is_valid());
        assert!(!ClockPlan { apb1_div: 32, ..c }.is_valid());
        assert!(!ClockPlan { apb1_div: 0, ..c }.is_valid());
        assert!(ClockPlan { apb1_div: 16, ..c }.is_valid());
        assert!(!ClockPlan { apb2_div: 6, ..c }.is_valid());
        assert!(!ClockPlan { apb2_div: 32, ..c }.is_valid());
        assert!(!ClockPlan { apb2_div: 0, ..c }.is_valid());
        assert!(ClockPlan { apb2_div: 16, ..c }.is_valid());
    }
}

/// An AHB prescaler that leaves a fractional HCLK is refused (180 MHz / 512, 150 MHz / 256).
#[test]
fn ahb_prescaler_must_divide_sysclk() {
    let c = ClockPlan {
        ahb_div: 512,
        apb1_div: 1,
        apb2_div: 1,
        ..F446.clocks
    };
    assert!(!c.is_valid());
    assert!(ClockPlan { ahb_div: 256, ..c }.is_valid());
    let c = ClockPlan {
        ahb_div: 256,
        ..G474.clocks
    };
    assert!(!c.is_valid());
    assert!(ClockPlan { ahb_div: 128, ..c }.is_valid());
}

/// An APB prescaler that leaves a fractional PCLK is refused (12.625 / 12.375 MHz HCLK, /16).
#[test]
fn apb_prescalers_must_divide_hclk() {
    // F446: 8 MHz / 8 = 1 MHz ×101 = 101 MHz /8 = 12.625 MHz; G474: 24 / 8 = 3 MHz ×33 /8.
    let f = ClockPlan {
        apb1_div: 1,
        apb2_div: 1,
        ..f446(8_000_000, 8, 101, 8, 12_625_000)
    };
    let g = g474(24_000_000, 8, 33, 8, 12_375_000);
    for c in [f, g] {
        assert!(c.is_valid());
        assert!(ClockPlan { apb1_div: 8, ..c }.is_valid());
        assert!(!ClockPlan { apb1_div: 16, ..c }.is_valid());
        assert!(ClockPlan { apb2_div: 8, ..c }.is_valid());
        assert!(!ClockPlan { apb2_div: 16, ..c }.is_valid());
    }
}

/// F446 PCLK1 ≤ 45 MHz: APB1 /2 at 180 MHz (90 MHz) and 45 000 001 Hz refused (RM0390 §6.3.3).
#[test]
fn f446_pclk1_maximum() {
    assert!(!ClockPlan {
        apb1_div: 2,
        ..F446.clocks
    }
    .is_valid());
    // 4 390 244 Hz / 4 = 1 097 561 Hz ×164 = 180 000 004 Hz /2 = 90 000 002 Hz, APB1 /2.
    let c = ClockPlan {
        apb1_div: 2,
        apb2_div: 2,
        ..f446(4_390_244, 4, 164, 2, 90_000_002)
    };
    assert_eq!(c.pclk1_hz(), 45_000_001);
    assert!(!c.is_valid());
}

/// F446 PCLK2 ≤ 90 MHz: APB2 /1 at 180 MHz and 90 000 004 Hz refused (RM0390 §6.3.3).
#[test]
fn f446_pclk2_maximum() {
    assert!(!ClockPlan {
        apb2_div: 1,
        ..F446.clocks
    }
    .is_valid());
    // 4 044 944 Hz / 2 = 2 022 472 Hz ×89 = 180 000 008 Hz /2 = 90 000 004 Hz, APB2 /1.
    let c = ClockPlan {
        apb2_div: 1,
        ..f446(4_044_944, 2, 89, 2, 90_000_004)
    };
    assert_eq!(c.pclk2_hz(), 90_000_004);
    assert!(!c.is_valid());
}

/// A limits table whose HCLK cap is below its SYSCLK cap has that HCLK cap enforced.
#[test]
fn hclk_maximum_is_enforced_when_below_sysclk_maximum() {
    // Unreachable with the shipped limits: both chips have HCLK max = SYSCLK max, HCLK ≤ SYSCLK.
    let limits = PllLimits {
        hclk_max_hz: 168_000_000,
        ..F446.clocks.limits
    };
    let c = ClockPlan {
        limits,
        ..F446.clocks
    };
    assert!(!c.is_valid());
    assert!(ClockPlan { ahb_div: 2, ..c }.is_valid());
}

// ---------------------------------------------------------------------------------------------
// BoardDef::is_consistent, one rule at a time.

/// Both shipped boards are consistent (the baseline every broken copy below differs from).
#[test]
fn shipped_boards_are_consistent() {
    assert!(F446.is_consistent());
    assert!(G474.is_consistent());
}

/// A board whose clock plan is out of the chip's limits is refused even if every figure agrees.
#[test]
fn invalid_clock_plan_is_refused() {
    // F446 PLLM 2 → 4 MHz PLL input (> 2.1 MHz), still 360 MHz VCO and 180 MHz SYSCLK.
    let f = BoardDef {
        clocks: ClockPlan {
            pll_m: 2,
            pll_n: 90,
            ..F446.clocks
        },
        ..F446
    };
    assert!(!f.is_consistent());
    // G474 PLLM 3, PLLR 4 → 600 MHz VCO (> 344 MHz), still 150 MHz SYSCLK.
    let g = BoardDef {
        clocks: ClockPlan {
            pll_m: 3,
            pll_out_div: 4,
            ..G474.clocks
        },
        ..G474
    };
    assert!(!g.is_consistent());
}

/// A flattened `sysclk_hz` that disagrees with the clock plan is refused.
#[test]
fn flattened_sysclk_must_match_the_plan() {
    for b in [F446, G474] {
        let bad = BoardDef {
            sysclk_hz: 168_000_000,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// A flattened carrier clock that disagrees with the carrier timer (30 MHz / 2) is refused.
#[test]
fn flattened_carrier_clock_must_match_the_timer() {
    for b in [F446, G474] {
        let bad = BoardDef {
            carrier_timer_clk_hz: 30_000_000,
            carrier_divider: 2,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// A carrier timer whose clock is not its bus's timer clock is refused (30 MHz stated).
#[test]
fn carrier_clock_must_be_the_bus_timer_clock() {
    for b in [F446, G474] {
        let bad = BoardDef {
            carrier: PwmTimer {
                clk_hz: 30_000_000,
                ..b.carrier
            },
            carrier_timer_clk_hz: 30_000_000,
            carrier_divider: 2,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
    // F446: TIM1 declared on APB1 (90 MHz timers) while its clock says 180 MHz.
    let f = BoardDef {
        carrier: PwmTimer {
            bus: Bus::Apb1,
            ..F446.carrier
        },
        ..F446
    };
    assert!(!f.is_consistent());
    // G474: both timer clocks are 150 MHz, so the bus does not change the carrier clock.
    let g = BoardDef {
        carrier: PwmTimer {
            bus: Bus::Apb1,
            ..G474.carrier
        },
        ..G474
    };
    assert!(g.is_consistent());
}

/// Carrier divider 0 (no panic) and 1 are refused, 2 is accepted (ARR 1, CCR 1).
#[test]
fn carrier_divider_at_least_two() {
    for b in [F446, G474] {
        let zero = BoardDef {
            carrier_divider: 0,
            ..b
        };
        assert!(!zero.is_consistent(), "{}", b.name);
    }
    // 120 MHz SYSCLK; APB2 /16 = 7.5 MHz → 15 MHz carrier timer clock, /8 = 15 MHz → 30 MHz.
    let f = f446(8_000_000, 4, 120, 2, 120_000_000); // APB1 /4 = 30 MHz → 60 MHz timers
    let g = g474(24_000_000, 6, 60, 2, 120_000_000); // APB1 /1 → 120 MHz timers
    for (b, c, apb1_tim) in [(F446, f, 60_000_000), (G474, g, 120_000_000)] {
        // Divider 1 on a 15 MHz clock breaks "≥ 2" and "even" (no 50 % duty) together.
        let one = BoardDef {
            carrier_divider: 1,
            ..retimed(&b, ClockPlan { apb2_div: 16, ..c }, apb1_tim, 15_000_000)
        };
        assert!(one.clocks.is_valid());
        assert!(!one.is_consistent(), "{}", b.name);
        let two = BoardDef {
            carrier_divider: 2,
            ..retimed(&b, ClockPlan { apb2_div: 8, ..c }, apb1_tim, 30_000_000)
        };
        assert!(two.is_consistent(), "{}", b.name);
        assert_eq!(two.carrier_hz(), 15_000_000);
        assert_eq!((two.carrier_arr(), two.carrier_ccr()), (1, 1));
    }
}

/// A carrier clock a few Hz off a 15 MHz multiple is refused though clock / divider is 15 000 000.
#[test]
fn carrier_clock_must_be_a_multiple_of_15_mhz() {
    // This rule cannot break alone: clock / divider = 15 MHz leaves the clock at most
    // divider − 1 Hz over a 15 MHz multiple, and every timer clock of one plan is that clock
    // × 2^k, so the ADC trigger clock then leaves a 10 kHz multiple too (its exact-rate rule
    // still holds).
    // F446: 4 044 944 Hz / 2 = 2 022 472 Hz ×89 = 180 000 008 Hz /2 = 90 000 004 Hz SYSCLK;
    // APB1 /4 = 22 500 001 Hz (timers 45 000 002), APB2 /2 (timers 90 000 004); /6 → 15 000 000.67.
    let f = BoardDef {
        carrier_divider: 6,
        ..retimed(
            &F446,
            f446(4_044_944, 2, 89, 2, 90_000_004),
            45_000_002,
            90_000_004,
        )
    };
    // G474: 4 477 612 Hz ×67 = 300 000 004 Hz /2 = 150 000 002 Hz, all timers; /10 → 15 000 000.2.
    let g = retimed(
        &G474,
        g474(4_477_612, 1, 67, 2, 150_000_002),
        150_000_002,
        150_000_002,
    );
    for b in [f, g] {
        assert!(b.clocks.is_valid(), "{}", b.name);
        assert_eq!(b.carrier_hz(), 15_000_000, "{}", b.name);
        assert_eq!(b.adc_trigger_hz(), 10_000, "{}", b.name);
        assert!(!b.is_consistent(), "{}", b.name);
    }
}

/// A carrier divider that does not give 15 MHz is refused (F446 /10 = 18 MHz, /14; G474 /12).
#[test]
fn carrier_divider_must_give_15_mhz() {
    for (b, div) in [(F446, 10), (F446, 14), (G474, 12), (G474, 8)] {
        let bad = BoardDef {
            carrier_divider: div,
            ..b
        };
        assert!(!bad.is_consistent(), "{} /{div}", b.name);
    }
}

/// An odd carrier divider (no 50 % duty) is refused: F446 at 135 MHz /9, G474 at 165 MHz /11.
#[test]
fn carrier_divider_must_be_even() {
    // F446 135 MHz: 2 MHz ×135 = 270 MHz /2; APB1 /4 = 33.75 MHz (timers 67.5), APB2 timers 135.
    let f = BoardDef {
        carrier_divider: 9,
        ..retimed(
            &F446,
            f446(8_000_000, 4, 135, 2, 135_000_000),
            67_500_000,
            135_000_000,
        )
    };
    // G474 165 MHz: 24 MHz / 8 = 3 MHz ×110 = 330 MHz /2, all timers 165 MHz.
    let g = BoardDef {
        carrier_divider: 11,
        ..retimed(
            &G474,
            g474(24_000_000, 8, 110, 2, 165_000_000),
            165_000_000,
            165_000_000,
        )
    };
    for b in [f, g] {
        assert!(b.clocks.is_valid(), "{}", b.name);
        assert_eq!(b.carrier_hz(), 15_000_000, "{}", b.name);
        assert!(!b.is_consistent(), "{}", b.name);
    }
}

/// A flattened burst clock that disagrees with the burst timer is refused.
#[test]
fn flattened_burst_clock_must_match_the_timer() {
    for b in [F446, G474] {
        let bad = BoardDef {
            burst_timer_clk_hz: b.burst_timer_clk_hz / 2,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// A burst timer whose clock is not its bus's timer clock is refused.
#[test]
fn burst_clock_must_be_the_bus_timer_clock() {
    for b in [F446, G474] {
        let half = b.burst_timer_clk_hz / 2;
        let bad = BoardDef {
            burst: PwmTimer {
                clk_hz: half,
                ..b.burst
            },
            burst_timer_clk_hz: half,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
    // F446: TIM2 declared on APB2 (180 MHz timers) while its clock says 90 MHz.
    let f = BoardDef {
        burst: PwmTimer {
            bus: Bus::Apb2,
            ..F446.burst
        },
        ..F446
    };
    assert!(!f.is_consistent());
}

/// A flattened burst counter width that disagrees with the burst timer is refused.
#[test]
fn flattened_burst_bits_must_match_the_timer() {
    for b in [F446, G474] {
        let bad = BoardDef {
            burst: PwmTimer {
                counter_bits: 16,
                ..b.burst
            },
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// The burst timer must be 32-bit: a 16-bit (TIM3-like) or 31-bit counter is refused.
#[test]
fn burst_timer_must_be_32_bit() {
    for b in [F446, G474] {
        // 16 bits also breaks "1 Hz fits at PSC 0" (90 M / 150 M ticks > 65 535); 31 bits breaks
        // only the width rule (2^31 − 1 > 150 M), which is the one that can break alone.
        for bits in [16, 31] {
            let bad = BoardDef {
                burst: PwmTimer {
                    counter_bits: bits,
                    ..b.burst
                },
                burst_timer_bits: bits,
                ..b
            };
            assert!(!bad.is_consistent(), "{} {bits}-bit", b.name);
        }
    }
}

/// A board advertising another top burst frequency than 2 kHz is refused.
#[test]
fn max_burst_hz_is_fixed() {
    for b in [F446, G474] {
        for hz in [1_000, 2_001] {
            let bad = BoardDef {
                max_burst_hz: hz,
                ..b
            };
            assert!(!bad.is_consistent(), "{} {hz}", b.name);
        }
    }
}

/// A board sampling at 20 kHz instead of 10 kHz is refused (its trigger would still be exact).
#[test]
fn sample_rate_is_fixed() {
    for b in [F446, G474] {
        let bad = BoardDef {
            sample_rate_hz: 20_000,
            ..b
        };
        assert_eq!(bad.adc_trigger_hz(), 20_000);
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// A board whose code is not the sum of 16 conversions is refused (flattened count or the
/// ADC's own).
#[test]
fn the_velocity_window_stays_within_the_narrow_sums() {
    // 8 ..= 64: both ends kept, one past either refused.
    for b in [F446, G474] {
        for (window, ok) in [(7, false), (8, true), (26, true), (64, true), (65, false)] {
            let w = BoardDef {
                velocity_window: window,
                ..b
            };
            assert_eq!(w.is_consistent(), ok, "{} window {window}", b.name);
        }
    }
}

#[test]
fn oversampling_is_sixteen() {
    for b in [F446, G474] {
        let flat = BoardDef {
            adc_oversample: 8,
            ..b
        };
        assert!(!flat.is_consistent(), "{}", b.name);
    }
    let f = BoardDef {
        adc: AdcDef {
            oversampling: Oversampling::Software {
                conversions: 8,
                shift: 0,
            },
            ..F446.adc
        },
        ..F446
    };
    assert!(!f.is_consistent());
    let g = BoardDef {
        adc: AdcDef {
            oversampling: Oversampling::Hardware { ratio: 8, shift: 0 },
            ..G474.adc
        },
        ..G474
    };
    assert!(!g.is_consistent());
    assert_eq!(f.adc.oversampling.conversions(), 8);
    assert_eq!(g.adc.oversampling.conversions(), 8);
    assert_eq!(F446.adc.oversampling.conversions(), 16);
    // The G474 converts 32 and halves the sum: the code is still 16 conversions' worth.
    assert_eq!(G474.adc.oversampling.conversions(), 32);
    assert_eq!(G474.adc.oversampling.code_conversions(), Some(16));
    let g474 = |ratio, shift| BoardDef {
        adc: AdcDef {
            oversampling: Oversampling::Hardware { ratio, shift },
            ..G474.adc
        },
        ..G474
    };
    // Any power-of-two ratio shifted back to 16 is a 16-conversion code; a sum of 32 unshifted,
    // a ratio the oversampler does not have (24, 512) or a shift past the ratio is not.
    for (ratio, shift, ok) in [
        (16, 0, true),
        (32, 1, true),
        (64, 2, true),
        (256, 4, true),
        (32, 0, false),
        (64, 1, false),
        (24, 0, false),
        (512, 5, false),
        (16, 5, false),
        (16, 40, false),
    ] {
        assert_eq!(g474(ratio, shift).is_consistent(), ok, "{ratio} >> {shift}");
    }
    assert_eq!(g474(16, 5).adc.oversampling.code_conversions(), None);
}

/// An ADC trigger timer clock that is not its bus's timer clock is refused.
#[test]
fn adc_trigger_clock_must_be_the_bus_timer_clock() {
    for b in [F446, G474] {
        // Half the clock still divides to exactly 10 kHz, so only the bus rule breaks.
        let bad = BoardDef {
            adc: AdcDef {
                trigger_timer_clk_hz: b.adc.trigger_timer_clk_hz / 2,
                ..b.adc
            },
            ..b
        };
        assert_eq!(bad.adc_trigger_hz(), 10_000);
        assert!(!bad.is_consistent(), "{}", b.name);
    }
    // F446: TIM3 declared on APB2 (180 MHz timers) while its clock says 90 MHz.
    let f = BoardDef {
        adc: AdcDef {
            trigger_bus: Bus::Apb2,
            ..F446.adc
        },
        ..F446
    };
    assert!(!f.is_consistent());
}

/// Seven triggers per sample (70 kHz, not reachable exactly: 70 038 / 70 028 Hz) are refused.
#[test]
fn adc_trigger_rate_must_be_exact() {
    // With 10 kHz samples and a carrier that is an exact 15 MHz multiple every timer clock is a
    // multiple of 3.75 MHz, so an inexact rate always also fails "clock % rate == 0".
    for (b, hz) in [(F446, 70_038), (G474, 70_028)] {
        let bad = BoardDef {
            adc: AdcDef {
                triggers_per_sample: 7,
                ..b.adc
            },
            ..b
        };
        assert_eq!(bad.adc_trigger_hz(), hz, "{}", b.name);
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// Every output or input on a reserved Nucleo pin is refused, one pin at a time.
#[test]
fn reserved_pins_are_refused_on_every_signal() {
    for b in [F446, G474] {
        // TIM1_CH1 → PA5 would light LD2, TIM2_CH1 on PA15 is high during boot, the wiper on
        // PA3 fights the VCP, RF arm on PC13 is the user button, IDT B on PA2 (TIM2_CH3) the VCP.
        let carrier = BoardDef {
            carrier: PwmTimer {
                pin: pin('A', 5),
                ..b.carrier
            },
            ..b
        };
        let burst = BoardDef {
            burst: PwmTimer {
                pin: pin('A', 15),
                ..b.burst
            },
            ..b
        };
        let adc = BoardDef {
            adc: AdcDef {
                pin: pin('A', 3),
                ..b.adc
            },
            ..b
        };
        let rf_arm = BoardDef {
            rf_arm_pin: pin('C', 13),
            ..b
        };
        let burst_b = BoardDef {
            burst_b_pin: pin('A', 2),
            ..b
        };
        for (what, bad) in [
            ("carrier", carrier),
            ("burst", burst),
            ("adc", adc),
            ("rf arm", rf_arm),
            ("burst B", burst_b),
        ] {
            assert!(!bad.is_consistent(), "{}: {what}", b.name);
        }
        // Same signals moved to free pins stay consistent.
        let moved = BoardDef {
            rf_arm_pin: pin('C', 12),
            burst_b_pin: pin('C', 11),
            ..b
        };
        assert!(moved.is_consistent(), "{}", b.name);
    }
}

/// Every reserved pin is reported, and its neighbours are not.
#[test]
fn reserved_pin_list() {
    for (port, n) in [
        ('A', 2),
        ('A', 3),
        ('A', 5),
        ('A', 13),
        ('A', 14),
        ('A', 15),
        ('C', 13),
        ('C', 14),
        ('C', 15),
        ('H', 0),
        ('H', 1),
        ('H', 3),
    ] {
        assert!(is_reserved(&pin(port, n)), "P{port}{n}");
    }
    for (port, n) in [
        ('A', 0),
        ('A', 1),
        ('A', 4),
        ('A', 6),
        ('A', 8),
        ('A', 12),
        ('B', 2),
        ('B', 3),
        ('B', 5),
        ('B', 13),
        ('B', 14),
        ('B', 15),
        ('C', 2),
        ('C', 5),
        ('C', 12),
        ('D', 2),
        ('G', 13),
    ] {
        assert!(!is_reserved(&pin(port, n)), "P{port}{n}");
    }
}

/// `Pin::is` matches port and number together, never one of them alone.
#[test]
fn pin_is_matches_port_and_number() {
    let pa8 = pin('A', 8);
    assert!(pa8.is('A', 8));
    assert!(!pa8.is('B', 8));
    assert!(!pa8.is('A', 9));
    assert!(!pa8.is('B', 9));
}

/// IDT B on the same pin as any other signal is refused (PA8, PA0, PA1, PB5).
#[test]
fn burst_b_pin_must_differ_from_every_other_pin() {
    for b in [F446, G474] {
        for other in [b.carrier.pin, b.burst.pin, b.adc.pin, b.rf_arm_pin] {
            let bad = BoardDef {
                burst_b_pin: other,
                ..b
            };
            assert!(!bad.is_consistent(), "{}: {other:?}", b.name);
        }
    }
}

/// IDT B on the burst timer's own channel is refused.
#[test]
fn burst_b_channel_must_differ_from_burst_channel() {
    for b in [F446, G474] {
        let bad = BoardDef {
            burst_b_channel: b.burst.channel,
            ..b
        };
        assert!(!bad.is_consistent(), "{}", b.name);
    }
}

/// IDT B channel 0 and 5 are refused; 1 (burst on 2), 2 and 4 are accepted.
#[test]
fn burst_b_channel_is_1_to_4() {
    for b in [F446, G474] {
        for (ch, ok) in [(0, false), (2, true), (4, true), (5, false)] {
            let c = BoardDef {
                burst_b_channel: ch,
                ..b
            };
            assert_eq!(c.is_consistent(), ok, "{} channel {ch}", b.name);
        }
        let one = BoardDef {
            burst: PwmTimer {
                channel: 2,
                ..b.burst
            },
            burst_b_channel: 1,
            ..b
        };
        assert!(one.is_consistent(), "{}", b.name);
    }
}

/// Any two of carrier, burst, wiper and RF arm on one pin are refused, whatever the AF.
#[test]
fn signal_pins_must_be_distinct() {
    for b in [F446, G474] {
        let pa8 = b.carrier.pin;
        let pa0 = b.burst.pin;
        let pa1 = b.adc.pin;
        let bad = [
            BoardDef {
                burst: PwmTimer {
                    pin: pa8,
                    ..b.burst
                },
                ..b
            },
            BoardDef {
                adc: AdcDef { pin: pa8, ..b.adc },
                ..b
            },
            BoardDef {
                rf_arm_pin: pa8,
                ..b
            },
            BoardDef {
                adc: AdcDef { pin: pa0, ..b.adc },
                ..b
            },
            BoardDef {
                rf_arm_pin: pa0,
                ..b
            },
            BoardDef {
                rf_arm_pin: pa1,
                ..b
            },
        ];
        for (i, bad) in bad.iter().enumerate() {
            assert!(!bad.is_consistent(), "{} pair {i}", b.name);
        }
        // A different AF on the same port/pin is still the same pin.
        let af = BoardDef {
            rf_arm_pin: Pin { af: Some(3), ..pa1 },
            ..b
        };
        assert!(!af.is_consistent(), "{}", b.name);
    }
}

/// Carrier, burst, ADC trigger and time driver sharing a timer (any pair) are refused.
#[test]
fn timers_must_be_distinct() {
    for b in [F446, G474] {
        let bad = [
            BoardDef {
                burst: PwmTimer {
                    name: "TIM1",
                    ..b.burst
                },
                ..b
            },
            BoardDef {
                adc: AdcDef {
                    trigger_timer: "TIM1",
                    ..b.adc
                },
                ..b
            },
            BoardDef {
                time_driver_timer: "TIM1",
                ..b
            },
            BoardDef {
                adc: AdcDef {
                    trigger_timer: "TIM2",
                    ..b.adc
                },
                ..b
            },
            BoardDef {
                time_driver_timer: "TIM2",
                ..b
            },
            BoardDef {
                time_driver_timer: "TIM3",
                ..b
            },
        ];
        for (i, bad) in bad.iter().enumerate() {
            assert!(!bad.is_consistent(), "{} pair {i}", b.name);
        }
    }
}

/// Timer names are compared whole: TIM12 (F446) / TIM15 (G474) as time driver is not TIM1.
#[test]
fn timer_names_compare_whole() {
    for (b, t) in [(F446, "TIM12"), (G474, "TIM15")] {
        let ok = BoardDef {
            time_driver_timer: t,
            ..b
        };
        assert!(ok.is_consistent(), "{} {t}", b.name);
    }
    // The same pair the other way round: carrier TIM12, time driver TIM1.
    let f = BoardDef {
        carrier: PwmTimer {
            name: "TIM12",
            ..F446.carrier
        },
        time_driver_timer: "TIM1",
        ..F446
    };
    assert!(f.is_consistent());
}

/// Carrier and burst channels 0 and 5 are refused, 1 and 4 accepted.
#[test]
fn timer_channels_are_1_to_4() {
    for b in [F446, G474] {
        for (ch, ok) in [(0, false), (1, true), (4, true), (5, false)] {
            let carrier = BoardDef {
                carrier: PwmTimer {
                    channel: ch,
                    ..b.carrier
                },
                ..b
            };
            assert_eq!(carrier.is_consistent(), ok, "{} carrier ch {ch}", b.name);
            let burst = BoardDef {
                burst: PwmTimer {
                    channel: ch,
                    ..b.burst
                },
                ..b
            };
            assert_eq!(burst.is_consistent(), ok, "{} burst ch {ch}", b.name);
        }
    }
}

/// Boards are found by their exact name only.
#[test]
fn lookup_by_exact_name() {
    assert_eq!(
        by_name("nucleo-f446re").map(|b| b.name),
        Some("nucleo-f446re")
    );
    assert_eq!(
        by_name("nucleo-g474re").map(|b| b.name),
        Some("nucleo-g474re")
    );
    assert!(by_name("nucleo-f446r").is_none());
    assert!(by_name("nucleo-f446ree").is_none());
    assert!(by_name("nucleo-f446rf").is_none());
    assert!(by_name("").is_none());
}

/// The memory each board definition states is what its linker script (`boards/<name>/memory.x`,
/// copied by the firmware's build.rs) gives the linker: origin and length of FLASH and RAM.
#[test]
fn memory_matches_each_boards_linker_script() {
    for b in saw_boards::ALL {
        let path = format!("{}/{}/memory.x", env!("CARGO_MANIFEST_DIR"), b.name);
        let text = std::fs::read_to_string(&path).unwrap();
        let region = |name: &str| -> (u32, u32) {
            let line = text
                .lines()
                .find(|l| l.trim_start().starts_with(&format!("{name} ")))
                .unwrap_or_else(|| panic!("{path}: no {name} region"));
            let field = |key: &str| {
                line.split(key)
                    .nth(1)
                    .unwrap()
                    .split(',')
                    .next()
                    .unwrap()
                    .trim()
            };
            let origin =
                u32::from_str_radix(field("ORIGIN =").trim_start_matches("0x"), 16).unwrap();
            let len = field("LENGTH =");
            let kib: u32 = len.strip_suffix('K').unwrap().parse().unwrap();
            (origin, kib * 1024)
        };
        assert_eq!(
            region("FLASH"),
            (b.flash_origin, b.flash_bytes),
            "{}",
            b.name
        );
        assert_eq!(region("RAM"), (b.ram_origin, b.ram_bytes), "{}", b.name);
    }
}

/// Each board's store is whole erase units (two or more) on unit boundaries, inside the chip's
/// flash and past everything the image may link into (`flash_bytes`, the linker's FLASH region),
/// and addressable in its embassy region. The F446's units are its sectors (RM0390 §3.3 table 4:
/// 4 × 16 KiB, 64 KiB, then 128 KiB each); the G474's store must be in bank 2 (from
/// 0x0804_0000 in dual-bank mode, RM0440 §5.3.1) for the CPU to run on while it is written.
#[test]
fn each_store_is_whole_erase_units_the_image_never_reaches() {
    for b in saw_boards::ALL {
        let s = b.store;
        let chip_end = b.flash_origin + b.chip_flash_bytes;
        assert!(
            s.origin >= b.flash_origin + b.flash_bytes,
            "{}: store overlaps the image",
            b.name
        );
        assert!(s.end() <= chip_end, "{}: store past the flash", b.name);
        assert_eq!((s.origin - b.flash_origin) % s.erase_bytes, 0, "{}", b.name);
        assert_eq!(s.bytes % s.erase_bytes, 0, "{}", b.name);
        assert!(
            s.bytes / s.erase_bytes >= 2,
            "{}: fewer than two erase units",
            b.name
        );
        assert!(s.region_base <= s.origin, "{}", b.name);
        let r = s.region_range();
        assert_eq!(r.end - r.start, s.bytes, "{}", b.name);
    }
    // The F446: sector boundaries from the reference manual's table, not from the layout.
    let f = saw_boards::NUCLEO_F446RE.store;
    let mut sector_starts = vec![0x0800_0000u32];
    for size_kib in [16, 16, 16, 16, 64, 128, 128, 128] {
        let last = *sector_starts.last().unwrap();
        sector_starts.push(last + size_kib * 1024);
    }
    assert!(sector_starts.contains(&f.origin) && sector_starts.contains(&f.end()));
    assert_eq!(f.erase_bytes, 128 * 1024);
    assert!(!f.read_while_write);
    // embassy's F446 region 3 starts at sector 5.
    assert_eq!(f.region_base, sector_starts[5]);
    // The G474: bank 2 is the upper 256 KiB.
    let g = saw_boards::NUCLEO_G474RE.store;
    assert!(g.origin >= 0x0804_0000 && g.region_base == 0x0804_0000);
    assert_eq!(g.erase_bytes, 2 * 1024);
    assert!(g.read_while_write);
}

/// The RF level's DAC output must be PA4 (DAC1_OUT1 on both chips), not a reserved pin, not
/// any other role's pin, and its calibration table must pass its checks: each broken alone is
/// refused, the board as shipped is accepted.
#[test]
fn rf_level_pin_and_table_rules() {
    use saw_boards::rf_level::{LevelPoint, LevelTable};
    const BAD_TABLE: LevelTable = LevelTable {
        points: &[
            LevelPoint {
                permille: 0,
                code: 0,
            },
            LevelPoint {
                permille: 1000,
                code: 5000,
            },
        ],
    };
    for b in [F446, G474] {
        assert!(b.is_consistent(), "{}", b.name);
        let with_pin = |pin: saw_boards::Pin| BoardDef {
            rf_level: saw_boards::RfLevelDef {
                dac_pin: pin,
                ..b.rf_level
            },
            ..b
        };
        // PA5 is DAC1_OUT2 but the Nucleo's LED: reserved, and not PA4 either.
        let pa = |pin| saw_boards::Pin {
            port: 'A',
            pin,
            af: None,
            header: "",
        };
        for (pin, why) in [(pa(5), "PA5 (the LED)"), (pa(6), "PA6 (no DAC)")] {
            assert!(!with_pin(pin).is_consistent(), "{}: {why}", b.name);
        }
        // Another role on PA4, with the DAC there too.
        let pa4 = |pin: saw_boards::Pin| saw_boards::Pin {
            port: 'A',
            pin: 4,
            ..pin
        };
        let others = [
            (
                "the carrier",
                BoardDef {
                    carrier: saw_boards::PwmTimer {
                        pin: pa4(b.carrier.pin),
                        ..b.carrier
                    },
                    ..b
                },
            ),
            (
                "the burst",
                BoardDef {
                    burst: saw_boards::PwmTimer {
                        pin: pa4(b.burst.pin),
                        ..b.burst
                    },
                    ..b
                },
            ),
            (
                "IDT B",
                BoardDef {
                    burst_b_pin: pa4(b.burst_b_pin),
                    ..b
                },
            ),
            (
                "the wiper",
                BoardDef {
                    adc: saw_boards::AdcDef {
                        pin: pa4(b.adc.pin),
                        ..b.adc
                    },
                    ..b
                },
            ),
            (
                "the arm",
                BoardDef {
                    rf_arm_pin: pa4(b.rf_arm_pin),
                    ..b
                },
            ),
        ];
        for (why, bad) in others {
            assert!(!bad.is_consistent(), "{}: {why} on PA4", b.name);
        }
        let bad = BoardDef {
            rf_level: saw_boards::RfLevelDef {
                table: BAD_TABLE,
                ..b.rf_level
            },
            ..b
        };
        assert!(!bad.is_consistent(), "{}: a code past the DAC", b.name);
    }
}

// ---------------------------------------------------------------------------------------------
// The sampling time against the rheostat's source impedance (`AdcDef::settles_source`).
//
// Hand-worked limits, from the datasheets' R_AIN equation (DS10693 / DS12288, ADC
// characteristics): R_AIN ≤ (k − 0.5) / (f_ADC · C_ADC · ln 2^14) − R_ADC, with
// ln 2^14 taken as 9.704061 (the code's rational, rounded up from 9.7040605):
//   F446, 22.5 MHz, 7 pF: f·C·ln = 1.575e-4 × 9.704061 = 1.52838961e-3 S
//     56 cycles:  55.5 / 1.52838961e-3 = 36 312.73 Ω → 36 312 − 6 000 = 30 312 Ω
//     15 cycles:  14.5 / 1.52838961e-3 =  9 487.11 Ω →  9 487 − 6 000 =  3 487 Ω
//      3 cycles:   2.5 / 1.52838961e-3 =  1 635.71 Ω, below R_ADC 6 000 Ω: nothing settles
//   G474, 37.5 MHz, 5 pF: f·C·ln = 1.875e-4 × 9.704061 = 1.81951144e-3 S
//     47.5 cycles: 47 / 1.81951144e-3 = 25 831.11 Ω → 25 831 − 11 500 = 14 331 Ω
//     24.5 cycles: 24 / 1.81951144e-3 = 13 190.35 Ω → 13 190 − 11 500 =  1 690 Ω

/// The rheostat named in the plan: 10 kΩ, its worst source R/4 = 2 500 Ω at mid-travel
/// (R·u·(1 − u) at u = ½), the figure both boards state.
#[test]
fn rheostat_source_is_a_quarter_of_its_resistance() {
    assert_eq!(RHEOSTAT_OHM, 10_000);
    assert_eq!(RHEOSTAT_SOURCE_OHM_MAX, 2_500);
    assert_eq!(F446.adc.source_ohm_max, 2_500);
    assert_eq!(G474.adc.source_ohm_max, 2_500);
}

/// The ADC data each board states: F446 22.5 MHz, 6 kΩ, 7 pF (DS10693 maxima); G474 37.5 MHz,
/// 11.5 kΩ (effective, fitted), 5 pF (DS12288).
#[test]
fn adc_input_data_as_stated() {
    assert_eq!(
        (F446.adc.clk_hz, F446.adc.switch_ohm, F446.adc.hold_ff),
        (22_500_000, 6_000, 7_000)
    );
    assert_eq!(
        (G474.adc.clk_hz, G474.adc.switch_ohm, G474.adc.hold_ff),
        (37_500_000, 11_500, 5_000)
    );
}

/// The largest source each sampling time settles, against the hand-worked figures above.
#[test]
fn max_source_ohm_hand_worked() {
    let at = |b: BoardDef, half_cycles| AdcDef {
        sample_half_cycles: half_cycles,
        ..b.adc
    };
    assert_eq!(F446.adc.max_source_ohm(), Some(30_312));
    assert_eq!(at(F446, 30).max_source_ohm(), Some(3_487));
    assert_eq!(at(F446, 6).max_source_ohm(), None);
    assert_eq!(G474.adc.max_source_ohm(), Some(14_331));
    assert_eq!(at(G474, 49).max_source_ohm(), Some(1_690));
}

/// A source one ohm past the sampling time's limit is refused, the source on the limit accepted
/// (F446 30 312 Ω, G474 14 331 Ω), the shipped 2 500 Ω accepted.
#[test]
fn source_past_the_sampling_limit_is_refused() {
    for (b, limit_ohm) in [(F446, 30_312), (G474, 14_331)] {
        let with = |source_ohm_max| BoardDef {
            adc: AdcDef {
                source_ohm_max,
                ..b.adc
            },
            ..b
        };
        assert!(with(2_500).is_consistent(), "{}", b.name);
        assert!(with(limit_ohm).is_consistent(), "{} on the limit", b.name);
        assert!(
            !with(limit_ohm + 1).is_consistent(),
            "{} one ohm past",
            b.name
        );
    }
}

/// A sampling time too short for the rheostat's 2 500 Ω is refused: G474 24.5 cycles (settles
/// 1 690 Ω; a 1 690 Ω source is accepted there, 1 691 refused) and F446 3 cycles (settles
/// nothing: R_ADC alone is past the bound, so even a 0 Ω source is refused); F446 15 cycles
/// (3 487 Ω) still settles 2 500 Ω.
#[test]
fn sampling_time_too_short_for_the_rheostat_is_refused() {
    let with = |b: BoardDef, half_cycles, source_ohm_max| BoardDef {
        adc: AdcDef {
            sample_half_cycles: half_cycles,
            source_ohm_max,
            ..b.adc
        },
        ..b
    };
    assert!(!with(G474, 49, 2_500).is_consistent());
    assert!(with(G474, 49, 1_690).is_consistent());
    assert!(!with(G474, 49, 1_691).is_consistent());
    assert!(!with(F446, 6, 2_500).is_consistent());
    assert!(!with(F446, 6, 0).is_consistent());
    assert!(with(F446, 30, 2_500).is_consistent());
}

/// A larger hold capacitor or a faster ADC clock shortens what a sampling time settles: the
/// F446 at 56 cycles with C_ADC 70 pF (ten times) settles 3 631 Ω − 6 000 Ω, nothing; the G474
/// at 47.5 cycles with f_ADC 75 MHz (twice) settles 12 915 − 11 500 = 1 415 Ω, short of 2 500.
#[test]
fn slower_settling_adc_data_is_refused() {
    let f = BoardDef {
        adc: AdcDef {
            hold_ff: 70_000,
            ..F446.adc
        },
        ..F446
    };
    // 55.5 / (22.5e6 × 70e-12 × 9.704061) = 55.5 / 1.52838961e-2 = 3 631.27 Ω.
    assert_eq!(f.adc.max_source_ohm(), None);
    assert!(!f.is_consistent());
    let g = BoardDef {
        adc: AdcDef {
            clk_hz: 75_000_000,
            ..G474.adc
        },
        ..G474
    };
    // 47 / (75e6 × 5e-12 × 9.704061) = 47 / 3.63902288e-3 = 12 915.55 Ω.
    assert_eq!(g.adc.max_source_ohm(), Some(1_415));
    assert!(!g.is_consistent());
}

/// A zero ADC clock, hold capacitor or sampling time is refused without a division by zero or
/// an underflow; a sampling time of u32::MAX half cycles at 1 Hz and 1 fF saturates to u32::MAX
/// ohms (4.29e9 × 1e15 / 1.94e1 ≈ 2.2e23 Ω) rather than wrapping.
#[test]
fn degenerate_adc_data_is_refused_without_panic() {
    for adc in [
        AdcDef {
            clk_hz: 0,
            ..F446.adc
        },
        AdcDef {
            hold_ff: 0,
            ..F446.adc
        },
        AdcDef {
            sample_half_cycles: 0,
            ..F446.adc
        },
    ] {
        assert_eq!(adc.max_source_ohm(), None, "{adc:?}");
        assert!(!adc.settles_source(), "{adc:?}");
    }
    let huge = AdcDef {
        sample_half_cycles: u32::MAX,
        clk_hz: 1,
        hold_ff: 1,
        switch_ohm: 0,
        source_ohm_max: u32::MAX,
        ..F446.adc
    };
    assert_eq!(huge.max_source_ohm(), Some(u32::MAX));
    assert!(huge.settles_source());
}

/// `max_source_ohm` at its edges, worked by hand: f_ADC 1 MHz, C_ADC 1 pF (1000 fF), 1.5
/// sampling cycles (3 half cycles: k − 0.5 = 1) give R_AIN + R_ADC ≤ 1 / (10^6 · 10^−12 ·
/// 9.704061) = 103 049.6 Ω, floored 103 049. A sampling switch of exactly that leaves 0 Ω for
/// the source (a 0 Ω source still settles); one ohm more and nothing settles. Data that would
/// allow more than u32::MAX ohms (f_ADC 1 Hz, C_ADC 1 fF: ~1.03 · 10^14 Ω) saturates there.
#[test]
fn the_source_limit_at_its_edges() {
    let edge = AdcDef {
        clk_hz: 1_000_000,
        hold_ff: 1_000,
        sample_half_cycles: 3,
        switch_ohm: 103_049,
        source_ohm_max: 0,
        ..F446.adc
    };
    assert_eq!(edge.max_source_ohm(), Some(0));
    assert!(edge.settles_source());
    let past = AdcDef {
        switch_ohm: 103_050,
        ..edge
    };
    assert_eq!(past.max_source_ohm(), None);
    assert!(!past.settles_source());
    let huge = AdcDef {
        clk_hz: 1,
        hold_ff: 1,
        switch_ohm: 0,
        ..edge
    };
    assert_eq!(huge.max_source_ohm(), Some(u32::MAX));
}
