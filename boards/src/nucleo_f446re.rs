//! NUCLEO-F446RE (STM32F446RET6, Cortex-M4F, 180 MHz max).
//!
//! Clock plan: HSE 8 MHz in **bypass** (the ST-LINK's MCO drives OSC_IN, solder bridge SB50 on,
//! the Nucleo default) → PLLM 4 → 2 MHz VCO input → PLLN 180 → 360 MHz VCO → PLLP 2 →
//! SYSCLK 180 MHz (needs voltage scale 1 + over-drive, set by embassy for > 168 MHz).
//! AHB /1 = 180 MHz, APB1 /4 = 45 MHz (APB1 timers 90 MHz), APB2 /2 = 90 MHz (APB2 timers
//! 180 MHz). Carrier: TIM1 (APB2) at 180 MHz, ARR 11 → 180 / 12 = 15 MHz exactly, CCR 6 = 50 %.
use crate::*;

/// STM32F446 PLL and bus limits (DS10693: PLL input 0.95–2.1 MHz, VCO 100–432 MHz;
/// RM0390: PLLM 2..=63, PLLN 50..=432, PLLP ∈ {2,4,6,8}; SYSCLK/HCLK 180 MHz with over-drive,
/// PCLK1 ≤ 45 MHz, PCLK2 ≤ 90 MHz).
pub const F446_LIMITS: PllLimits = PllLimits {
    m_min: 2,
    m_max: 63,
    n_min: 50,
    n_max: 432,
    out_divs: &[2, 4, 6, 8],
    vco_in_min_hz: 950_000,
    vco_in_max_hz: 2_100_000,
    vco_out_min_hz: 100_000_000,
    vco_out_max_hz: 432_000_000,
    sysclk_max_hz: 180_000_000,
    hclk_max_hz: 180_000_000,
    pclk1_max_hz: 45_000_000,
    pclk2_max_hz: 90_000_000,
};

/// ADCCLK, Hz: PCLK2 90 MHz / 4 (ADC_CCR.ADCPRE, RM0390 §13 common registers; /2 would give 45 MHz, past
/// DS10693's f_ADC maximum of 36 MHz at VDDA ≥ 2.4 V). embassy-stm32 picks this divider; the
/// binding's comment (firmware/src/board/f446.rs `SAMPLE_TIME`) states the same.
pub const F446_ADC_CLK_HZ: u32 = 22_500_000;
/// R_ADC, Ω: DS10693 ADC characteristics, sampling switch resistance, 6 kΩ max.
pub const F446_ADC_SWITCH_OHM: u32 = 6_000;
/// C_ADC, fF: DS10693 ADC characteristics, 4 pF typical, 7 pF max: the maximum is taken.
pub const F446_ADC_HOLD_FF: u32 = 7_000;

pub const CLOCKS: ClockPlan = ClockPlan {
    source: OscSource::HseBypass,
    osc_hz: 8_000_000,
    pll_m: 4,
    pll_n: 180,
    pll_out: PllOut::P,
    pll_out_div: 2,
    sysclk_hz: 180_000_000,
    ahb_div: 1,
    apb1_div: 4,
    apb2_div: 2,
    limits: F446_LIMITS,
};

pub const NUCLEO_F446RE: BoardDef = BoardDef {
    name: "nucleo-f446re",
    probe_rs_chip: "STM32F446RETx",
    embassy_chip: "stm32f446re",
    family: Family::Stm32F4,
    clocks: CLOCKS,
    sysclk_hz: CLOCKS.sysclk_hz,

    // TIM1_CH1 = PA8 AF1 (Arduino D7).
    carrier: PwmTimer {
        name: "TIM1",
        bus: Bus::Apb2,
        clk_hz: CLOCKS.apb2_timer_hz(),
        counter_bits: 16,
        channel: 1,
        pin: Pin {
            port: 'A',
            pin: 8,
            af: Some(1),
            header: "D7 (CN9-8), morpho CN10-23",
        },
    },
    carrier_timer_clk_hz: CLOCKS.apb2_timer_hz(),
    carrier_divider: 12,

    // TIM2_CH1 = PA0 AF1 (Arduino A0). TIM2 is 32-bit on the F446.
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

    // Rheostat wiper on PA1 = ADC123_IN1 (Arduino A1). ADC1 EXTSEL 0b1000 = TIM3_TRGO.
    adc: AdcDef {
        mode: AdcMode::Single,
        adc: "ADC1",
        channel: 1,
        pin: Pin {
            port: 'A',
            pin: 1,
            af: None,
            header: "A1 (CN8-2), morpho CN7-30",
        },
        oversampling: Oversampling::Software {
            conversions: ADC_OVERSAMPLE,
            shift: 0,
        },
        // 56 cycles (firmware/src/board/f446.rs: the rheostat's source impedance).
        sample_half_cycles: 112,
        trigger_timer: "TIM3",
        trigger_bus: Bus::Apb1,
        trigger_timer_clk_hz: CLOCKS.apb1_timer_hz(),
        trigger_extsel: 0b1000,
        triggers_per_sample: 1,
        clk_hz: F446_ADC_CLK_HZ,
        switch_ohm: F446_ADC_SWITCH_OHM,
        hold_ff: F446_ADC_HOLD_FF,
        source_ohm_max: RHEOSTAT_SOURCE_OHM_MAX,
    },
    sample_rate_hz: SAMPLE_RATE_HZ,
    adc_oversample: ADC_OVERSAMPLE,
    // 16 conversions a sample: 32 samples keep the velocity noise at 1.59 mm/s (1.66 worst seed)
    // for 1.63 ms of lag (docs/conversion-budget.md, "The pick").
    velocity_window: 32,

    // PA4 = DAC1_OUT1 (Arduino A2), the amplifier's gain control; TIM8 paces envelopes.
    rf_level: crate::RfLevelDef::nucleo64(
        CLOCKS.apb2_timer_hz(),
        "DMA2 stream 2 channel 7 (TIM8_CH1, RM0390 table 29)",
    ),
    // PB5 (Arduino D4): plain push-pull GPIO, RF amplifier arm/interlock.
    rf_arm_pin: Pin {
        port: 'B',
        pin: 5,
        af: None,
        header: "D4 (CN9-5), morpho CN10-29",
    },
    time_driver_timer: "TIM4",

    flash_origin: 0x0800_0000,
    // The image: sectors 0–4 (4 × 16 + 64 KiB, RM0390 §3.3 table 4). Sector 5 is left empty so
    // the image can grow by 128 KiB without moving the store.
    flash_bytes: 128 * 1024,
    chip_flash_bytes: 512 * 1024,
    // Sectors 6 and 7 (128 KiB each): the smallest erase units past the image's room. Erasing
    // one stalls every flash fetch for 1–2 s (DS10693 t_ERASE128KB; RM0390 §3.5: a read during
    // an operation stalls the bus): the save sequence turns RF off and lengthens the IWDG.
    store: crate::StoreLayout {
        origin: 0x0804_0000,
        bytes: 256 * 1024,
        erase_bytes: 128 * 1024,
        write_bytes: 4,
        // embassy's Bank1Region3: sectors 5–7.
        region_base: 0x0802_0000,
        read_while_write: false,
    },
    ram_origin: 0x2000_0000,
    ram_bytes: 128 * 1024,
};

// Compile-time proof of the plan.
const _: () = assert!(CLOCKS.is_valid());
const _: () = assert!(CLOCKS.vco_in_hz() == 2_000_000);
const _: () = assert!(CLOCKS.vco_out_hz() == 360_000_000);
const _: () = assert!(CLOCKS.pll_sysclk_hz() == 180_000_000);
const _: () = assert!(NUCLEO_F446RE.carrier_timer_clk_hz == 180_000_000);
const _: () = assert!(NUCLEO_F446RE.carrier_timer_clk_hz % CARRIER_HZ == 0);
const _: () = assert!(NUCLEO_F446RE.carrier_hz() == CARRIER_HZ);
const _: () = assert!(NUCLEO_F446RE.burst_timer_clk_hz == 90_000_000);
// 56 cycles at 22.5 MHz settle ≤ 30 312 Ω (DS10693's R_AIN equation, `AdcDef::max_source_ohm`):
// the rheostat's 2.5 kΩ with twelvefold room.
const _: () = assert!(
    NUCLEO_F446RE.adc.settles_source(),
    "nucleo-f446re: adc.sample_half_cycles does not settle adc.source_ohm_max (the rheostat's \
     2 500 Ω mid-travel source) to 1/4 LSB (DS10693 R_AIN equation, AdcDef::max_source_ohm)"
);
const _: () = assert!(NUCLEO_F446RE.is_consistent());

/// NUCLEO-F446RE with ADC1 + ADC2 in dual regular interleaved mode on the wiper (issue #35; the
/// firmware's `dual-adc` feature): PA1 is ADC123_IN1, so both ADCs reach it (DS10693 pin
/// table). One TIM3 trigger per 10 kHz sample runs both ADCs' 16-rank sequences, ADC2
/// 17 cycles behind ADC1 (15-cycle sampling + 2: only one ADC may sample the pin at a time,
/// RM0390 §13.9.3): 32 conversions at 15 cycles, 16 pairs of 34 ADC clock cycles, 24.6 µs of
/// the 100 µs period; the sum of 32 halved (shift 1) is the core's 16-conversion code.
///
/// Not the conversion budget's 128 per sample (`docs/conversion-budget.md`): 64 pairs at 34
/// cycles are 96.7 µs, nearly the whole period, and the sensor-to-gate latency is measured from
/// the trigger that starts a sample's conversions (limit 100 µs; the sample path after the last
/// conversion takes ~25 µs on this board): see `docs/board-model.md`, "Dual interleaved".
pub const NUCLEO_F446RE_DUAL: BoardDef = BoardDef {
    adc: AdcDef {
        mode: AdcMode::DualInterleaved { delay_cycles: 17 },
        oversampling: Oversampling::Software {
            conversions: 2 * ADC_OVERSAMPLE,
            shift: 1,
        },
        // 15 cycles at 22.5 MHz settle ≤ 3 488 Ω against the rheostat's 2 500 Ω (the const
        // assertion below; the conversion budget's feasibility rule, 536 ns, is met by 667 ns).
        sample_half_cycles: 30,
        ..NUCLEO_F446RE.adc
    },
    ..NUCLEO_F446RE
};
const _: () = assert!(NUCLEO_F446RE_DUAL.adc.settles_source());
const _: () = assert!(NUCLEO_F446RE_DUAL.is_consistent());

/// [`NUCLEO_F446RE_DUAL`] at the conversion budget's 128 conversions per sample (the firmware's
/// `dual-adc-128` feature, an experiment, not a shipping plan): TIM3 at 40 kHz, four triggers
/// per 10 kHz sample, each running both ADCs' 16 ranks (16 pairs, 24.6 µs of its 25 µs); the sum
/// of 128 shifted by 3. Its conversions span 99.6 µs of the sample's 100 µs, which the board
/// model's sensor-to-gate latency (from the sample's first trigger) holds against 100 µs
/// (`docs/board-model.md`, "Issue #35").
pub const NUCLEO_F446RE_DUAL128: BoardDef = BoardDef {
    adc: AdcDef {
        oversampling: Oversampling::Software {
            conversions: 8 * ADC_OVERSAMPLE,
            shift: 3,
        },
        triggers_per_sample: 4,
        ..NUCLEO_F446RE_DUAL.adc
    },
    ..NUCLEO_F446RE_DUAL
};
const _: () = assert!(NUCLEO_F446RE_DUAL128.is_consistent());
