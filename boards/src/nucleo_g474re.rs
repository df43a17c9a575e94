//! NUCLEO-G474RE (STM32G474RET6, Cortex-M4F, 170 MHz max).
//!
//! Clock plan: HSE 24 MHz **crystal** (X3 on the Nucleo-G474RE) → PLLM 6 → 4 MHz PLL input →
//! PLLN 75 → 300 MHz VCO → PLLR 2 → SYSCLK 150 MHz. 150 MHz is the range-1 *normal* mode
//! maximum, so no boost mode is needed, and 150 MHz = 10 × 15 MHz. AHB/APB1/APB2 all /1, every
//! timer kernel clock is 150 MHz. Carrier: TIM1 ARR 9 → 150 / 10 = 15 MHz exactly, CCR 5 = 50 %.
use crate::*;

/// STM32G474 PLL and bus limits (DS12288: PLL input 2.66–16 MHz, VCO 96–344 MHz;
/// RM0440: PLLM 1..=16, PLLN 8..=127, PLLR ∈ {2,4,6,8}; SYSCLK/HCLK/PCLK ≤ 170 MHz in boost mode).
pub const G474_LIMITS: PllLimits = PllLimits {
    m_min: 1,
    m_max: 16,
    n_min: 8,
    n_max: 127,
    out_divs: &[2, 4, 6, 8],
    vco_in_min_hz: 2_660_000,
    vco_in_max_hz: 16_000_000,
    vco_out_min_hz: 96_000_000,
    vco_out_max_hz: 344_000_000,
    sysclk_max_hz: 170_000_000,
    hclk_max_hz: 170_000_000,
    pclk1_max_hz: 170_000_000,
    pclk2_max_hz: 170_000_000,
};

/// ADC12 clock, Hz: SYSCLK 150 MHz / 4 (ADC12_CCR.PRESC, RM0440 §21 common registers; DS12288's f_ADC
/// maximum is 60 MHz). embassy-stm32 picks this divider; the binding's comment
/// (firmware/src/board/g474.rs `SAMPLE_TIME`) states the same.
pub const G474_ADC_CLK_HZ: u32 = 37_500_000;
/// R_ADC, Ω: an **effective** value, not a datasheet line. DS12288 gives C_ADC and a "maximum
/// R_AIN" table instead of R_ADC; 11.5 kΩ is fitted to that table as the firmware reads it
/// (≈ 2 kΩ at 24.5 cycles; docs/conversion-budget.md, host-sim `budget::g474`). Not re-checked
/// against the datasheet: replace it when the table is read again.
pub const G474_ADC_SWITCH_OHM: u32 = 11_500;
/// C_ADC, fF: DS12288 ADC characteristics, 5 pF.
pub const G474_ADC_HOLD_FF: u32 = 5_000;

pub const CLOCKS: ClockPlan = ClockPlan {
    source: OscSource::HseCrystal,
    osc_hz: 24_000_000,
    pll_m: 6,
    pll_n: 75,
    pll_out: PllOut::R,
    pll_out_div: 2,
    sysclk_hz: 150_000_000,
    ahb_div: 1,
    apb1_div: 1,
    apb2_div: 1,
    limits: G474_LIMITS,
};

pub const NUCLEO_G474RE: BoardDef = BoardDef {
    name: "nucleo-g474re",
    probe_rs_chip: "STM32G474RETx",
    embassy_chip: "stm32g474re",
    family: Family::Stm32G4,
    clocks: CLOCKS,
    sysclk_hz: CLOCKS.sysclk_hz,

    // TIM1_CH1 = PA8 AF6 (Arduino D7) — same connector position as on the F446 board.
    carrier: PwmTimer {
        name: "TIM1",
        bus: Bus::Apb2,
        clk_hz: CLOCKS.apb2_timer_hz(),
        counter_bits: 16,
        channel: 1,
        pin: Pin {
            port: 'A',
            pin: 8,
            af: Some(6),
            header: "D7 (CN9-8), morpho CN10-23",
        },
    },
    carrier_timer_clk_hz: CLOCKS.apb2_timer_hz(),
    carrier_divider: 10,

    // TIM2_CH1 = PA0 AF1 (Arduino A0). TIM2 is 32-bit on the G474.
    burst: PwmTimer {
        name: "TIM2",
        bus: Bus::Apb1,
        clk_hz: CLOCKS.apb1_timer_hz(),
        counter_bits: 32,
        channel: 1,
        pin: Pin {
            port: 'A',
            pin: 0,
            af: Some(1),
            header: "A0 (CN8-1), morpho CN7-28",
        },
    },
    // TIM2_CH3 = PB10 AF1 (Arduino D6): second RF enable (IDT B).
    burst_b_channel: 3,
    burst_b_pin: Pin {
        port: 'B',
        pin: 10,
        af: Some(1),
        header: "D6 (CN9-7), morpho CN10-25",
    },
    burst_timer_clk_hz: CLOCKS.apb1_timer_hz(),
    burst_timer_bits: 32,
    max_burst_hz: MAX_BURST_HZ,

    // Rheostat wiper on PA1 = ADC12_IN2 (Arduino A1). ADC12 EXTSEL 4 = TIM3_TRGO (RM0440).
    adc: AdcDef {
        mode: AdcMode::Single,
        adc: "ADC1",
        channel: 2,
        pin: Pin {
            port: 'A',
            pin: 1,
            af: None,
            header: "A1 (CN8-2), morpho CN7-30",
        },
        // 32 conversions at 47.5-cycle sampling (51.2 µs of the 100 µs period), the sum halved
        // to the 16-conversion code: the conversion budget's G474 default
        // (docs/conversion-budget.md: 1/√2 the velocity noise of 16 conversions at the same
        // lag); why 47.5 cycles against the rheostat: firmware/src/board/g474.rs.
        oversampling: Oversampling::Hardware {
            ratio: 2 * ADC_OVERSAMPLE,
            shift: 1,
        },
        sample_half_cycles: 95,
        trigger_timer: "TIM3",
        trigger_bus: Bus::Apb1,
        trigger_timer_clk_hz: CLOCKS.apb1_timer_hz(),
        trigger_extsel: 4,
        triggers_per_sample: 1,
        clk_hz: G474_ADC_CLK_HZ,
        switch_ohm: G474_ADC_SWITCH_OHM,
        hold_ff: G474_ADC_HOLD_FF,
        source_ohm_max: RHEOSTAT_SOURCE_OHM_MAX,
    },
    sample_rate_hz: SAMPLE_RATE_HZ,
    adc_oversample: ADC_OVERSAMPLE,
    // 32 conversions a sample (1/√2 the F446's noise): 26 samples give 1.54 mm/s (1.58 worst
    // seed), under the 1.66 mm/s bound, for 1.33 ms of lag instead of 1.66 (docs/conversion-budget.md,
    // "The pick"; host-sim/tests/budget.rs `the_g474_acquisition_could_buy_a_fifth_of_the_lag`).
    velocity_window: 26,

    // PA4 = DAC1_OUT1 (Arduino A2), the amplifier's gain control; TIM8 paces envelopes.
    rf_level: crate::RfLevelDef::nucleo64(
        CLOCKS.apb2_timer_hz(),
        "DMA1 channel 4 (DMAMUX1 channel 3, request 49 = TIM8_CH1)",
    ),
    rf_arm_pin: Pin {
        port: 'B',
        pin: 5,
        af: None,
        header: "D4 (CN9-5), morpho CN10-29",
    },
    time_driver_timer: "TIM4",

    flash_origin: 0x0800_0000,
    // The image: the first 128 KiB of bank 1 (as on the F446).
    flash_bytes: 128 * 1024,
    chip_flash_bytes: 512 * 1024,
    // The last 8 pages of bank 2 (2 KiB pages in dual-bank mode, DBANK = 1, the factory setting:
    // RM0440 §5.3.1; FLASH_OPTR in §5.7). Erasing or writing bank 2 leaves bank 1 readable
    // (read-while-write, RM0440 §5.3): the firmware keeps running from bank 1 while it saves.
    store: crate::StoreLayout {
        origin: 0x0807_C000,
        bytes: 16 * 1024,
        erase_bytes: 2 * 1024,
        write_bytes: 8,
        // embassy's Bank2Region (feature `dual-bank`): all of bank 2.
        region_base: 0x0804_0000,
        read_while_write: true,
    },
    ram_origin: 0x2000_0000,
    ram_bytes: 96 * 1024,
};

const _: () = assert!(CLOCKS.is_valid());
const _: () = assert!(CLOCKS.vco_in_hz() == 4_000_000);
const _: () = assert!(CLOCKS.vco_out_hz() == 300_000_000);
const _: () = assert!(CLOCKS.pll_sysclk_hz() == 150_000_000);
const _: () = assert!(CLOCKS.sysclk_hz <= 170_000_000);
const _: () = assert!(NUCLEO_G474RE.carrier_timer_clk_hz % CARRIER_HZ == 0);
const _: () = assert!(NUCLEO_G474RE.carrier_hz() == CARRIER_HZ);
const _: () = assert!(NUCLEO_G474RE.burst_timer_clk_hz == 150_000_000);
// 47.5 cycles at 37.5 MHz settle ≤ 14 331 Ω (25 831 Ω − R_ADC, DS12288's R_AIN equation,
// `AdcDef::max_source_ohm`): the rheostat's 2.5 kΩ with fivefold room. 24.5 cycles would settle
// only 1 690 Ω and is refused.
const _: () = assert!(
    NUCLEO_G474RE.adc.settles_source(),
    "nucleo-g474re: adc.sample_half_cycles does not settle adc.source_ohm_max (the rheostat's \
     2 500 Ω mid-travel source) to 1/4 LSB (DS12288 R_AIN equation, AdcDef::max_source_ohm)"
);
const _: () = assert!(NUCLEO_G474RE.is_consistent());
