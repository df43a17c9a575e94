//! Board definitions for the SAW tactile display.
//!
//! Pure data and `const fn`s: no embassy, no PAC, no chip crates, so `cargo test -p saw-boards`
//! runs on the host and the firmware (`firmware/`) builds its embassy RCC/timer configuration
//! from these numbers. Every clock figure is checked twice: by `const` assertions in the board
//! modules (a wrong plan does not compile) and by the unit tests below.
//!
//! The one hard requirement: the SAW carrier is **exactly** 15 MHz, i.e. the carrier timer's
//! kernel clock is an integer multiple of 15 MHz and the timer divides by that integer.
#![no_std]
#![forbid(unsafe_code)]

pub mod nucleo_f446re;
pub mod nucleo_g474re;
pub mod rf_level;
pub mod touch;

pub use nucleo_f446re::{NUCLEO_F446RE, NUCLEO_F446RE_DUAL, NUCLEO_F446RE_DUAL128};
pub use nucleo_g474re::NUCLEO_G474RE;

/// SAW carrier frequency (Hz). Fixed by the interdigital transducer on the LiNbO3 substrate.
pub const CARRIER_HZ: u32 = 15_000_000;
/// Position sample rate delivered to the control core (Hz).
pub const SAMPLE_RATE_HZ: u32 = 10_000;
/// The position sample's scale: the sum of 16 12-bit conversions (0..=65 520). A board may
/// convert more per sample and scale the sum back to this ([`Oversampling::Hardware`]'s shift).
pub const ADC_OVERSAMPLE: u32 = 16;
/// The rheostat's total resistance, Ω: a linear slide potentiometer wired as a divider (ends to
/// 3.3 V and GND, wiper to the ADC pin; `boards/README.md`, "Before the first flash").
pub const RHEOSTAT_OHM: u32 = 10_000;
/// The wiper's worst Thevenin source resistance, Ω: R·u·(1 − u) at travel fraction u peaks at
/// u = ½, R/4 = 2.5 kΩ for the 10 kΩ part. Each board's sampling time must settle it
/// ([`AdcDef::settles_source`]).
pub const RHEOSTAT_SOURCE_OHM_MAX: u32 = RHEOSTAT_OHM / 4;
/// Highest burst frequency the textures use (Hz).
pub const MAX_BURST_HZ: u32 = 2_000;
/// Lowest burst frequency the textures use (Hz).
pub const MIN_BURST_HZ: u32 = 1;

/// Every board the firmware supports.
pub const ALL: &[BoardDef] = &[NUCLEO_F446RE, NUCLEO_G474RE];

/// Look a board up by its [`BoardDef::name`].
pub fn by_name(name: &str) -> Option<&'static BoardDef> {
    ALL.iter().find(|b| eq(b.name, name))
}

const fn eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// Chip family: decides the PLL limits and which PLL output drives SYSCLK.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Family {
    /// STM32F4 (F446): SYSCLK = PLL "P" output.
    Stm32F4,
    /// STM32G4 (G474): SYSCLK = PLL "R" output.
    Stm32G4,
}

/// Oscillator feeding the PLL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OscSource {
    /// HSE in bypass mode: an external clock on OSC_IN (the ST-LINK's MCO on Nucleo-64 boards).
    HseBypass,
    /// HSE with a crystal on OSC_IN/OSC_OUT.
    HseCrystal,
    /// Internal 16 MHz RC oscillator.
    Hsi,
}

/// Which PLL output is SYSCLK.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PllOut {
    P,
    R,
}

/// Datasheet limits of a PLL (all Hz, inclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PllLimits {
    pub m_min: u32,
    pub m_max: u32,
    pub n_min: u32,
    pub n_max: u32,
    /// Allowed dividers of the output that drives SYSCLK.
    pub out_divs: &'static [u32],
    pub vco_in_min_hz: u32,
    pub vco_in_max_hz: u32,
    pub vco_out_min_hz: u32,
    pub vco_out_max_hz: u32,
    pub sysclk_max_hz: u32,
    pub hclk_max_hz: u32,
    pub pclk1_max_hz: u32,
    pub pclk2_max_hz: u32,
}

/// A complete clock tree: oscillator → PLL → SYSCLK → AHB → APB1/APB2 (+ timer clocks).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClockPlan {
    pub source: OscSource,
    pub osc_hz: u32,
    /// PLL input divider (PLLM).
    pub pll_m: u32,
    /// PLL multiplier (PLLN).
    pub pll_n: u32,
    /// Divider of the PLL output that drives SYSCLK (PLLP on F4, PLLR on G4).
    pub pll_out: PllOut,
    pub pll_out_div: u32,
    /// Stated SYSCLK — checked against the PLL chain.
    pub sysclk_hz: u32,
    pub ahb_div: u32,
    pub apb1_div: u32,
    pub apb2_div: u32,
    pub limits: PllLimits,
}

impl ClockPlan {
    /// PLL input (VCO input) frequency.
    pub const fn vco_in_hz(&self) -> u32 {
        self.osc_hz / self.pll_m
    }
    /// VCO output frequency.
    pub const fn vco_out_hz(&self) -> u32 {
        self.vco_in_hz() * self.pll_n
    }
    /// SYSCLK as computed from the PLL chain.
    pub const fn pll_sysclk_hz(&self) -> u32 {
        self.vco_out_hz() / self.pll_out_div
    }
    pub const fn hclk_hz(&self) -> u32 {
        self.sysclk_hz / self.ahb_div
    }
    pub const fn pclk1_hz(&self) -> u32 {
        self.hclk_hz() / self.apb1_div
    }
    pub const fn pclk2_hz(&self) -> u32 {
        self.hclk_hz() / self.apb2_div
    }
    /// Kernel clock of timers on APB1 (TIM2..7): ×2 when the APB1 prescaler is not 1 (RM: "if the
    /// APB prescaler is 1 the timer clock is PCLK, otherwise 2 × PCLK"; TIMPRE = 0 on F4).
    pub const fn apb1_timer_hz(&self) -> u32 {
        if self.apb1_div == 1 {
            self.pclk1_hz()
        } else {
            2 * self.pclk1_hz()
        }
    }
    /// Kernel clock of timers on APB2 (TIM1, TIM8, TIM15..17, TIM20).
    pub const fn apb2_timer_hz(&self) -> u32 {
        if self.apb2_div == 1 {
            self.pclk2_hz()
        } else {
            2 * self.pclk2_hz()
        }
    }
    pub const fn timer_clk_hz(&self, bus: Bus) -> u32 {
        match bus {
            Bus::Apb1 => self.apb1_timer_hz(),
            Bus::Apb2 => self.apb2_timer_hz(),
        }
    }

    /// True when every divider is in range, every intermediate frequency is within the chip's
    /// limits and the PLL chain yields exactly the stated SYSCLK (no remainder anywhere).
    pub const fn is_valid(&self) -> bool {
        let l = &self.limits;
        let mut out_div_ok = false;
        let mut i = 0;
        while i < l.out_divs.len() {
            if l.out_divs[i] == self.pll_out_div {
                out_div_ok = true;
            }
            i += 1;
        }
        out_div_ok
            && self.pll_m >= l.m_min
            && self.pll_m <= l.m_max
            && self.pll_n >= l.n_min
            && self.pll_n <= l.n_max
            && self.osc_hz % self.pll_m == 0
            && self.vco_in_hz() >= l.vco_in_min_hz
            && self.vco_in_hz() <= l.vco_in_max_hz
            && self.vco_out_hz() >= l.vco_out_min_hz
            && self.vco_out_hz() <= l.vco_out_max_hz
            && self.vco_out_hz() % self.pll_out_div == 0
            && self.pll_sysclk_hz() == self.sysclk_hz
            && self.sysclk_hz <= l.sysclk_max_hz
            // HPRE (RM0390 §6.3.3 RCC_CFGR, RM0440 §7.4.3 RCC_CFGR): 1, 2, 4, 8, 16, 64, 128,
            // 256, 512 — a power of two up to 512 except 32, which the field cannot encode.
            && is_pow2_le(self.ahb_div, 512)
            && self.ahb_div != 32
            && is_pow2_le(self.apb1_div, 16)
            && is_pow2_le(self.apb2_div, 16)
            && self.sysclk_hz % self.ahb_div == 0
            && self.hclk_hz() <= l.hclk_max_hz
            && self.hclk_hz() % self.apb1_div == 0
            && self.hclk_hz() % self.apb2_div == 0
            && self.pclk1_hz() <= l.pclk1_max_hz
            && self.pclk2_hz() <= l.pclk2_max_hz
    }
}

const fn is_pow2_le(x: u32, max: u32) -> bool {
    x != 0 && x <= max && x.is_power_of_two()
}

/// Peripheral bus a timer hangs off (decides its kernel clock).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bus {
    Apb1,
    Apb2,
}

/// A GPIO pin with the alternate function used, and where it is on the Nucleo-64.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Pin {
    /// Port letter, e.g. `'A'`.
    pub port: char,
    pub pin: u8,
    /// Alternate function number (AFx) or `None` for GPIO/analog use.
    pub af: Option<u8>,
    /// Connector position on the Nucleo-64 (Arduino name and morpho pin).
    pub header: &'static str,
}

impl Pin {
    pub const fn is(&self, port: char, pin: u8) -> bool {
        self.port == port && self.pin == pin
    }
}

/// A timer used for a PWM output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PwmTimer {
    /// e.g. `"TIM1"`.
    pub name: &'static str,
    pub bus: Bus,
    /// Kernel clock (Hz) — must equal `clocks.timer_clk_hz(bus)`.
    pub clk_hz: u32,
    /// Counter width (16 or 32 bits).
    pub counter_bits: u8,
    /// Output channel 1..=4.
    pub channel: u8,
    pub pin: Pin,
}

/// How the conversions of one sample are obtained, and scaled to the 16-conversion code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Oversampling {
    /// `conversions` summed in software and shifted right by `shift` (F446: no hardware
    /// oversampler; 16 from a 16-rank regular sequence, shift 0; or, in dual interleaved mode,
    /// both ADCs' 16 ranks, shift 1).
    Software { conversions: u32, shift: u32 },
    /// ADC hardware oversampler (G474): `ratio` conversions accumulated, then shifted right by
    /// `shift` with rounding (RM0440 §21.4.30), so ratio / 2^shift conversions' worth of code.
    Hardware { ratio: u32, shift: u32 },
}

impl Oversampling {
    /// A ratio the G474's regular oversampler has: a power of two, 2..=256 (RM0440 §21.4.30,
    /// ADC_CFGR2.OVSR).
    pub const fn is_hardware_ratio(ratio: u32) -> bool {
        ratio.is_power_of_two() && ratio >= 2 && ratio <= 256
    }

    /// Conversions made per sample.
    pub const fn conversions(&self) -> u32 {
        match *self {
            Oversampling::Software { conversions, .. } => conversions,
            Oversampling::Hardware { ratio, .. } => ratio,
        }
    }

    /// How many conversions' sum the delivered code is: the core's scale is
    /// [`ADC_OVERSAMPLE`]. None when 2^shift does not divide the ratio (the code would not be
    /// a sum of whole conversions).
    pub const fn code_conversions(&self) -> Option<u32> {
        match *self {
            Oversampling::Software {
                conversions: ratio,
                shift,
            }
            | Oversampling::Hardware { ratio, shift } => {
                if shift >= 32 || ratio % (1 << shift) != 0 {
                    None
                } else {
                    Some(ratio >> shift)
                }
            }
        }
    }
}

/// Which ADCs convert the wiper, and how (the board plan selects it; the binding refuses a mode
/// its chip does not have).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AdcMode {
    /// One ADC (`AdcDef::adc`) converts every conversion of a sample.
    Single,
    /// ADC1 and ADC2 in dual regular interleaved mode on the same pin (RM0390 §13.9.3): a
    /// trigger starts ADC1 at once and ADC2 `delay_cycles` ADC clock cycles later, each
    /// converting its regular sequence; results are read in pairs from the common data
    /// register. `delay_cycles` must be at least the sampling time + 2 cycles (only one ADC may
    /// sample the pin at a time; the manual's rule) and is what the binding writes to DELAY.
    DualInterleaved { delay_cycles: u32 },
}

impl AdcMode {
    /// ADCs converting the wiper.
    pub const fn adcs(&self) -> u32 {
        match self {
            AdcMode::Single => 1,
            AdcMode::DualInterleaved { .. } => 2,
        }
    }
}

/// The rheostat (slider position) acquisition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AdcDef {
    /// One ADC, or two interleaved on the wiper.
    pub mode: AdcMode,
    /// e.g. `"ADC1"`.
    pub adc: &'static str,
    /// ADC input channel number of the wiper pin.
    pub channel: u8,
    pub pin: Pin,
    pub oversampling: Oversampling,
    /// Sampling time of each conversion, in half ADC-clock cycles (the G474's settings end in
    /// .5: 95 = 47.5 cycles); the binding maps it to the SMPR code and refuses one the ADC
    /// does not have. The conversion budget's "default" row is this with `oversampling`.
    pub sample_half_cycles: u32,
    /// Timer whose TRGO triggers the conversions (hardware trigger plan).
    pub trigger_timer: &'static str,
    pub trigger_bus: Bus,
    pub trigger_timer_clk_hz: u32,
    /// EXTSEL code of `trigger_timer` TRGO for this ADC (reference manual).
    pub trigger_extsel: u8,
    /// Trigger events per output sample. 1 on both boards: on the F446 one trigger runs a
    /// 16-rank regular sequence (the same channel in every rank, summed in software), on the
    /// G474 one trigger runs the 32× hardware oversampler.
    pub triggers_per_sample: u32,
    /// ADC clock f_ADC, Hz: the clock the sampling time counts in (the binding's prescaler).
    pub clk_hz: u32,
    /// Sampling switch resistance R_ADC, Ω (the chip's datasheet, "ADC characteristics").
    pub switch_ohm: u32,
    /// Sample-and-hold capacitor C_ADC, fF (femtofarads: 7 pF = 7 000 fF), datasheet as above.
    pub hold_ff: u32,
    /// The worst source resistance the pin sees, Ω: the rheostat's Thevenin resistance at
    /// mid-travel ([`RHEOSTAT_SOURCE_OHM_MAX`]). The sampling time must settle it.
    pub source_ohm_max: u32,
}

/// ln(2^(N+2)) for N = 12 bits, ln 2^14 = 14 · ln 2 = 9.704 060 53…, as the fraction
/// 9 704 061 / 1 000 000, rounded up so the integer rule is never more lenient than the formula.
pub const LN_2_POW_14: (u128, u128) = (9_704_061, 1_000_000);

impl AdcDef {
    /// Largest source resistance, Ω, that `sample_half_cycles` settles to the datasheets' error
    /// bound: the "R_AIN max" equation of DS10693 (F446) and DS12288 (G474), ADC
    /// characteristics, R_AIN < (k − 0.5) / (f_ADC · C_ADC · ln 2^(N+2)) − R_ADC with k the
    /// sampling cycles and N = 12 — the error left below ¼ LSB (e^−ln 2^14 = 2^−14 of full
    /// scale), so below ½ LSB too. k − 0.5 = (half cycles − 1) / 2, C_ADC in fF (10^−15 F):
    /// R_AIN + R_ADC ≤ (h − 1) · 10^15 / (2 · f_ADC · C_ADC,fF · ln 2^14), floored (exact for
    /// integer ohms). `None` when the sampling switch alone does not settle (R_ADC past that
    /// bound) or when the clock, the capacitor or the sampling time is zero (nothing to settle
    /// with; refused rather than divided by). Integer arithmetic in u128: no product of these
    /// u32 fields overflows it.
    pub const fn max_source_ohm(&self) -> Option<u32> {
        let (ln_num, ln_den) = LN_2_POW_14;
        if self.clk_hz == 0 || self.hold_ff == 0 || self.sample_half_cycles == 0 {
            return None;
        }
        let num = (self.sample_half_cycles as u128 - 1) * 1_000_000_000_000_000 * ln_den;
        let den = 2 * self.clk_hz as u128 * self.hold_ff as u128 * ln_num;
        let total_ohm = num / den;
        if total_ohm < self.switch_ohm as u128 {
            return None;
        }
        let r = total_ohm - self.switch_ohm as u128;
        // Saturated to u32 (only absurd data gets there: a clock or capacitor near zero).
        Some(if r >> 32 != 0 { u32::MAX } else { r as u32 })
    }

    /// The sampling time settles the stated worst source (`source_ohm_max`) to ¼ LSB.
    pub const fn settles_source(&self) -> bool {
        match self.max_source_ohm() {
            Some(limit_ohm) => self.source_ohm_max <= limit_ohm,
            None => false,
        }
    }
}

/// The flash the saved scene lives in: whole erase units the image never reaches.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StoreLayout {
    /// First address.
    pub origin: u32,
    /// Length, bytes: two or more erase units (sequential-storage reclaims a unit only once
    /// its items live on in another).
    pub bytes: u32,
    /// The erase unit, bytes (the F446's sector, the G474's page).
    pub erase_bytes: u32,
    /// The programming unit, bytes: embassy's `WRITE_SIZE` (the F446's ×32 word, the G474's
    /// double word).
    pub write_bytes: u32,
    /// Base of the embassy flash region the store is addressed in (its offsets count from here).
    pub region_base: u32,
    /// Whether the CPU keeps fetching from flash while the store is erased or written: true only
    /// when the store is in the other bank of a dual-bank flash (read-while-write, RM0440 §5.3);
    /// a single-bank erase stalls every fetch until it ends (RM0390 §3.5).
    pub read_while_write: bool,
}

impl StoreLayout {
    /// One past the last address.
    pub const fn end(&self) -> u32 {
        self.origin + self.bytes
    }
    /// The store's range as offsets in its embassy region.
    pub const fn region_range(&self) -> core::ops::Range<u32> {
        self.origin - self.region_base..self.end() - self.region_base
    }
}

/// The RF level output of a board (`docs/rf-level.md`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RfLevelDef {
    /// DAC1_OUT1 (analog, no alternate function).
    pub dac_pin: Pin,
    /// The envelope timer: slave of the burst timer, its TRGO triggers the DAC.
    pub envelope_timer: &'static str,
    pub envelope_timer_clk_hz: u32,
    /// DAC_CR.TSEL1 code of the envelope timer's TRGO.
    pub dac_tsel: u8,
    /// SMCR.TS of the envelope timer that selects the burst timer's TRGO (ITR1 = TIM2).
    pub envelope_ts: u8,
    /// The DMA that writes envelope entries into DHR12R1 on the envelope timer's CC1 request.
    pub envelope_dma: &'static str,
    /// Level ‰ → DAC code (replace for your amplifier; checked at compile time).
    pub table: rf_level::LevelTable,
}

impl RfLevelDef {
    /// The RF level of both Nucleo-64 boards: DAC1_OUT1 on PA4 (Arduino A2; UM1724 / UM2505
    /// pinouts), TIM8 as envelope timer — free on both, a DAC1 trigger on both (TSEL1 = 1, the
    /// code embassy-stm32 generates for TIM8_TRGO) and slave of TIM2 through ITR1 (TS = 1) —
    /// clocked at `envelope_timer_clk_hz`, its CC1 request on `envelope_dma`, and the reference
    /// circuit's calibration table.
    pub const fn nucleo64(envelope_timer_clk_hz: u32, envelope_dma: &'static str) -> Self {
        Self {
            dac_pin: Pin {
                port: 'A',
                pin: 4,
                af: None,
                header: "A2 (CN8-3), morpho CN7-32",
            },
            envelope_timer: "TIM8",
            envelope_timer_clk_hz,
            dac_tsel: 1,
            envelope_ts: 1,
            envelope_dma,
            table: rf_level::REFERENCE_TABLE,
        }
    }
}

/// The velocity windows a board may pick, samples: from 8 (below, the slope's noise grows as
/// N^-1.5 past any acquisition's reach) to 64, the longest whose sums saw-core keeps in 32-bit
/// arithmetic (`saw_core::velocity::LSQ_NARROW_WINDOW`).
pub const VELOCITY_WINDOWS: core::ops::RangeInclusive<usize> = 8..=64;

/// One board: chip, clocks, timers, pins, memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoardDef {
    /// Board name, also the cargo feature and the `boards/<name>/memory.x` directory.
    pub name: &'static str,
    /// probe-rs `--chip` name.
    pub probe_rs_chip: &'static str,
    /// embassy-stm32 chip feature.
    pub embassy_chip: &'static str,
    pub family: Family,
    pub clocks: ClockPlan,
    /// = `clocks.sysclk_hz` (flattened for convenience).
    pub sysclk_hz: u32,

    /// Free-running carrier timer (PWM, 50 %).
    pub carrier: PwmTimer,
    /// = `carrier.clk_hz`.
    pub carrier_timer_clk_hz: u32,
    /// carrier_timer_clk_hz / carrier_divider = 15 MHz exactly (ARR = divider − 1).
    pub carrier_divider: u32,

    /// Burst timer: PWM mode 1 on the RF-enable pin (IDT A; always follows the burst).
    pub burst: PwmTimer,
    /// Second RF-enable output on another channel of the same burst timer (IDT B): follows the
    /// burst in standing-wave drive, held inactive in progressive drive.
    pub burst_b_channel: u8,
    pub burst_b_pin: Pin,
    /// = `burst.clk_hz`.
    pub burst_timer_clk_hz: u32,
    /// = `burst.counter_bits`.
    pub burst_timer_bits: u8,
    pub max_burst_hz: u32,

    /// Rheostat ADC acquisition.
    pub adc: AdcDef,
    pub sample_rate_hz: u32,
    pub adc_oversample: u32,
    /// Samples in the velocity estimator's least-squares window (behind the median-of-3): the
    /// board's acquisition noise picks it (`docs/conversion-budget.md`, "The pick": the G474's
    /// 32 conversions a sample buy 26 samples, 1.33 ms of lag, where the F446's 16 need 32,
    /// 1.66 ms, both under the 1.66 mm/s noise bound). 8 ..= 64 ([`VELOCITY_WINDOWS`]).
    pub velocity_window: usize,

    /// RF level: DAC1 channel 1 into the amplifier's gain control, and the timer that paces
    /// envelopes (`docs/rf-level.md`).
    pub rf_level: RfLevelDef,

    /// Plain GPIO "RF arm" output (amplifier supply/enable interlock), low = RF impossible.
    pub rf_arm_pin: Pin,
    /// Timer reserved for embassy-time (the `time-driver-timX` feature).
    pub time_driver_timer: &'static str,

    pub flash_origin: u32,
    /// Flash the firmware image links into (`boards/<name>/memory.x`): the linker refuses an
    /// image that would grow past it, into the store.
    pub flash_bytes: u32,
    /// The chip's whole flash.
    pub chip_flash_bytes: u32,
    /// Where the saved scene lives (`saw-store`).
    pub store: StoreLayout,
    pub ram_origin: u32,
    /// RAM the firmware links into (see `boards/<name>/memory.x`).
    pub ram_bytes: u32,
}

impl BoardDef {
    /// Carrier frequency produced by this board (must be [`CARRIER_HZ`]).
    pub const fn carrier_hz(&self) -> u32 {
        self.carrier_timer_clk_hz / self.carrier_divider
    }
    /// Carrier timer ARR (PSC = 0).
    pub const fn carrier_arr(&self) -> u32 {
        self.carrier_divider - 1
    }
    /// Carrier timer CCR for 50 % duty in PWM mode 1 (high for CCR counts of `divider`).
    pub const fn carrier_ccr(&self) -> u32 {
        self.carrier_divider / 2
    }
    /// Largest counter value of the burst timer.
    pub const fn burst_counter_max(&self) -> u64 {
        (1u64 << self.burst_timer_bits) - 1
    }
    /// Burst timer ticks per period at the slowest burst ([`MIN_BURST_HZ`]) with PSC = 0.
    pub const fn burst_ticks_at_min_hz(&self) -> u64 {
        self.burst_timer_clk_hz as u64 / MIN_BURST_HZ as u64
    }
    /// ADC trigger timer: prescaler and auto-reload for the trigger rate
    /// (`sample_rate_hz * adc.triggers_per_sample`), as (PSC, ARR).
    pub const fn adc_trigger_psc_arr(&self) -> (u32, u32) {
        let rate = self.sample_rate_hz * self.adc.triggers_per_sample;
        let ticks = self.adc.trigger_timer_clk_hz / rate;
        // Smallest prescaler that fits the 16-bit counter.
        let psc = (ticks - 1) / 65_536;
        let arr = ticks / (psc + 1) - 1;
        (psc, arr)
    }
    /// The exact trigger rate produced by [`Self::adc_trigger_psc_arr`].
    pub const fn adc_trigger_hz(&self) -> u32 {
        let (psc, arr) = self.adc_trigger_psc_arr();
        self.adc.trigger_timer_clk_hz / ((psc + 1) * (arr + 1))
    }

    /// Every consistency rule; used by the const assertions and the tests.
    pub const fn is_consistent(&self) -> bool {
        let c = &self.clocks;
        c.is_valid()
            && self.sysclk_hz == c.sysclk_hz
            // Carrier: exact 15 MHz, integer division, 50 % duty representable.
            && self.carrier_timer_clk_hz == self.carrier.clk_hz
            && self.carrier.clk_hz == c.timer_clk_hz(self.carrier.bus)
            && self.carrier_divider >= 2
            && self.carrier_timer_clk_hz % CARRIER_HZ == 0
            && self.carrier_timer_clk_hz / self.carrier_divider == CARRIER_HZ
            && self.carrier_divider % 2 == 0
            // Burst timer: 32-bit, kernel clock from the bus, slowest burst fits with PSC = 0.
            && self.burst_timer_clk_hz == self.burst.clk_hz
            && self.burst.clk_hz == c.timer_clk_hz(self.burst.bus)
            && self.burst_timer_bits == self.burst.counter_bits
            && self.burst_timer_bits == 32
            && self.burst_ticks_at_min_hz() <= self.burst_counter_max()
            && self.max_burst_hz == MAX_BURST_HZ
            // ADC: 10 kHz, a 16-conversion code (the G474 converts 32 and halves the sum; the
            // hardware oversampler's ratio is a power of two, 2..=256, RM0440 §21.4.30),
            // trigger rate exactly reachable.
            && self.sample_rate_hz == SAMPLE_RATE_HZ
            && self.adc_oversample == ADC_OVERSAMPLE
            // The estimator's window: long enough to average, short enough for 32-bit sums.
            && self.velocity_window >= *VELOCITY_WINDOWS.start()
            && self.velocity_window <= *VELOCITY_WINDOWS.end()
            && matches!(self.adc.oversampling.code_conversions(), Some(ADC_OVERSAMPLE))
            // Dual interleaved: the second ADC starts at least the sampling time + 2 cycles
            // after the first (one ADC samples the pin at a time, RM0390 §13.9.3), so the
            // delay in half cycles is at least the sampling time's + 4.
            && match self.adc.mode {
                AdcMode::Single => true,
                AdcMode::DualInterleaved { delay_cycles } => {
                    2 * delay_cycles >= self.adc.sample_half_cycles + 4
                }
            }
            && match self.adc.oversampling {
                Oversampling::Software { .. } => true,
                Oversampling::Hardware { ratio, .. } => Oversampling::is_hardware_ratio(ratio),
            }
            // The sampling time settles the rheostat's worst source impedance (the datasheets'
            // R_AIN equation, DS10693 / DS12288 ADC characteristics; boards/README.md).
            && self.adc.settles_source()
            && self.adc.trigger_timer_clk_hz == c.timer_clk_hz(self.adc.trigger_bus)
            && self.adc_trigger_hz() == self.sample_rate_hz * self.adc.triggers_per_sample
            && self.adc.trigger_timer_clk_hz
                % (self.sample_rate_hz * self.adc.triggers_per_sample)
                == 0
            // Pins: none of the reserved Nucleo-64 pins, all distinct.
            && !is_reserved(&self.carrier.pin)
            && !is_reserved(&self.burst.pin)
            && !is_reserved(&self.adc.pin)
            && !is_reserved(&self.rf_arm_pin)
            && !is_reserved(&self.burst_b_pin)
            && !same(&self.burst_b_pin, &self.carrier.pin)
            && !same(&self.burst_b_pin, &self.burst.pin)
            && !same(&self.burst_b_pin, &self.adc.pin)
            && !same(&self.burst_b_pin, &self.rf_arm_pin)
            && self.burst_b_channel != self.burst.channel
            && self.burst_b_channel >= 1
            && self.burst_b_channel <= 4
            && !same(&self.carrier.pin, &self.burst.pin)
            && !same(&self.carrier.pin, &self.adc.pin)
            && !same(&self.carrier.pin, &self.rf_arm_pin)
            && !same(&self.burst.pin, &self.adc.pin)
            && !same(&self.burst.pin, &self.rf_arm_pin)
            && !same(&self.adc.pin, &self.rf_arm_pin)
            // The DAC output: PA4 on both chips (DAC1_OUT1), shared with nothing else.
            && self.rf_level.dac_pin.is('A', 4)
            && !is_reserved(&self.rf_level.dac_pin)
            && !same(&self.rf_level.dac_pin, &self.carrier.pin)
            && !same(&self.rf_level.dac_pin, &self.burst.pin)
            && !same(&self.rf_level.dac_pin, &self.burst_b_pin)
            && !same(&self.rf_level.dac_pin, &self.adc.pin)
            && !same(&self.rf_level.dac_pin, &self.rf_arm_pin)
            && self.rf_level.table.check().is_ok()
            // Timers: carrier, burst, ADC trigger and time driver are four different timers.
            && !eq(self.carrier.name, self.burst.name)
            && !eq(self.carrier.name, self.adc.trigger_timer)
            && !eq(self.carrier.name, self.time_driver_timer)
            && !eq(self.burst.name, self.adc.trigger_timer)
            && !eq(self.burst.name, self.time_driver_timer)
            && !eq(self.adc.trigger_timer, self.time_driver_timer)
            && self.carrier.channel >= 1
            && self.carrier.channel <= 4
            && self.burst.channel >= 1
            && self.burst.channel <= 4
    }
}

const fn same(a: &Pin, b: &Pin) -> bool {
    a.port == b.port && a.pin == b.pin
}

/// Pins the Nucleo-64 boards use for something else: PA2/PA3 (ST-LINK virtual COM port),
/// PA5 (user LED LD2), PA13/PA14 (SWD), PC13 (user button), PH0/PH1 (HSE / MCO input),
/// PC14/PC15 (LSE crystal). PA15 is additionally avoided for outputs because it comes out of
/// reset as JTDI *with pull-up* (an RF enable there would be high during boot).
pub const fn is_reserved(p: &Pin) -> bool {
    p.is('A', 2)
        || p.is('A', 3)
        || p.is('A', 5)
        || p.is('A', 13)
        || p.is('A', 14)
        || p.is('A', 15)
        || p.is('C', 13)
        || p.is('C', 14)
        || p.is('C', 15)
        || p.port == 'H'
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn all_boards_consistent() {
        assert_eq!(ALL.len(), 2);
        for b in ALL {
            assert!(b.is_consistent(), "{} inconsistent", b.name);
            assert!(b.clocks.is_valid(), "{} clock plan invalid", b.name);
        }
    }

    #[test]
    fn pll_chain_gives_stated_sysclk_within_limits() {
        for b in ALL {
            let c = &b.clocks;
            let l = &c.limits;
            assert_eq!(
                c.osc_hz % c.pll_m,
                0,
                "{}: PLLM does not divide the oscillator",
                b.name
            );
            let vin = c.osc_hz / c.pll_m;
            assert!(
                (l.vco_in_min_hz..=l.vco_in_max_hz).contains(&vin),
                "{}: VCO in {vin}",
                b.name
            );
            let vco = vin * c.pll_n;
            assert!(
                (l.vco_out_min_hz..=l.vco_out_max_hz).contains(&vco),
                "{}: VCO {vco}",
                b.name
            );
            assert_eq!(vco % c.pll_out_div, 0);
            assert_eq!(
                vco / c.pll_out_div,
                c.sysclk_hz,
                "{}: PLL chain != SYSCLK",
                b.name
            );
            assert_eq!(b.sysclk_hz, c.sysclk_hz);
            assert!(c.sysclk_hz <= l.sysclk_max_hz);
            assert!(c.pclk1_hz() <= l.pclk1_max_hz && c.pclk2_hz() <= l.pclk2_max_hz);
        }
    }

    #[test]
    fn carrier_is_exactly_15_mhz() {
        for b in ALL {
            assert_eq!(b.carrier_timer_clk_hz % CARRIER_HZ, 0, "{}", b.name);
            assert_eq!(b.carrier_timer_clk_hz % b.carrier_divider, 0, "{}", b.name);
            assert_eq!(b.carrier_hz(), 15_000_000, "{}", b.name);
            assert_eq!(b.carrier_arr() + 1, b.carrier_divider);
            // 50 % duty: high for CCR of `divider` counts.
            assert_eq!(2 * b.carrier_ccr(), b.carrier_divider);
            assert_eq!(b.carrier.clk_hz, b.clocks.timer_clk_hz(b.carrier.bus));
        }
    }

    #[test]
    fn f446_plan() {
        let b = &NUCLEO_F446RE;
        assert_eq!(b.probe_rs_chip, "STM32F446RETx");
        assert_eq!(b.embassy_chip, "stm32f446re");
        assert_eq!(b.clocks.osc_hz, 8_000_000);
        assert_eq!(b.clocks.source, OscSource::HseBypass);
        assert_eq!(b.sysclk_hz, 180_000_000);
        assert_eq!(b.carrier_timer_clk_hz, 180_000_000);
        assert_eq!(b.carrier_divider, 12);
        assert_eq!((b.carrier_arr(), b.carrier_ccr()), (11, 6));
        assert_eq!(b.burst_timer_clk_hz, 90_000_000);
        assert_eq!(b.clocks.pclk1_hz(), 45_000_000);
        assert_eq!(b.clocks.pclk2_hz(), 90_000_000);
        // TIM3 at 90 MHz → one 10 kHz trigger runs a 16-rank regular sequence of the same channel.
        assert_eq!(b.adc_trigger_hz(), 10_000);
        assert_eq!(b.adc_trigger_psc_arr(), (0, 8_999));
    }

    #[test]
    fn g474_plan() {
        let b = &NUCLEO_G474RE;
        assert_eq!(b.probe_rs_chip, "STM32G474RETx");
        assert_eq!(b.embassy_chip, "stm32g474re");
        assert_eq!(b.clocks.osc_hz, 24_000_000);
        assert_eq!(b.clocks.source, OscSource::HseCrystal);
        assert!(b.sysclk_hz <= 170_000_000);
        assert_eq!(b.sysclk_hz, 150_000_000);
        assert_eq!(b.carrier_divider, 10);
        assert_eq!((b.carrier_arr(), b.carrier_ccr()), (9, 5));
        assert_eq!(b.burst_timer_clk_hz, 150_000_000);
        assert_eq!(b.adc_trigger_hz(), 10_000);
        assert_eq!(b.adc_trigger_psc_arr(), (0, 14_999));
    }

    #[test]
    fn burst_range_fits_32_bit_timer() {
        for b in ALL {
            // 1 Hz with PSC = 0 needs clk ticks: fits a 32-bit counter.
            assert!(b.burst_ticks_at_min_hz() <= b.burst_counter_max());
            // 2 kHz still has fine duty resolution.
            assert!(b.burst_timer_clk_hz / b.max_burst_hz >= 10_000);
        }
    }

    #[test]
    fn pins_avoid_nucleo_reserved() {
        let reserved = [('A', 2), ('A', 3), ('A', 5), ('A', 13), ('A', 14)];
        for b in ALL {
            for p in [
                b.carrier.pin,
                b.burst.pin,
                b.burst_b_pin,
                b.adc.pin,
                b.rf_arm_pin,
            ] {
                assert!(
                    !reserved.iter().any(|&(port, pin)| p.is(port, pin)),
                    "{}: {:?}",
                    b.name,
                    p
                );
            }
        }
    }

    #[test]
    fn lookup_by_name() {
        assert_eq!(by_name("nucleo-f446re"), Some(&NUCLEO_F446RE));
        assert_eq!(by_name("nucleo-g474re"), Some(&NUCLEO_G474RE));
        assert_eq!(by_name("nope"), None);
    }

    #[test]
    fn invalid_plans_are_rejected() {
        // VCO input too high on the F446 (M = 2 → 4 MHz > 2.1 MHz).
        let mut c = NUCLEO_F446RE.clocks;
        c.pll_m = 2;
        c.pll_n = 90;
        assert!(!c.is_valid());
        // SYSCLK mismatch.
        let mut c = NUCLEO_F446RE.clocks;
        c.sysclk_hz = 168_000_000;
        assert!(!c.is_valid());
        // G474 above 170 MHz.
        let mut c = NUCLEO_G474RE.clocks;
        c.pll_n = 90; // 360 MHz VCO (> 344) and 180 MHz SYSCLK
        c.sysclk_hz = 180_000_000;
        assert!(!c.is_valid());
        // A carrier divider that does not give 15 MHz.
        let mut b = NUCLEO_G474RE;
        b.carrier_divider = 12;
        assert!(!b.is_consistent());
    }

    /// Timer-name comparison: whole, case-sensitive names only (TIM1 is neither TIM12 nor TIM2).
    #[test]
    fn eq_compares_whole_names() {
        assert!(eq("TIM1", "TIM1"));
        assert!(eq("", ""));
        assert!(!eq("TIM1", "TIM2"));
        assert!(!eq("TIM1", "TIM12"));
        assert!(!eq("TIM12", "TIM1"));
        assert!(!eq("TIM1", "tim1"));
        assert!(!eq("", "TIM1"));
    }

    /// Two pins are the same when port and number both match, whatever their AF or connector.
    #[test]
    fn same_needs_port_and_number() {
        let p = |port, pin, af| Pin {
            port,
            pin,
            af,
            header: "",
        };
        assert!(same(&p('A', 8, Some(1)), &p('A', 8, None)));
        assert!(!same(&p('A', 8, None), &p('A', 9, None)));
        assert!(!same(&p('A', 8, None), &p('B', 8, None)));
        assert!(!same(&p('A', 8, None), &p('B', 9, None)));
    }

    /// Bus prescalers: 1, 2, 4, … up to the maximum; 0, non-powers of two and max × 2 refused.
    #[test]
    fn is_pow2_le_bounds() {
        for x in [1, 2, 4, 8, 16] {
            assert!(is_pow2_le(x, 16), "{x}");
        }
        for x in [0, 3, 6, 12, 32] {
            assert!(!is_pow2_le(x, 16), "{x}");
        }
        assert!(is_pow2_le(512, 512));
        assert!(!is_pow2_le(1024, 512));
    }

    /// The dual interleaved plan (issue #35): two ADCs, 32 conversions halved to the 16-conversion
    /// code, 15-cycle sampling; a delay shorter than the sampling time + 2 cycles (two ADCs
    /// sampling the pin at once, RM0390 §13.9.3) or a sum not scaled to the code is refused, and
    /// the default plans stay single-ADC.
    #[test]
    fn dual_interleaved_plan_is_checked() {
        let d = NUCLEO_F446RE_DUAL;
        assert!(d.is_consistent());
        assert_eq!(d.adc.mode, AdcMode::DualInterleaved { delay_cycles: 17 });
        assert_eq!(d.adc.mode.adcs(), 2);
        assert_eq!(d.adc.oversampling.conversions(), 32);
        assert_eq!(d.adc.oversampling.code_conversions(), Some(ADC_OVERSAMPLE));
        assert_eq!(NUCLEO_F446RE.adc.mode, AdcMode::Single);
        assert_eq!(NUCLEO_G474RE.adc.mode, AdcMode::Single);
        let with = |mode, oversampling| BoardDef {
            adc: AdcDef {
                mode,
                oversampling,
                ..d.adc
            },
            ..d
        };
        let ovs = d.adc.oversampling;
        assert!(with(AdcMode::DualInterleaved { delay_cycles: 17 }, ovs).is_consistent());
        assert!(!with(AdcMode::DualInterleaved { delay_cycles: 16 }, ovs).is_consistent());
        assert!(!with(
            AdcMode::DualInterleaved { delay_cycles: 17 },
            Oversampling::Software {
                conversions: 32,
                shift: 0
            }
        )
        .is_consistent());
    }
}
