//! Reset and clock control of the STM32G474 (RM0440 §7): oscillators with ready flags (HSI16,
//! HSE, HSI48, LSI), the main PLL, the system clock switch, bus prescalers, peripheral clock
//! enables and resets, the kernel clock muxes (CCIPR: ADC12SEL), the backup-domain control
//! register, reset flags, and the clock tree computed from all of it.
//!
//! What embassy-stm32 0.6 init (lib.rs `init_hw`, ucpd.rs, rcc/g4.rs, rcc/hsi48.rs, rcc/bd.rs,
//! the generated `init_gpio`/`init_bdma`/`init_dmamux`/`ClockMux::init`) does with it, in
//! order, for the firmware's plan (HSE 24 MHz crystal, PLL M 6 N 75 R 2, AHB/APB1/APB2 /1,
//! ADC12SEL = SYSCLK):
//! - enable-and-reset SYSCFG (APB2RSTR/APB2ENR bit 0), PWR (APB1RSTR1/APB1ENR1 bit 28) and
//!   FLASH (AHB1RSTR/AHB1ENR bit 8): set RST, set EN, read EN back, clear RST;
//! - AHB2ENR GPIOA..G; AHB1ENR DMA1, DMA2, DMAMUX1;
//! - CR HSION, wait HSIRDY; CFGR SW = HSI, wait SWS; CR HSEBYP = 0, then HSEON, wait HSERDY;
//!   CRRCR HSI48ON, wait HSI48RDY (the default config keeps the HSI48 on);
//! - CR PLLON = 0, wait PLLRDY = 0; PLLCFGR written (N, M, SRC), then PLLR + PLLREN by
//!   read-modify-write; PLLON, wait PLLRDY;
//! - (no boost: CR5 untouched) FLASH latency; CFGR SW = PLL with prescalers, wait SWS = PLL;
//! - CSR LSION, wait LSIRDY; BDCR read; BDRST 1 then 0 unless the RTC already runs on the LSI;
//!   RTCEN + RTCSEL = LSI; then `ClockMux::init`: BDCR RTCSEL = 0 (ignored: write-once),
//!   CCIPR (ADC12SEL = SYS, everything else 0), CCIPR2 (0);
//! - later drivers: enable-and-reset TIM1..4, ADC12 (AHB2RSTR/AHB2ENR bit 13); `Adc` reads
//!   CCIPR.ADC12SEL to know its kernel clock.
//!
//! Ready flags and the SYSCLK switch behave as in the F446 model (`rcc_f4` module docs):
//! `ReadyDelays` default to immediate, SWS follows SW when the source is ready.

use super::misc::{g474_min_wait_states, FlashG4, PwrG4};
use super::rcc_f4::{ahb_div, apb_div, divides_master, rising_resets, Gate, Osc, Pll};
pub use super::rcc_f4::{HseInput, ReadyDelays, HSI_HZ, LSI_HZ};
use super::{merge, Clocks, Peripheral, ResetCause, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;

/// HSI48 RC oscillator (RM0440 §7.2.4).
pub const HSI48_HZ: u64 = 48_000_000;

// Register offsets (RM0440 §7.4.27 register map).
const OFF_CR: u32 = 0x00;
const OFF_ICSCR: u32 = 0x04;
const OFF_CFGR: u32 = 0x08;
const OFF_PLLCFGR: u32 = 0x0C;
const OFF_AHB1RSTR: u32 = 0x28;
const OFF_AHB2RSTR: u32 = 0x2C;
const OFF_AHB3RSTR: u32 = 0x30;
const OFF_APB1RSTR1: u32 = 0x38;
const OFF_APB1RSTR2: u32 = 0x3C;
const OFF_APB2RSTR: u32 = 0x40;
const OFF_AHB1ENR: u32 = 0x48;
const OFF_AHB2ENR: u32 = 0x4C;
const OFF_AHB3ENR: u32 = 0x50;
const OFF_APB1ENR1: u32 = 0x58;
const OFF_APB1ENR2: u32 = 0x5C;
const OFF_APB2ENR: u32 = 0x60;
const OFF_CCIPR: u32 = 0x88;
const OFF_BDCR: u32 = 0x90;
const OFF_CSR: u32 = 0x94;
const OFF_CRRCR: u32 = 0x98;
const OFF_CCIPR2: u32 = 0x9C;

/// Bus reset/enable registers: offset, writable bits, reset value (RM0440 §7.4.14–7.4.25).
/// AHB1ENR resets with FLASHEN set, APB1ENR1 with RTCAPBEN set.
const BUS_REGS: [(u32, u32, u32); 12] = [
    (OFF_AHB1RSTR, 0x0000_111F, 0),
    (OFF_AHB2RSTR, 0x050F_607F, 0),
    (OFF_AHB3RSTR, 0x0000_0101, 0),
    (OFF_APB1RSTR1, 0xD2FE_C13F, 0),
    (OFF_APB1RSTR2, 0x0000_0103, 0),
    (OFF_APB2RSTR, 0x0437_F801, 0),
    (OFF_AHB1ENR, 0x0000_111F, 0x0000_0100),
    (OFF_AHB2ENR, 0x050F_607F, 0),
    (OFF_AHB3ENR, 0x0000_0101, 0),
    (OFF_APB1ENR1, 0xD2FE_CD3F, 0x0000_0400),
    (OFF_APB1ENR2, 0x0000_0103, 0),
    (OFF_APB2ENR, 0x0437_F801, 0),
];

const fn is_rstr(off: u32) -> bool {
    off < OFF_AHB1ENR
}

const SYSCFG_EN: &[(u32, u32)] = &[(OFF_APB2ENR, 0)];
const SYSCFG_RST: Option<(u32, u32)> = Some((OFF_APB2RSTR, 0));

/// The blocks with an enable bit, by base address (RM0440 §2.2.2 memory map, §7.4 bit lists).
/// FLASH has an enable but no reset request: FLASHRST "can be activated only when the flash
/// memory is in power-down mode" (RM0440 §7.4.14), never the case while code runs from it.
/// SYSCFGEN/SYSCFGRST also gate COMP, VREFBUF and OPAMP (RM0440 §7.4.24 "SYSCFG + COMP +
/// VREFBUF + OPAMP clock enable"). RTC/TAMP are clocked by RTCAPBEN and reset only with the
/// backup domain; WWDG has an enable but no reset bit.
#[rustfmt::skip]
const GATES: &[Gate] = &[
    Gate { base: 0x4002_0000, en: &[(OFF_AHB1ENR, 0)], rst: Some((OFF_AHB1RSTR, 0)) }, // DMA1
    Gate { base: 0x4002_0400, en: &[(OFF_AHB1ENR, 1)], rst: Some((OFF_AHB1RSTR, 1)) }, // DMA2
    Gate { base: 0x4002_0800, en: &[(OFF_AHB1ENR, 2)], rst: Some((OFF_AHB1RSTR, 2)) }, // DMAMUX1
    Gate { base: 0x4002_0C00, en: &[(OFF_AHB1ENR, 3)], rst: Some((OFF_AHB1RSTR, 3)) }, // CORDIC
    Gate { base: 0x4002_1400, en: &[(OFF_AHB1ENR, 4)], rst: Some((OFF_AHB1RSTR, 4)) }, // FMAC
    Gate { base: 0x4002_2000, en: &[(OFF_AHB1ENR, 8)], rst: None }, // FLASH
    Gate { base: 0x4002_3000, en: &[(OFF_AHB1ENR, 12)], rst: Some((OFF_AHB1RSTR, 12)) }, // CRC
    Gate { base: 0x4800_0000, en: &[(OFF_AHB2ENR, 0)], rst: Some((OFF_AHB2RSTR, 0)) },
    Gate { base: 0x4800_0400, en: &[(OFF_AHB2ENR, 1)], rst: Some((OFF_AHB2RSTR, 1)) },
    Gate { base: 0x4800_0800, en: &[(OFF_AHB2ENR, 2)], rst: Some((OFF_AHB2RSTR, 2)) },
    Gate { base: 0x4800_0C00, en: &[(OFF_AHB2ENR, 3)], rst: Some((OFF_AHB2RSTR, 3)) },
    Gate { base: 0x4800_1000, en: &[(OFF_AHB2ENR, 4)], rst: Some((OFF_AHB2RSTR, 4)) },
    Gate { base: 0x4800_1400, en: &[(OFF_AHB2ENR, 5)], rst: Some((OFF_AHB2RSTR, 5)) },
    Gate { base: 0x4800_1800, en: &[(OFF_AHB2ENR, 6)], rst: Some((OFF_AHB2RSTR, 6)) },
    Gate { base: 0x5000_0000, en: &[(OFF_AHB2ENR, 13)], rst: Some((OFF_AHB2RSTR, 13)) }, // ADC1
    Gate { base: 0x5000_0100, en: &[(OFF_AHB2ENR, 13)], rst: Some((OFF_AHB2RSTR, 13)) }, // ADC2
    Gate { base: 0x5000_0300, en: &[(OFF_AHB2ENR, 13)], rst: Some((OFF_AHB2RSTR, 13)) }, // ADC12 common
    Gate { base: 0x5000_0400, en: &[(OFF_AHB2ENR, 14)], rst: Some((OFF_AHB2RSTR, 14)) }, // ADC3
    Gate { base: 0x5000_0500, en: &[(OFF_AHB2ENR, 14)], rst: Some((OFF_AHB2RSTR, 14)) }, // ADC4
    Gate { base: 0x5000_0600, en: &[(OFF_AHB2ENR, 14)], rst: Some((OFF_AHB2RSTR, 14)) }, // ADC5
    Gate { base: 0x5000_0700, en: &[(OFF_AHB2ENR, 14)], rst: Some((OFF_AHB2RSTR, 14)) }, // ADC345 common
    Gate { base: 0x5000_0800, en: &[(OFF_AHB2ENR, 16)], rst: Some((OFF_AHB2RSTR, 16)) }, // DAC1
    Gate { base: 0x5000_0C00, en: &[(OFF_AHB2ENR, 17)], rst: Some((OFF_AHB2RSTR, 17)) }, // DAC2
    Gate { base: 0x5000_1000, en: &[(OFF_AHB2ENR, 18)], rst: Some((OFF_AHB2RSTR, 18)) }, // DAC3
    Gate { base: 0x5000_1400, en: &[(OFF_AHB2ENR, 19)], rst: Some((OFF_AHB2RSTR, 19)) }, // DAC4
    Gate { base: 0x5006_0800, en: &[(OFF_AHB2ENR, 26)], rst: Some((OFF_AHB2RSTR, 26)) }, // RNG
    Gate { base: 0x4000_0000, en: &[(OFF_APB1ENR1, 0)], rst: Some((OFF_APB1RSTR1, 0)) }, // TIM2
    Gate { base: 0x4000_0400, en: &[(OFF_APB1ENR1, 1)], rst: Some((OFF_APB1RSTR1, 1)) }, // TIM3
    Gate { base: 0x4000_0800, en: &[(OFF_APB1ENR1, 2)], rst: Some((OFF_APB1RSTR1, 2)) }, // TIM4
    Gate { base: 0x4000_0C00, en: &[(OFF_APB1ENR1, 3)], rst: Some((OFF_APB1RSTR1, 3)) }, // TIM5
    Gate { base: 0x4000_1000, en: &[(OFF_APB1ENR1, 4)], rst: Some((OFF_APB1RSTR1, 4)) }, // TIM6
    Gate { base: 0x4000_1400, en: &[(OFF_APB1ENR1, 5)], rst: Some((OFF_APB1RSTR1, 5)) }, // TIM7
    Gate { base: 0x4000_2000, en: &[(OFF_APB1ENR1, 8)], rst: Some((OFF_APB1RSTR1, 8)) }, // CRS
    Gate { base: 0x4000_2400, en: &[(OFF_APB1ENR1, 10)], rst: None }, // TAMP
    Gate { base: 0x4000_2800, en: &[(OFF_APB1ENR1, 10)], rst: None }, // RTC
    Gate { base: 0x4000_2C00, en: &[(OFF_APB1ENR1, 11)], rst: None }, // WWDG
    Gate { base: 0x4000_3800, en: &[(OFF_APB1ENR1, 14)], rst: Some((OFF_APB1RSTR1, 14)) }, // SPI2
    Gate { base: 0x4000_3C00, en: &[(OFF_APB1ENR1, 15)], rst: Some((OFF_APB1RSTR1, 15)) }, // SPI3
    Gate { base: 0x4000_4400, en: &[(OFF_APB1ENR1, 17)], rst: Some((OFF_APB1RSTR1, 17)) }, // USART2
    Gate { base: 0x4000_4800, en: &[(OFF_APB1ENR1, 18)], rst: Some((OFF_APB1RSTR1, 18)) }, // USART3
    Gate { base: 0x4000_4C00, en: &[(OFF_APB1ENR1, 19)], rst: Some((OFF_APB1RSTR1, 19)) }, // UART4
    Gate { base: 0x4000_5000, en: &[(OFF_APB1ENR1, 20)], rst: Some((OFF_APB1RSTR1, 20)) }, // UART5
    Gate { base: 0x4000_5400, en: &[(OFF_APB1ENR1, 21)], rst: Some((OFF_APB1RSTR1, 21)) }, // I2C1
    Gate { base: 0x4000_5800, en: &[(OFF_APB1ENR1, 22)], rst: Some((OFF_APB1RSTR1, 22)) }, // I2C2
    Gate { base: 0x4000_5C00, en: &[(OFF_APB1ENR1, 23)], rst: Some((OFF_APB1RSTR1, 23)) }, // USB
    Gate { base: 0x4000_7000, en: &[(OFF_APB1ENR1, 28)], rst: Some((OFF_APB1RSTR1, 28)) }, // PWR
    Gate { base: 0x4000_7800, en: &[(OFF_APB1ENR1, 30)], rst: Some((OFF_APB1RSTR1, 30)) }, // I2C3
    Gate { base: 0x4000_7C00, en: &[(OFF_APB1ENR1, 31)], rst: Some((OFF_APB1RSTR1, 31)) }, // LPTIM1
    Gate { base: 0x4000_8000, en: &[(OFF_APB1ENR2, 0)], rst: Some((OFF_APB1RSTR2, 0)) }, // LPUART1
    Gate { base: 0x4000_8400, en: &[(OFF_APB1ENR2, 1)], rst: Some((OFF_APB1RSTR2, 1)) }, // I2C4
    Gate { base: 0x4000_A000, en: &[(OFF_APB1ENR2, 8)], rst: Some((OFF_APB1RSTR2, 8)) }, // UCPD1
    Gate { base: 0x4001_0000, en: SYSCFG_EN, rst: SYSCFG_RST }, // SYSCFG
    Gate { base: 0x4001_0030, en: SYSCFG_EN, rst: SYSCFG_RST }, // VREFBUF
    Gate { base: 0x4001_0200, en: SYSCFG_EN, rst: SYSCFG_RST }, // COMP1
    Gate { base: 0x4001_0300, en: SYSCFG_EN, rst: SYSCFG_RST }, // OPAMP1
    Gate { base: 0x4001_2C00, en: &[(OFF_APB2ENR, 11)], rst: Some((OFF_APB2RSTR, 11)) }, // TIM1
    Gate { base: 0x4001_3000, en: &[(OFF_APB2ENR, 12)], rst: Some((OFF_APB2RSTR, 12)) }, // SPI1
    Gate { base: 0x4001_3400, en: &[(OFF_APB2ENR, 13)], rst: Some((OFF_APB2RSTR, 13)) }, // TIM8
    Gate { base: 0x4001_3800, en: &[(OFF_APB2ENR, 14)], rst: Some((OFF_APB2RSTR, 14)) }, // USART1
    Gate { base: 0x4001_4000, en: &[(OFF_APB2ENR, 16)], rst: Some((OFF_APB2RSTR, 16)) }, // TIM15
    Gate { base: 0x4001_4400, en: &[(OFF_APB2ENR, 17)], rst: Some((OFF_APB2RSTR, 17)) }, // TIM16
    Gate { base: 0x4001_4800, en: &[(OFF_APB2ENR, 18)], rst: Some((OFF_APB2RSTR, 18)) }, // TIM17
    Gate { base: 0x4001_5000, en: &[(OFF_APB2ENR, 20)], rst: Some((OFF_APB2RSTR, 20)) }, // TIM20
    Gate { base: 0x4001_5400, en: &[(OFF_APB2ENR, 21)], rst: Some((OFF_APB2RSTR, 21)) }, // SAI1
    Gate { base: 0x4001_6800, en: &[(OFF_APB2ENR, 26)], rst: Some((OFF_APB2RSTR, 26)) }, // HRTIM1
];

// CR bits (RM0440 §7.4.1).
const CR_HSION: u32 = 1 << 8;
const CR_HSIKERON: u32 = 1 << 9;
const CR_HSIRDY: u32 = 1 << 10;
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_HSEBYP: u32 = 1 << 18;
const CR_CSSON: u32 = 1 << 19;
const CR_PLLON: u32 = 1 << 24;
const CR_PLLRDY: u32 = 1 << 25;

// PLLCFGR bits (RM0440 §7.4.4).
const PLL_PEN: u32 = 1 << 16;
const PLL_QEN: u32 = 1 << 20;
const PLL_REN: u32 = 1 << 24;
const PLLCFGR_WRITABLE: u32 = 0xFF73_7FF3;
const PLLCFGR_RESET: u32 = 0x0000_1000;

// CSR bits (RM0440 §7.4.26).
const CSR_LSION: u32 = 1 << 0;
const CSR_LSIRDY: u32 = 1 << 1;
const CSR_RMVF: u32 = 1 << 23;
pub const CSR_OBLRSTF: u32 = 1 << 25;
pub const CSR_PINRSTF: u32 = 1 << 26;
pub const CSR_BORRSTF: u32 = 1 << 27;
pub const CSR_SFTRSTF: u32 = 1 << 28;
pub const CSR_IWDGRSTF: u32 = 1 << 29;
const CSR_FLAGS: u32 = 0xFE00_0000;
/// After power-on: PINRSTF and BORRSTF (CSR reset value 0x0C00 0000).
const CSR_POR_FLAGS: u32 = CSR_PINRSTF | CSR_BORRSTF;

// BDCR bits (RM0440 §7.4.25).
const BDCR_LSEON: u32 = 1 << 0;
const BDCR_LSECSSON: u32 = 1 << 5;
const BDCR_RTCSEL: u32 = 3 << 8;
const BDCR_BDRST: u32 = 1 << 16;
const BDCR_LSCOEN: u32 = 1 << 24;

/// SW/SWS (RM0440 §7.4.3): 00 reserved, 01 HSI16, 10 HSE, 11 PLL (R output).
const SW_HSI: u32 = 1;
const SW_HSE: u32 = 2;
const SW_PLL: u32 = 3;

/// Reset value of CR: HSION and HSIRDY (RM0440 §7.4.1 "0x0000 0500"; ST's SVD says 0x63, a
/// leftover of another family's MSI bits — the manual is followed).
const CR_RESET_HSITRIM_ICSCR: u32 = 0x40;

/// STM32G474 RCC.
#[derive(Clone, Debug)]
pub struct RccG4 {
    hse_input: HseInput,
    delays: ReadyDelays,
    hsi: Osc,
    hse: Osc,
    hsi48: Osc,
    lsi: Osc,
    pll: Pll,
    hsikeron: bool,
    hsebyp: bool,
    csson: bool,
    hsitrim: u32,
    pllcfgr: u32,
    cfgr: u32,
    sws: u32,
    bus: [u32; 12],
    ccipr: u32,
    ccipr2: u32,
    bdcr: u32,
    csr_lsion: bool,
    csr_flags: u32,
    backup_writable: bool,
    lsi_forced: bool,
    resets_out: Vec<u32>,
    last_clocks: Clocks,
    clocks_changed: bool,
    bdcr_writes_ignored: u32,
    /// When SYSCLK last changed (for the 1 µs of the HCLK step rule).
    sysclk_since: Time,
    /// HCLK steps across 80 MHz that break RM0440 §7.2.7's intermediate /2 step: (time, what).
    pub hclk_step_violations: Vec<(Time, String)>,
}

impl Default for RccG4 {
    fn default() -> Self {
        Self::new()
    }
}

impl RccG4 {
    /// Power-on state of the Nucleo board's chip (see `nucleo_g474re`).
    pub fn new() -> Self {
        Self::nucleo_g474re()
    }

    /// What the board puts on OSC_IN/OSC_OUT from now on (fault injection: `HseInput::None`
    /// for an F446 whose ST-LINK MCO is absent — solder bridges open, ST-LINK unpowered — or a
    /// dead crystal: HSERDY never sets).
    pub fn set_hse_input(&mut self, hse: HseInput) {
        self.hse_input = hse;
    }

    /// Power-on state with `hse` on the oscillator pins.
    pub fn with_hse(hse: HseInput) -> Self {
        let mut r = RccG4 {
            hse_input: hse,
            delays: ReadyDelays::default(),
            hsi: Osc::default(),
            hse: Osc::default(),
            hsi48: Osc::default(),
            lsi: Osc::default(),
            pll: Pll::default(),
            hsikeron: false,
            hsebyp: false,
            csson: false,
            hsitrim: CR_RESET_HSITRIM_ICSCR,
            pllcfgr: PLLCFGR_RESET,
            cfgr: SW_HSI,
            sws: SW_HSI,
            bus: [0; 12],
            ccipr: 0,
            ccipr2: 0,
            bdcr: 0,
            csr_lsion: false,
            csr_flags: CSR_POR_FLAGS,
            backup_writable: false,
            lsi_forced: false,
            resets_out: Vec::new(),
            last_clocks: Clocks::default(),
            clocks_changed: false,
            bdcr_writes_ignored: 0,
            sysclk_since: 0,
            hclk_step_violations: Vec::new(),
        };
        r.reset_registers(0);
        r.last_clocks = r.clocks();
        r
    }

    /// NUCLEO-G474RE: a 24 MHz crystal on OSC_IN/OSC_OUT (oscillator mode, HSEBYP = 0).
    pub fn nucleo_g474re() -> Self {
        Self::with_hse(HseInput::Crystal(24_000_000))
    }

    pub fn set_ready_delays(&mut self, delays: ReadyDelays) {
        self.delays = delays;
    }

    /// The chip is being reset by `cause`: sets its RCC_CSR reset flag and PINRSTF (an
    /// internal reset source also drives NRST low; see `reset`). The flags survive the system
    /// reset, so the board may call this before or after `reset`.
    pub fn note_reset(&mut self, cause: ResetCause) {
        self.csr_flags |= match cause {
            ResetCause::IndependentWatchdog => CSR_IWDGRSTF | CSR_PINRSTF,
            ResetCause::Software => CSR_SFTRSTF | CSR_PINRSTF,
        };
    }

    /// PWR_CR1.DBP as the PWR model has it: RCC_BDCR is write-protected without it (RM0440
    /// §6.1.4, §7.4.25). The board copies `PwrG4::dbp()` here after PWR writes and resets.
    pub fn set_backup_domain_writable(&mut self, writable: bool) {
        self.backup_writable = writable;
    }

    pub fn bdcr_writes_ignored(&self) -> u32 {
        self.bdcr_writes_ignored
    }

    /// The IWDG forces the LSI on while it runs (RM0440 §41.3.1).
    pub fn set_lsi_forced_on(&mut self, now: Time, forced: bool) {
        self.lsi_forced = forced;
        self.lsi.set(now, forced || self.csr_lsion, self.delays.lsi);
    }

    /// Blocks whose RCC reset bit was set since the last call (their models should reset).
    pub fn take_peripheral_resets(&mut self) -> Vec<u32> {
        std::mem::take(&mut self.resets_out)
    }

    /// The clock tree changed since the last call.
    pub fn take_clocks_changed(&mut self) -> bool {
        std::mem::take(&mut self.clocks_changed)
    }

    /// The block at `block_base` is held in reset by its RCC reset bit; None if it has none.
    pub fn held_in_reset(&self, block_base: u32) -> Option<bool> {
        let g = GATES.iter().find(|g| g.base == block_base)?;
        let (off, bit) = g.rst?;
        Some(self.bus_reg(off) & (1 << bit) != 0)
    }

    /// Whether the block at `block_base` has its bus clock enabled; None for blocks without an
    /// enable bit (IWDG, RCC, EXTI, DBGMCU) and blocks this model does not list.
    pub fn clock_enabled(&self, block_base: u32) -> Option<bool> {
        let g = GATES.iter().find(|g| g.base == block_base)?;
        Some(
            g.en.iter()
                .any(|&(off, bit)| self.bus_reg(off) & (1 << bit) != 0),
        )
    }

    /// RCC_CSR reset flags (bits 31:25).
    pub fn reset_flags(&self) -> u32 {
        self.csr_flags
    }

    pub fn pll_on(&self) -> bool {
        self.pll.on()
    }

    /// CCIPR.LPUART1SEL (bits 11:10): 0 PCLK1, 1 SYSCLK, 2 HSI16, 3 LSE (RM0440 §7.4.26).
    pub fn lpuart1sel(&self) -> u32 {
        (self.ccipr >> 10) & 3
    }

    /// CCIPR.ADC12SEL: 0 none, 1 PLL P, 2 SYSCLK, 3 reserved.
    pub fn adc12sel(&self) -> u32 {
        (self.ccipr >> 28) & 3
    }

    fn bus_index(off: u32) -> Option<usize> {
        BUS_REGS.iter().position(|&(o, _, _)| o == off)
    }

    fn bus_reg(&self, off: u32) -> u32 {
        Self::bus_index(off).map_or(0, |i| self.bus[i])
    }

    fn pllsrc(&self) -> u32 {
        self.pllcfgr & 3
    }
    fn pllm(&self) -> u64 {
        ((self.pllcfgr >> 4) & 0xF) as u64 + 1
    }
    fn plln(&self) -> u64 {
        ((self.pllcfgr >> 8) & 0x7F) as u64
    }
    fn pllr(&self) -> u64 {
        2 * (((self.pllcfgr >> 25) & 3) as u64 + 1)
    }
    /// PLLP: PLLPDIV (2..=31) when non-zero, else PLLP bit: 0 → /7, 1 → /17 (RM0440 §7.4.4).
    fn pllp(&self) -> u64 {
        match (self.pllcfgr >> 27) & 0x1F {
            0 => {
                if self.pllcfgr & (1 << 17) != 0 {
                    17
                } else {
                    7
                }
            }
            d => d as u64,
        }
    }
    fn pll_input_hz(&self) -> u64 {
        match self.pllsrc() {
            2 => HSI_HZ,
            3 => self.hse_input.hz(),
            _ => 0,
        }
    }
    fn pll_input_ready_at(&self) -> Option<Time> {
        match self.pllsrc() {
            2 => self.hsi.ready_at,
            3 => self.hse.ready_at,
            _ => None,
        }
    }
    fn pll_ready_at(&self) -> Option<Time> {
        self.pll
            .ready_at(self.pll_input_ready_at(), self.delays.pll)
    }
    /// PLL output for divider `div` as an exact fraction of Hz.
    fn pll_out(&self, div: u64) -> (u64, u64) {
        (self.pll_input_hz() * self.plln(), self.pllm() * div)
    }

    fn source_ready_at(&self, sw: u32) -> Option<Time> {
        match sw {
            SW_HSI => self.hsi.ready_at,
            SW_HSE => self.hse.ready_at,
            // PLLCLK (the R output) must be enabled to be selected.
            SW_PLL if self.pllcfgr & PLL_REN != 0 => self.pll_ready_at(),
            _ => None,
        }
    }

    fn sw(&self) -> u32 {
        self.cfgr & 3
    }

    fn settle(&mut self, now: Time) {
        if self.sw() != self.sws && self.source_ready_at(self.sw()).is_some_and(|t| t <= now) {
            self.sws = self.sw();
        }
    }

    fn note_clocks(&mut self, now: Time, out: &mut Signals) {
        let c = self.clocks();
        if c != self.last_clocks {
            self.check_hclk_step(now, &c);
            self.last_clocks = c;
            self.clocks_changed = true;
            out.replan = true;
        }
    }

    /// RM0440 §7.2.7 (and ST's HAL_RCC_ClockConfig, "intermediate step with HCLK prescaler 2
    /// necessary before to go over 80 MHz"): HCLK may not go from ≤ 80 MHz to above it in one
    /// step; the switch is made with AHB /2, and /1 is set at least 1 µs later. A step that
    /// breaks the rule is recorded (`hclk_step_violations`), as a board would show it, if at
    /// all, by a brown-out or a corrupted fetch.
    fn check_hclk_step(&mut self, now: Time, c: &Clocks) {
        const LIMIT_HZ: u64 = 80_000_000;
        let before = self.last_clocks;
        if c.sysclk_hz != before.sysclk_hz {
            self.sysclk_since = now;
        }
        let (from, to) = (before.hclk_hz as u64, c.hclk_hz as u64);
        if from == 0 || from > LIMIT_HZ || to <= LIMIT_HZ {
            return;
        }
        // The allowed step: the same SYSCLK, AHB /2 → /1, at least 1 µs after SYSCLK settled.
        let halving_undone = c.sysclk_hz == before.sysclk_hz && to == 2 * from;
        if halving_undone && now - self.sysclk_since >= TICKS_PER_S / 1_000_000 {
            return;
        }
        self.hclk_step_violations.push((
            now,
            format!(
                "HCLK {} -> {} Hz in one step (SYSCLK {} Hz{}): RM0440 §7.2.7 asks for AHB /2 for at least 1 µs first",
                from,
                to,
                c.sysclk_hz,
                if halving_undone { ", /2 held under 1 µs" } else { "" }
            ),
        ));
    }

    fn hsi_in_use(&self) -> bool {
        self.sws == SW_HSI || (self.sws == SW_PLL && self.pllsrc() == 2)
    }
    fn hse_in_use(&self) -> bool {
        self.sws == SW_HSE || (self.sws == SW_PLL && self.pllsrc() == 3)
    }

    fn sysclk_frac(&self) -> (u64, u64) {
        match self.sws {
            SW_HSI => (HSI_HZ, 1),
            SW_HSE => (self.hse_input.hz(), 1),
            _ => self.pll_out(self.pllr()),
        }
    }

    /// The clock tree the registers configure now (RM0440 §7.2, figure 16).
    pub fn clocks(&self) -> Clocks {
        let (num, den) = self.sysclk_frac();
        let sysclk_hz = num.checked_div(den).unwrap_or(0);
        let hclk_hz = sysclk_hz / ahb_div(self.cfgr >> 4);
        let ppre1 = apb_div(self.cfgr >> 8);
        let ppre2 = apb_div(self.cfgr >> 11);
        let pclk1_hz = hclk_hz / ppre1;
        let pclk2_hz = hclk_hz / ppre2;
        // Timers: PCLK when the APB prescaler is 1, otherwise 2 x PCLK (RM0440 §7.2.15).
        let tim = |pclk: u64, div: u64| if div == 1 { pclk } else { 2 * pclk };
        let adc_kernel_hz = match self.adc12sel() {
            1 if self.pll.on() && self.pllcfgr & PLL_PEN != 0 => {
                let (n, d) = self.pll_out(self.pllp());
                n.checked_div(d).unwrap_or(0)
            }
            2 => sysclk_hz,
            _ => 0,
        };
        Clocks {
            sysclk_hz,
            hclk_hz,
            pclk1_hz,
            pclk2_hz,
            tim_apb1_hz: tim(pclk1_hz, ppre1),
            tim_apb2_hz: tim(pclk2_hz, ppre2),
            adc_kernel_hz,
            // Running once enabled (LSION or forced by the IWDG); start-up only shows in LSIRDY.
            lsi_hz: if self.lsi.on() { LSI_HZ } else { 0 },
            // CCIPR.LPUART1SEL (RM0440 §7.4.26): PCLK1, SYSCLK, HSI16; LSE is not modelled.
            lpuart1_hz: match self.lpuart1sel() {
                0 => pclk1_hz,
                1 => sysclk_hz,
                2 if self.hsi.on() => HSI_HZ,
                _ => 0,
            },
        }
    }

    /// The clock plan against the G474's limits as far as the RCC registers show them: HSE
    /// range (crystal 4–48 MHz, external clock ≤ 48 MHz), PLL (PLLM 1..=16, PLLN 8..=127, VCO
    /// input 2.66–16 MHz, VCO output 96–344 MHz, R output ≤ 170 MHz and enabled when it is
    /// SYSCLK; RM0440 §7.4.4 and the STM32G474 datasheet's PLL table — the author is not
    /// certain whether RM0440 bounds the VCO input at 8 or 16 MHz), SYSCLK/HCLK/PCLKx ≤ 170 MHz,
    /// the ADC12 kernel selection, a pending switch, and that the bus/timer clocks are whole
    /// numbers of Hz dividing the 3.6 GHz master clock. Boost (> 150 MHz) and flash latency
    /// need PWR and FLASH: `check_power_and_flash`.
    pub fn clock_plan_valid(&self) -> Result<(), String> {
        const MHZ: u64 = 1_000_000;
        let mut errs: Vec<String> = Vec::new();
        if self.sw() != self.sws {
            errs.push(format!(
                "SW = {} selected but the source is not ready (SWS = {})",
                self.sw(),
                self.sws
            ));
        }
        if self.hse_in_use() {
            match self.hse_input {
                HseInput::None => errs.push("SYSCLK uses HSE but no HSE is fitted".into()),
                HseInput::ExternalClock(hz) if hz > 48 * MHZ => {
                    errs.push(format!("HSE external clock {hz} Hz above 48 MHz"))
                }
                HseInput::Crystal(hz) if !(4 * MHZ..=48 * MHZ).contains(&hz) => {
                    errs.push(format!("HSE crystal {hz} Hz outside 4–48 MHz"))
                }
                _ => {}
            }
        }
        if self.sws == SW_PLL {
            let n = self.plln();
            if !(8..=127).contains(&n) {
                errs.push(format!("PLLN = {n}: wrong configuration (8..=127)"));
            }
            let vin = self.pll_input_hz() as f64 / self.pllm() as f64;
            if !(2.66e6..=16e6).contains(&vin) {
                errs.push(format!("VCO input {vin} Hz outside 2.66–16 MHz"));
            }
            let vco = vin * n as f64;
            if !(96e6..=344e6).contains(&vco) {
                errs.push(format!("VCO output {vco} Hz outside 96–344 MHz"));
            }
            let (num, den) = self.pll_out(self.pllr());
            if num / den > 170 * MHZ {
                errs.push(format!("PLL R output {} Hz above 170 MHz", num / den));
            }
        }
        let (num, den) = self.sysclk_frac();
        if den == 0 || num % den != 0 {
            errs.push(format!("SYSCLK {num}/{den} Hz is not a whole number of Hz"));
        }
        let c = self.clocks();
        for (name, hz) in [
            ("SYSCLK", c.sysclk_hz),
            ("PCLK1", c.pclk1_hz),
            ("PCLK2", c.pclk2_hz),
        ] {
            if hz > 170 * MHZ {
                errs.push(format!("{name} {hz} Hz above 170 MHz"));
            }
        }
        match self.adc12sel() {
            1 if !(self.pll.on() && self.pllcfgr & PLL_PEN != 0) => {
                errs.push("ADC12SEL = PLL P but the PLL or its P output is off".into())
            }
            3 => errs.push("ADC12SEL = 11 is reserved".into()),
            _ => {}
        }
        for (name, hz) in [
            ("HCLK", c.hclk_hz),
            ("PCLK1", c.pclk1_hz),
            ("PCLK2", c.pclk2_hz),
            ("APB1 timer clock", c.tim_apb1_hz),
            ("APB2 timer clock", c.tim_apb2_hz),
        ] {
            if !divides_master(hz) {
                errs.push(format!(
                    "{name} {hz} Hz does not divide the 3.6 GHz master clock"
                ));
            }
        }
        if c.adc_kernel_hz != 0 && !divides_master(c.adc_kernel_hz) {
            errs.push(format!(
                "ADC12 kernel clock {} Hz does not divide the 3.6 GHz master clock",
                c.adc_kernel_hz
            ));
        }
        if errs.is_empty() {
            Ok(())
        } else {
            Err(errs.join("; "))
        }
    }

    /// `clock_plan_valid` plus the limits that depend on PWR and FLASH: SYSCLK within the core
    /// voltage range (range 1 normal 150 MHz, boost 170 MHz, range 2 26 MHz; RM0440 §6.1.5)
    /// and the flash wait states (RM0440 §5.3.3 table 9).
    pub fn check_power_and_flash(&self, pwr: &PwrG4, flash: &FlashG4) -> Result<(), String> {
        let mut errs: Vec<String> = self.clock_plan_valid().err().into_iter().collect();
        let c = self.clocks();
        let range = pwr.range();
        if c.sysclk_hz > range.max_sysclk_hz() {
            errs.push(format!(
                "SYSCLK {} Hz above {} Hz for {range:?}",
                c.sysclk_hz,
                range.max_sysclk_hz()
            ));
        }
        if let Some(need) = g474_min_wait_states(c.hclk_hz, range) {
            if flash.wait_states() < need {
                errs.push(format!(
                    "FLASH_ACR.LATENCY = {} but HCLK {} Hz needs {need}",
                    flash.wait_states(),
                    c.hclk_hz
                ));
            }
        }
        if errs.is_empty() {
            Ok(())
        } else {
            Err(errs.join("; "))
        }
    }

    fn cr_read(&self, now: Time) -> u32 {
        let bit = |on: bool, b: u32| if on { b } else { 0 };
        bit(self.hsi.on(), CR_HSION)
            | bit(self.hsikeron, CR_HSIKERON)
            | bit(self.hsi.ready(now), CR_HSIRDY)
            | bit(self.hse.on(), CR_HSEON)
            | bit(self.hse.ready(now), CR_HSERDY)
            | bit(self.hsebyp, CR_HSEBYP)
            | bit(self.csson, CR_CSSON)
            | bit(self.pll.on(), CR_PLLON)
            | bit(self.pll_ready_at().is_some_and(|t| t <= now), CR_PLLRDY)
    }

    fn cr_write(&mut self, now: Time, value: u32, mask: u32) -> Result<(), Unmodelled> {
        let req = merge(self.cr_read(now), value, mask);
        // HSEBYP "can be written only if the HSE oscillator is disabled" (RM0440 §7.4.1).
        if !self.hse.on() {
            self.hsebyp = req & CR_HSEBYP != 0;
        }
        // HSION/HSEON/PLLON cannot be cleared while their clock drives SYSCLK.
        let hsi_on = req & CR_HSION != 0 || self.hsi_in_use();
        let hse_on = req & CR_HSEON != 0 || self.hse_in_use();
        let pll_on = req & CR_PLLON != 0 || self.sws == SW_PLL;
        if hse_on && !self.hse.on() {
            match (self.hse_input, self.hsebyp) {
                (HseInput::ExternalClock(_), true) | (HseInput::Crystal(_), false) => {}
                // Nothing on OSC_IN/OSC_OUT (fault injection): HSEON is taken, HSERDY never
                // sets (RM0390 §6.2.1 / RM0440 §7.2.1: HSERDY follows the oscillator's start).
                (HseInput::None, _) => {}
                (HseInput::ExternalClock(_), false) => {
                    return Err(Unmodelled::write(
                        OFF_CR,
                        value,
                        "RCC_CR.HSEON with HSEBYP = 0 (crystal oscillator) but the board feeds an external clock: not modelled",
                    ));
                }
                (HseInput::Crystal(_), true) => {
                    return Err(Unmodelled::write(
                        OFF_CR,
                        value,
                        "RCC_CR.HSEON with HSEBYP = 1 (external clock) but the board has a crystal: not modelled",
                    ));
                }
            }
        }
        self.hsi.set(now, hsi_on, self.delays.hsi);
        self.hse.set(now, hse_on, self.delays.hse);
        if hse_on && self.hse_input == HseInput::None {
            // On, never ready: a time no run reaches (Time::MAX would overflow the PLL's sums).
            self.hse.ready_at = Some(Time::MAX / 2);
        }
        self.pll.set(now, pll_on);
        self.hsikeron = req & CR_HSIKERON != 0;
        self.csson = req & CR_CSSON != 0;
        Ok(())
    }

    fn reset_registers(&mut self, now: Time) {
        // After reset the HSI16 runs and is the system clock (RM0440 §7.1.2).
        self.hsi = Osc {
            ready_at: Some(now),
        };
        self.hse = Osc::default();
        self.hsi48 = Osc::default();
        self.lsi = Osc::default();
        self.pll = Pll::default();
        self.hsikeron = false;
        self.hsebyp = false;
        self.csson = false;
        self.hsitrim = CR_RESET_HSITRIM_ICSCR;
        self.pllcfgr = PLLCFGR_RESET;
        self.cfgr = SW_HSI;
        self.sws = SW_HSI;
        for (i, &(_, _, reset)) in BUS_REGS.iter().enumerate() {
            self.bus[i] = reset;
        }
        self.ccipr = 0;
        self.ccipr2 = 0;
        self.csr_lsion = false;
        self.backup_writable = false;
        self.lsi_forced = false;
        self.resets_out.clear();
    }
}

impl Peripheral for RccG4 {
    fn name(&self) -> &'static str {
        "RCC"
    }

    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        self.settle(now);
        self.note_clocks(now, out);
        match offset {
            OFF_CR => Ok(self.cr_read(now)),
            // HSICAL (23:16): factory calibration, not modelled (reads 0).
            OFF_ICSCR => Ok(self.hsitrim << 24),
            OFF_CFGR => Ok(self.cfgr | (self.sws << 2)),
            OFF_PLLCFGR => Ok(self.pllcfgr),
            OFF_CCIPR => Ok(self.ccipr),
            OFF_CCIPR2 => Ok(self.ccipr2),
            OFF_BDCR => Ok(self.bdcr),
            OFF_CSR => {
                let mut v = self.csr_flags;
                if self.csr_lsion {
                    v |= CSR_LSION;
                }
                if self.lsi.ready(now) {
                    v |= CSR_LSIRDY;
                }
                Ok(v)
            }
            // HSI48ON (0), HSI48RDY (1); HSI48CAL not modelled (0).
            OFF_CRRCR => {
                Ok(if self.hsi48.on() { 1 } else { 0 } | if self.hsi48.ready(now) { 2 } else { 0 })
            }
            _ => match Self::bus_index(offset) {
                Some(i) => Ok(self.bus[i]),
                None => Err(Unmodelled::read(offset, unmodelled_reg(offset))),
            },
        }
    }

    fn write(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled> {
        self.settle(now);
        match offset {
            OFF_CR => self.cr_write(now, value, mask)?,
            OFF_ICSCR => {
                self.hsitrim = (merge(self.hsitrim << 24, value, mask & 0x7F00_0000) >> 24) & 0x7F
            }
            OFF_CFGR => {
                // SW, HPRE, PPRE1, PPRE2, MCOSEL, MCOPRE; SWS read-only.
                let new = merge(self.cfgr, value, mask & 0x7F00_3FF3);
                if new & 3 == 0 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "RCC_CFGR.SW = 00 is reserved",
                    ));
                }
                self.cfgr = new;
                self.settle(now);
            }
            OFF_PLLCFGR => {
                let mut new = merge(self.pllcfgr, value, mask & PLLCFGR_WRITABLE);
                if new & 3 == 1 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "RCC_PLLCFGR.PLLSRC = 01 is reserved",
                    ));
                }
                if (new >> 27) & 0x1F == 1 {
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "RCC_PLLCFGR.PLLPDIV = 1 is reserved",
                    ));
                }
                let enables = PLL_PEN | PLL_QEN | PLL_REN;
                if self.pll.on() && (new ^ self.pllcfgr) & !enables != 0 {
                    // RM0440 §7.4.4: M, N, P, Q, R and SRC "can be written only when the PLL
                    // is disabled"; the output enables can be written at any time.
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "RCC_PLLCFGR divider/source changed while PLLON = 1 (allowed only with the PLL disabled)",
                    ));
                }
                if self.sws == SW_PLL {
                    // "PLLCLK cannot be disabled if PLLCLK is used as system clock."
                    new |= PLL_REN;
                }
                self.pllcfgr = new;
            }
            OFF_CCIPR => self.ccipr = merge(self.ccipr, value, mask),
            OFF_CCIPR2 => self.ccipr2 = merge(self.ccipr2, value, mask & 0x0030_0003),
            OFF_BDCR => {
                if !self.backup_writable {
                    self.bdcr_writes_ignored += 1;
                } else {
                    // LSEON, LSEBYP, LSEDRV, LSECSSON, RTCSEL, RTCEN, BDRST, LSCOEN, LSCOSEL.
                    let req = merge(self.bdcr, value, mask & 0x0301_833D);
                    if req & BDCR_BDRST != 0 {
                        // BDRST resets the whole backup domain (RM0440 §7.4.25).
                        self.bdcr = BDCR_BDRST;
                    } else if req & (BDCR_LSEON | BDCR_LSECSSON | BDCR_LSCOEN) != 0 {
                        return Err(Unmodelled::write(
                            offset,
                            value,
                            "RCC_BDCR.LSEON/LSECSSON/LSCOEN: the LSE oscillator and the LSCO output are not modelled",
                        ));
                    } else {
                        let mut new = req;
                        // RTCSEL is write-once until a backup domain reset.
                        if self.bdcr & BDCR_RTCSEL != 0 {
                            new = (new & !BDCR_RTCSEL) | (self.bdcr & BDCR_RTCSEL);
                        }
                        self.bdcr = new;
                    }
                }
            }
            OFF_CSR => {
                let v = value & mask;
                if mask & CSR_LSION != 0 {
                    self.csr_lsion = v & CSR_LSION != 0;
                    self.lsi
                        .set(now, self.csr_lsion || self.lsi_forced, self.delays.lsi);
                }
                if v & CSR_RMVF != 0 {
                    self.csr_flags &= !CSR_FLAGS;
                }
            }
            OFF_CRRCR => {
                if mask & 1 != 0 {
                    self.hsi48.set(now, value & 1 != 0, self.delays.hsi48);
                }
            }
            _ => match Self::bus_index(offset) {
                Some(i) => {
                    let (_, writable, _) = BUS_REGS[i];
                    let old = self.bus[i];
                    let new = merge(old, value, mask & writable);
                    self.bus[i] = new;
                    if is_rstr(offset) {
                        rising_resets(GATES, offset, old, new, &mut self.resets_out);
                    }
                }
                None => return Err(Unmodelled::write(offset, value, unmodelled_reg(offset))),
            },
        }
        self.note_clocks(now, out);
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        self.settle(now);
        self.note_clocks(now, out);
    }

    fn next_event(&self) -> Option<Time> {
        if self.sw() != self.sws {
            self.source_ready_at(self.sw())
        } else {
            None
        }
    }

    /// System reset: as the F446 model (BDCR and reset flags kept; `note_reset` sets the
    /// cause's flag together with PINRSTF since an internal reset drives NRST low, RM0440
    /// §7.1.2, as the author reads the reset circuit figure).
    fn reset(&mut self, now: Time) {
        self.reset_registers(now);
        let c = self.clocks();
        if c != self.last_clocks {
            self.last_clocks = c;
            self.clocks_changed = true;
        }
    }

    fn as_any(&self) -> &dyn Any {
        self
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

fn unmodelled_reg(offset: u32) -> String {
    let name = match offset {
        0x18 | 0x1C | 0x20 => "RCC_CIER/CIFR/CICR (clock interrupts)",
        0x68..=0x80 => "RCC sleep-mode enable registers (xxxSMENR)",
        _ => "reserved RCC offset",
    };
    format!("{name} at offset {offset:#x} is not modelled")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::misc::{FlashG4, G4Range, PwrG4};

    struct Chip {
        now: Time,
        rcc: RccG4,
        pwr: PwrG4,
        flash: FlashG4,
        polls: u32,
    }

    #[derive(Clone, Copy)]
    enum B {
        Rcc,
        Pwr,
        Flash,
    }

    impl Chip {
        fn new() -> Self {
            Chip {
                now: 1_000,
                rcc: RccG4::nucleo_g474re(),
                pwr: PwrG4::new(),
                flash: FlashG4::new(),
                polls: 0,
            }
        }
        fn p(&mut self, b: B) -> &mut dyn Peripheral {
            match b {
                B::Rcc => &mut self.rcc,
                B::Pwr => &mut self.pwr,
                B::Flash => &mut self.flash,
            }
        }
        fn rd(&mut self, b: B, off: u32) -> u32 {
            let now = self.now;
            self.p(b).read(now, off, &mut Signals::default()).unwrap()
        }
        fn wr(&mut self, b: B, off: u32, v: u32) {
            let now = self.now;
            self.p(b)
                .write(now, off, v, 0xFFFF_FFFF, &mut Signals::default())
                .unwrap();
            self.rcc.set_backup_domain_writable(self.pwr.dbp());
        }
        fn modify(&mut self, b: B, off: u32, clear: u32, set: u32) {
            let v = (self.rd(b, off) & !clear) | set;
            self.wr(b, off, v);
        }
        fn wait(&mut self, b: B, off: u32, mask: u32, want: u32) {
            for _ in 0..100_000 {
                self.polls += 1;
                let mut s = Signals::default();
                self.rcc.advance(self.now, &mut s);
                if self.rd(b, off) & mask == want {
                    return;
                }
                self.now += 3_600;
            }
            panic!("wait on {off:#x} mask {mask:#x} never ended");
        }
        fn enable_and_reset(&mut self, rstr: u32, enr: u32, bit: u32) {
            self.modify(B::Rcc, rstr, 0, 1 << bit);
            self.modify(B::Rcc, enr, 0, 1 << bit);
            self.rd(B::Rcc, enr);
            self.modify(B::Rcc, rstr, 1 << bit, 0);
        }

        /// embassy-stm32 0.6 `init` for the firmware's G474 plan.
        fn embassy_init(&mut self) {
            self.enable_and_reset(OFF_APB2RSTR, OFF_APB2ENR, 0); // SYSCFG
            self.enable_and_reset(OFF_APB1RSTR1, OFF_APB1ENR1, 28); // PWR
            self.enable_and_reset(OFF_AHB1RSTR, OFF_AHB1ENR, 8); // FLASH
            self.modify(B::Pwr, 0x08, 0, 1 << 14); // ucpd: UCPD1_DBDIS
            for port in 0..7 {
                self.modify(B::Rcc, OFF_AHB2ENR, 0, 1 << port);
            }
            for bit in [0, 1, 2] {
                self.modify(B::Rcc, OFF_AHB1ENR, 0, 1 << bit); // DMA1, DMA2, DMAMUX1
            }
            // rcc/g4.rs
            self.modify(B::Rcc, OFF_CR, 0, CR_HSION);
            self.wait(B::Rcc, OFF_CR, CR_HSIRDY, CR_HSIRDY);
            self.modify(B::Rcc, OFF_CFGR, 3, SW_HSI);
            self.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_HSI << 2);
            self.modify(B::Rcc, OFF_CR, CR_HSEBYP, 0);
            self.modify(B::Rcc, OFF_CR, 0, CR_HSEON);
            self.wait(B::Rcc, OFF_CR, CR_HSERDY, CR_HSERDY);
            self.modify(B::Rcc, OFF_CRRCR, 0, 1);
            self.wait(B::Rcc, OFF_CRRCR, 2, 2);
            self.modify(B::Rcc, OFF_CR, CR_PLLON, 0);
            self.wait(B::Rcc, OFF_CR, CR_PLLRDY, 0);
            // PLLCFGR.write: N 75, M 6 (5), SRC HSE (3); then PLLR /2 (0) + PLLREN.
            self.wr(B::Rcc, OFF_PLLCFGR, (75 << 8) | (5 << 4) | 3);
            self.modify(B::Rcc, OFF_PLLCFGR, 3 << 25, PLL_REN);
            self.modify(B::Rcc, OFF_CR, 0, CR_PLLON);
            self.wait(B::Rcc, OFF_CR, CR_PLLRDY, CR_PLLRDY);
            // Latency for 150 MHz without boost: WS4, by read-modify-write, read back.
            self.modify(B::Flash, 0x00, 0xF, 4);
            self.wait(B::Flash, 0x00, 0xF, 4);
            // SW = PLL, all prescalers /1.
            self.modify(B::Rcc, OFF_CFGR, 0x3FF3, SW_PLL);
            self.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_PLL << 2);
            // rcc/bd.rs
            self.modify(B::Pwr, 0x00, 0, 1 << 8);
            self.wait(B::Pwr, 0x00, 1 << 8, 1 << 8);
            self.modify(B::Rcc, OFF_CSR, 0, CSR_LSION);
            self.wait(B::Rcc, OFF_CSR, CSR_LSIRDY, CSR_LSIRDY);
            let bdcr = self.rd(B::Rcc, OFF_BDCR);
            let ok = bdcr & BDCR_RTCSEL == 2 << 8 && bdcr & (1 << 15) != 0 && bdcr & 0x5 == 0;
            if !ok {
                self.modify(B::Rcc, OFF_BDCR, 0, BDCR_BDRST);
                self.modify(B::Rcc, OFF_BDCR, BDCR_BDRST, 0);
                self.modify(B::Rcc, OFF_BDCR, BDCR_RTCSEL, (1 << 15) | (2 << 8));
            }
            // ClockMux::init: RTCSEL 0, CCIPR all 0 but ADC12SEL = SYS (2), CCIPR2 0.
            self.modify(B::Rcc, OFF_BDCR, BDCR_RTCSEL, 0);
            self.modify(B::Rcc, OFF_CCIPR, 0xFFFF_FFFF, 2 << 28);
            self.modify(B::Rcc, OFF_CCIPR2, 3, 0);
            // time driver TIM4; later TIM1..3 and ADC12.
            self.enable_and_reset(OFF_APB1RSTR1, OFF_APB1ENR1, 2);
        }
    }

    /// RM0440 §7.2.7's step rule as the model checks it: embassy-stm32 0.6's G4 sequence (SW =
    /// PLL with AHB /1 in one write, from HSI16) is recorded; ST's HAL sequence (AHB /2, switch,
    /// 1 µs, AHB /1) is not; the same with /2 held for less than 1 µs is.
    #[test]
    fn hclk_may_not_step_past_80_mhz_in_one_go() {
        let mut chip = Chip::new();
        chip.embassy_init();
        assert_eq!(
            chip.rcc.hclk_step_violations.len(),
            1,
            "{:?}",
            chip.rcc.hclk_step_violations
        );
        assert!(chip.rcc.hclk_step_violations[0]
            .1
            .contains("HCLK 16000000 -> 150000000 Hz"));

        for (wait_ticks, violations) in [(3_600, 0), (3_599, 1)] {
            let mut chip = Chip::new();
            chip.embassy_init();
            // Back to HSI16, then up again as ST's HAL does.
            chip.modify(B::Rcc, OFF_CFGR, 3, SW_HSI);
            chip.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_HSI << 2);
            chip.rcc.hclk_step_violations.clear();
            chip.modify(B::Rcc, OFF_CFGR, 0xF << 4, 0b1000 << 4);
            chip.modify(B::Rcc, OFF_CFGR, 3, SW_PLL);
            chip.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_PLL << 2);
            assert_eq!(chip.rcc.clocks().hclk_hz, 75_000_000);
            chip.now += wait_ticks;
            chip.modify(B::Rcc, OFF_CFGR, 0xF << 4, 0);
            assert_eq!(chip.rcc.clocks().hclk_hz, 150_000_000);
            assert_eq!(
                chip.rcc.hclk_step_violations.len(),
                violations,
                "AHB /2 held {wait_ticks} ticks: {:?}",
                chip.rcc.hclk_step_violations
            );
        }
    }

    #[test]
    fn reset_state_runs_on_hsi16() {
        let mut r = RccG4::nucleo_g474re();
        let mut s = Signals::default();
        assert_eq!(r.read(0, OFF_CR, &mut s).unwrap(), 0x0000_0500);
        assert_eq!(r.read(0, OFF_CFGR, &mut s).unwrap(), 0x0000_0005);
        assert_eq!(r.read(0, OFF_PLLCFGR, &mut s).unwrap(), 0x0000_1000);
        assert_eq!(r.read(0, OFF_AHB1ENR, &mut s).unwrap(), 0x0000_0100);
        assert_eq!(r.read(0, OFF_APB1ENR1, &mut s).unwrap(), 0x0000_0400);
        assert_eq!(r.read(0, OFF_CSR, &mut s).unwrap(), 0x0C00_0000);
        let c = r.clocks();
        assert_eq!(
            (c.sysclk_hz, c.hclk_hz, c.pclk1_hz, c.pclk2_hz),
            (16_000_000, 16_000_000, 16_000_000, 16_000_000)
        );
        assert_eq!(c.adc_kernel_hz, 0);
        assert!(r.clock_plan_valid().is_ok());
    }

    /// The firmware's plan worked by hand: 24 MHz / 6 = 4 MHz VCO input, × 75 = 300 MHz VCO,
    /// / 2 (R) = 150 MHz SYSCLK; every prescaler /1, so HCLK, PCLK1, PCLK2 and both timer
    /// clocks are 150 MHz; ADC12SEL = SYSCLK gives a 150 MHz ADC kernel clock.
    #[test]
    fn embassy_init_gives_the_firmware_plan() {
        let mut chip = Chip::new();
        chip.embassy_init();
        let c = chip.rcc.clocks();
        assert_eq!(c.sysclk_hz, 150_000_000);
        assert_eq!(c.hclk_hz, 150_000_000);
        assert_eq!(c.pclk1_hz, 150_000_000);
        assert_eq!(c.pclk2_hz, 150_000_000);
        assert_eq!(c.tim_apb1_hz, 150_000_000);
        assert_eq!(c.tim_apb2_hz, 150_000_000);
        assert_eq!(c.adc_kernel_hz, 150_000_000);
        assert_eq!(c.lsi_hz, 32_000);
        assert_eq!(chip.rcc.clock_plan_valid(), Ok(()));
        assert_eq!(chip.pwr.range(), G4Range::Range1Normal);
        assert_eq!(
            chip.rcc.check_power_and_flash(&chip.pwr, &chip.flash),
            Ok(())
        );
        assert_eq!(chip.polls, 10);
        assert_eq!(chip.rd(B::Rcc, OFF_BDCR), (1 << 15) | (2 << 8));
        assert_eq!(chip.rd(B::Rcc, OFF_PLLCFGR), 0x0100_4B53);
        for base in [
            0x4800_0000,
            0x4800_0400,
            0x4002_0000,
            0x4002_0800,
            0x4000_0800,
            0x4000_7000,
            0x4001_0000,
            0x4002_2000,
        ] {
            assert_eq!(chip.rcc.clock_enabled(base), Some(true), "{base:#x}");
        }
        assert_eq!(chip.rcc.clock_enabled(0x5000_0000), Some(false)); // ADC1 later
        assert_eq!(chip.rcc.clock_enabled(0x4000_3000), None); // IWDG
                                                               // SYSCFG, PWR, TIM4 asked for a reset; FLASHRST does not reset the flash interface.
        assert_eq!(
            chip.rcc.take_peripheral_resets(),
            vec![
                0x4001_0000,
                0x4001_0030,
                0x4001_0200,
                0x4001_0300,
                0x4000_7000,
                0x4000_0800
            ]
        );
        // ADC12: one reset bit for ADC1, ADC2 and their common block.
        chip.enable_and_reset(OFF_AHB2RSTR, OFF_AHB2ENR, 13);
        assert_eq!(
            chip.rcc.take_peripheral_resets(),
            vec![0x5000_0000, 0x5000_0100, 0x5000_0300]
        );
        assert_eq!(chip.rcc.clock_enabled(0x5000_0300), Some(true));
    }

    #[test]
    fn adc_kernel_from_pll_p() {
        let mut chip = Chip::new();
        chip.embassy_init();
        // ADC12SEL = PLL P with P off: no clock, and the plan check says why.
        chip.modify(B::Rcc, OFF_CCIPR, 3 << 28, 1 << 28);
        assert_eq!(chip.rcc.clocks().adc_kernel_hz, 0);
        assert!(chip
            .rcc
            .clock_plan_valid()
            .unwrap_err()
            .contains("ADC12SEL"));
        // PLLPEN may be set while the PLL runs: PLLPDIV = 0 and PLLP = 0 give /7 (300/7 MHz,
        // floored; the plan check objects to it).
        chip.modify(B::Rcc, OFF_PLLCFGR, 0, PLL_PEN);
        assert_eq!(chip.rcc.clocks().adc_kernel_hz, 300_000_000 / 7);
        assert!(chip
            .rcc
            .clock_plan_valid()
            .unwrap_err()
            .contains("ADC12 kernel"));
        // Changing the P divider while the PLL runs is refused.
        let e = chip.rcc.write(
            chip.now,
            OFF_PLLCFGR,
            chip.rcc.pllcfgr | (10 << 27),
            0xFFFF_FFFF,
            &mut Signals::default(),
        );
        assert!(e.is_err());
        // Clearing PLLREN while SYSCLK is the PLL is ignored.
        chip.modify(B::Rcc, OFF_PLLCFGR, PLL_REN, 0);
        assert_ne!(chip.rd(B::Rcc, OFF_PLLCFGR) & PLL_REN, 0);
    }

    #[test]
    fn boost_needed_above_150_mhz() {
        // 24 / 6 × 85 / 2 = 170 MHz.
        let mut r = RccG4::nucleo_g474re();
        let mut s = Signals::default();
        r.write(0, OFF_CR, 0x500 | CR_HSEON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(
            0,
            OFF_PLLCFGR,
            (85 << 8) | (5 << 4) | 3 | PLL_REN,
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        r.write(0, OFF_CR, 0x500 | CR_HSEON | CR_PLLON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(0, OFF_CFGR, SW_PLL, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(r.clocks().sysclk_hz, 170_000_000);
        // Within the chip's limits, but 170 MHz has no whole period in 3.6 GHz master ticks.
        let e = r.clock_plan_valid().unwrap_err();
        assert!(e.contains("master clock") && !e.contains("above"), "{e}");
        let mut pwr = PwrG4::new();
        let mut flash = FlashG4::new();
        flash.write(0, 0, 0x0004_0604, 0xFFFF_FFFF, &mut s).unwrap();
        let e = r.check_power_and_flash(&pwr, &flash).unwrap_err();
        assert!(e.contains("Range1Normal"), "{e}");
        pwr.write(0, 0x80, 0, 0xFFFF_FFFF, &mut s).unwrap(); // R1MODE = 0: boost
        let e = r.check_power_and_flash(&pwr, &flash).unwrap_err();
        assert!(!e.contains("Range1") && !e.contains("LATENCY"), "{e}");
        // One wait state short in boost.
        flash.write(0, 0, 0x0004_0603, 0xFFFF_FFFF, &mut s).unwrap();
        assert!(r
            .check_power_and_flash(&pwr, &flash)
            .unwrap_err()
            .contains("LATENCY"));
    }

    #[test]
    fn switch_waits_for_pll_lock() {
        let us = crate::periph::TICKS_PER_S / 1_000_000;
        let mut r = RccG4::nucleo_g474re();
        r.set_ready_delays(ReadyDelays {
            hse: 2_000 * us,
            pll: 40 * us,
            hsi48: 3 * us,
            ..Default::default()
        });
        let mut s = Signals::default();
        r.write(0, OFF_CR, 0x500 | CR_HSEON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(
            0,
            OFF_PLLCFGR,
            (75 << 8) | (5 << 4) | 3 | PLL_REN,
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        r.write(0, OFF_CR, 0x500 | CR_HSEON | CR_PLLON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(0, OFF_CFGR, SW_PLL, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(r.next_event(), Some(2_040 * us));
        assert_eq!(
            r.read(2_040 * us - 1, OFF_CFGR, &mut s).unwrap() >> 2 & 3,
            SW_HSI
        );
        assert_eq!(
            r.read(2_040 * us, OFF_CFGR, &mut s).unwrap() >> 2 & 3,
            SW_PLL
        );
        // HSI48 ready flag after its own delay.
        r.write(10, OFF_CRRCR, 1, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(r.read(10 + 3 * us - 1, OFF_CRRCR, &mut s).unwrap(), 1);
        assert_eq!(r.read(10 + 3 * us, OFF_CRRCR, &mut s).unwrap(), 3);
    }

    #[test]
    fn iwdg_reset_flags_and_backup_domain() {
        let mut chip = Chip::new();
        chip.embassy_init();
        chip.modify(B::Rcc, OFF_CSR, 0, CSR_RMVF);
        assert_eq!(chip.rd(B::Rcc, OFF_CSR) & CSR_FLAGS, 0);
        chip.rcc.note_reset(ResetCause::IndependentWatchdog);
        chip.rcc.reset(chip.now);
        chip.pwr.reset(chip.now);
        let csr = chip.rd(B::Rcc, OFF_CSR);
        assert_ne!(csr & CSR_IWDGRSTF, 0);
        assert_ne!(csr & CSR_PINRSTF, 0);
        assert_eq!(csr & (CSR_BORRSTF | CSR_SFTRSTF | CSR_OBLRSTF), 0);
        assert_eq!(chip.rcc.clocks().sysclk_hz, 16_000_000);
        assert_eq!(chip.rd(B::Rcc, OFF_BDCR), (1 << 15) | (2 << 8));
        assert!(chip.rcc.take_clocks_changed());
    }

    #[test]
    fn reserved_encodings_are_reported() {
        let mut r = RccG4::nucleo_g474re();
        let mut s = Signals::default();
        assert!(r.write(0, OFF_CFGR, 0, 0xFFFF_FFFF, &mut s).is_err());
        assert!(r.write(0, OFF_PLLCFGR, 1, 0xFFFF_FFFF, &mut s).is_err());
        assert!(r
            .write(0, OFF_CR, 0x500 | CR_HSEBYP | CR_HSEON, 0xFFFF_FFFF, &mut s)
            .is_err());
        assert!(r.read(0, 0x1C, &mut s).unwrap_err().why.contains("CIER"));
    }
}
