//! Reset and clock control of the STM32F446 (RM0390 §6): oscillators with ready flags, the main
//! PLL, the system clock switch, bus prescalers, peripheral clock enables and resets, the
//! backup-domain control register, reset flags, and the clock tree computed from all of it.
//!
//! What embassy-stm32 0.6 init (lib.rs `init_hw`, rcc/f247.rs, rcc/bd.rs, the generated
//! `init_gpio`/`init_dma`/`ClockMux::init`) does with it, in order, for the firmware's plan
//! (HSE 8 MHz bypass, PLL M 4 N 180 P 2, AHB /1, APB1 /4, APB2 /2):
//! - enable-and-reset SYSCFG (APB2RSTR/APB2ENR bit 14) and PWR (APB1RSTR/APB1ENR bit 28): set
//!   the RST bit, set the EN bit, read EN back, clear the RST bit;
//! - AHB1ENR: GPIOA..H, DMA1, DMA2 (read-modify-write each);
//! - CR: HSION, wait HSIRDY; CFGR SW = HSI, wait SWS = HSI; CR HSEBYP, then HSEON, wait
//!   HSERDY; PLLON = 0, wait PLLRDY = 0; PLLCFGR written whole (M, N, P, SRC; Q and R left 0);
//!   PLLON, wait PLLRDY; PLLI2SON = 0 and PLLSAION = 0 with their RDY waits;
//! - CSR LSION, wait LSIRDY; BDCR read, BDRST 1 then 0 when it does not already select LSI,
//!   then RTCEN + RTCSEL = LSI (the default `LsConfig` runs the RTC on the LSI);
//! - CFGR SW = PLL_P with HPRE/PPRE1/PPRE2, wait SWS = PLL_P;
//! - BDCR RTCSEL = 0 (the zeroed `ClockMux`; ignored by the hardware once RTCSEL is set),
//!   DCKCFGR, DCKCFGR2 (zeroed muxes);
//! - later drivers: enable-and-reset TIM1..4 and enable ADC1 (APB2ENR bit 8, no reset).
//!
//! Ready flags: each oscillator and PLL becomes ready a configurable time after its enable
//! (`ReadyDelays`, default all 0 = immediate: the datasheet's typical start-up and lock times
//! are not modelled unless the board asks for them). A PLL locks `pll` after both PLLON and its
//! input are there. The system clock switch (SWS follows SW) happens when the selected source
//! is ready, as RM0390 §6.2.6 describes; `next_event` reports that moment and the clock change
//! sets `Signals::replan` so the board can call `clocks()`.

use super::misc::{f446_min_wait_states, FlashF4, PwrF4};
use super::{merge, Clocks, Peripheral, ResetCause, Signals, Time, Unmodelled, TICKS_PER_S};
use std::any::Any;

/// HSI RC oscillator, both chips (RM0390 §6.2.2, RM0440 §7.2.2).
pub const HSI_HZ: u64 = 16_000_000;
/// LSI RC oscillator, nominal, both chips (RM0390 §6.2.5, RM0440 §7.2.6).
pub const LSI_HZ: u64 = 32_000;

/// What the board connects to OSC_IN/OSC_OUT.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HseInput {
    /// Nothing: HSE never becomes ready.
    None,
    /// An external clock on OSC_IN (needs HSEBYP = 1), e.g. the ST-LINK MCO on the Nucleo-F446RE.
    ExternalClock(u64),
    /// A crystal between OSC_IN and OSC_OUT (needs HSEBYP = 0), e.g. the Nucleo-G474RE's 24 MHz.
    Crystal(u64),
}

impl HseInput {
    pub fn hz(self) -> u64 {
        match self {
            HseInput::None => 0,
            HseInput::ExternalClock(hz) | HseInput::Crystal(hz) => hz,
        }
    }
}

/// Time from enable to ready flag, in master ticks. Default: everything immediate.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadyDelays {
    pub hsi: Time,
    pub hse: Time,
    /// PLL lock time, counted from when both PLLON and the PLL input are there.
    pub pll: Time,
    pub lsi: Time,
    /// G4 only.
    pub hsi48: Time,
}

/// An oscillator: Some(ready time) while enabled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Osc {
    pub(crate) ready_at: Option<Time>,
}

impl Osc {
    pub(crate) fn on(&self) -> bool {
        self.ready_at.is_some()
    }
    pub(crate) fn ready(&self, now: Time) -> bool {
        self.ready_at.is_some_and(|t| t <= now)
    }
    /// Enable or disable at `now`; enabling an enabled oscillator changes nothing.
    pub(crate) fn set(&mut self, now: Time, on: bool, delay: Time) {
        match (on, self.ready_at) {
            (true, None) => self.ready_at = Some(now + delay),
            (false, _) => self.ready_at = None,
            _ => {}
        }
    }
}

/// A PLL: on since when; it locks `delay` after both it and its input are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Pll {
    pub(crate) on_since: Option<Time>,
}

impl Pll {
    pub(crate) fn on(&self) -> bool {
        self.on_since.is_some()
    }
    /// Lock time given the input oscillator's ready time (None if the input is off).
    pub(crate) fn ready_at(&self, input_ready_at: Option<Time>, delay: Time) -> Option<Time> {
        Some(self.on_since?.max(input_ready_at?) + delay)
    }
    pub(crate) fn set(&mut self, now: Time, on: bool) {
        match (on, self.on_since) {
            (true, None) => self.on_since = Some(now),
            (false, _) => self.on_since = None,
            _ => {}
        }
    }
}

/// A peripheral block the RCC gates and resets: its base address, the enable bits that clock
/// it (any one suffices), and its reset bit, as (register offset, bit).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Gate {
    pub(crate) base: u32,
    pub(crate) en: &'static [(u32, u32)],
    pub(crate) rst: Option<(u32, u32)>,
}

/// `x` divides `TICKS_PER_S` (so the board can time it exactly).
pub(crate) fn divides_master(hz: u64) -> bool {
    hz > 0 && TICKS_PER_S.is_multiple_of(hz)
}

/// Bases of the blocks whose reset bit went from 0 to 1 in register `off` (old → new).
pub(crate) fn rising_resets(gates: &[Gate], off: u32, old: u32, new: u32, out: &mut Vec<u32>) {
    let rising = new & !old;
    for g in gates {
        if let Some((o, bit)) = g.rst {
            if o == off && rising & (1 << bit) != 0 && !out.contains(&g.base) {
                out.push(g.base);
            }
        }
    }
}

// Register offsets (RM0390 §6.3.28 register map).
const OFF_CR: u32 = 0x00;
const OFF_PLLCFGR: u32 = 0x04;
const OFF_CFGR: u32 = 0x08;
const OFF_AHB1RSTR: u32 = 0x10;
const OFF_AHB2RSTR: u32 = 0x14;
const OFF_AHB3RSTR: u32 = 0x18;
const OFF_APB1RSTR: u32 = 0x20;
const OFF_APB2RSTR: u32 = 0x24;
const OFF_AHB1ENR: u32 = 0x30;
const OFF_AHB2ENR: u32 = 0x34;
const OFF_AHB3ENR: u32 = 0x38;
const OFF_APB1ENR: u32 = 0x40;
const OFF_APB2ENR: u32 = 0x44;
const OFF_BDCR: u32 = 0x70;
const OFF_CSR: u32 = 0x74;
const OFF_DCKCFGR: u32 = 0x8C;
const OFF_DCKCFGR2: u32 = 0x94;

/// Bus reset/enable registers: offset, writable bits, reset value (RM0390 §6.3.5–6.3.14; the
/// writable bits are the documented fields). AHB1ENR bit 20 is reserved but resets to 1
/// ("0x0010 0000") and is kept.
const BUS_REGS: [(u32, u32, u32); 10] = [
    (OFF_AHB1RSTR, 0x2060_10FF, 0),
    (OFF_AHB2RSTR, 0x0000_0081, 0),
    (OFF_AHB3RSTR, 0x0000_0003, 0),
    (OFF_APB1RSTR, 0x37FF_C9FF, 0),
    (OFF_APB2RSTR, 0x00C7_7933, 0),
    (OFF_AHB1ENR, 0x6064_10FF, 0x0010_0000),
    (OFF_AHB2ENR, 0x0000_0081, 0),
    (OFF_AHB3ENR, 0x0000_0003, 0),
    (OFF_APB1ENR, 0x3FFF_C9FF, 0),
    (OFF_APB2ENR, 0x00C7_7F33, 0),
];

const fn is_rstr(off: u32) -> bool {
    off < OFF_AHB1ENR
}

/// The blocks with an enable bit, by base address (RM0390 §2.2.2 memory map, §6.3 bit lists).
/// The three ADCs share one reset bit (APB2RSTR.ADCRST); the common registers at 0x4001_2300
/// are taken to be clocked when any ADC is (the manual does not single one out).
#[rustfmt::skip]
const GATES: &[Gate] = &[
    Gate { base: 0x4002_0000, en: &[(OFF_AHB1ENR, 0)], rst: Some((OFF_AHB1RSTR, 0)) },
    Gate { base: 0x4002_0400, en: &[(OFF_AHB1ENR, 1)], rst: Some((OFF_AHB1RSTR, 1)) },
    Gate { base: 0x4002_0800, en: &[(OFF_AHB1ENR, 2)], rst: Some((OFF_AHB1RSTR, 2)) },
    Gate { base: 0x4002_0C00, en: &[(OFF_AHB1ENR, 3)], rst: Some((OFF_AHB1RSTR, 3)) },
    Gate { base: 0x4002_1000, en: &[(OFF_AHB1ENR, 4)], rst: Some((OFF_AHB1RSTR, 4)) },
    Gate { base: 0x4002_1400, en: &[(OFF_AHB1ENR, 5)], rst: Some((OFF_AHB1RSTR, 5)) },
    Gate { base: 0x4002_1800, en: &[(OFF_AHB1ENR, 6)], rst: Some((OFF_AHB1RSTR, 6)) },
    Gate { base: 0x4002_1C00, en: &[(OFF_AHB1ENR, 7)], rst: Some((OFF_AHB1RSTR, 7)) },
    Gate { base: 0x4002_3000, en: &[(OFF_AHB1ENR, 12)], rst: Some((OFF_AHB1RSTR, 12)) }, // CRC
    Gate { base: 0x4002_6000, en: &[(OFF_AHB1ENR, 21)], rst: Some((OFF_AHB1RSTR, 21)) }, // DMA1
    Gate { base: 0x4002_6400, en: &[(OFF_AHB1ENR, 22)], rst: Some((OFF_AHB1RSTR, 22)) }, // DMA2
    Gate { base: 0x4000_0000, en: &[(OFF_APB1ENR, 0)], rst: Some((OFF_APB1RSTR, 0)) }, // TIM2
    Gate { base: 0x4000_0400, en: &[(OFF_APB1ENR, 1)], rst: Some((OFF_APB1RSTR, 1)) }, // TIM3
    Gate { base: 0x4000_0800, en: &[(OFF_APB1ENR, 2)], rst: Some((OFF_APB1RSTR, 2)) }, // TIM4
    Gate { base: 0x4000_0C00, en: &[(OFF_APB1ENR, 3)], rst: Some((OFF_APB1RSTR, 3)) }, // TIM5
    Gate { base: 0x4000_1000, en: &[(OFF_APB1ENR, 4)], rst: Some((OFF_APB1RSTR, 4)) }, // TIM6
    Gate { base: 0x4000_1400, en: &[(OFF_APB1ENR, 5)], rst: Some((OFF_APB1RSTR, 5)) }, // TIM7
    Gate { base: 0x4000_1800, en: &[(OFF_APB1ENR, 6)], rst: Some((OFF_APB1RSTR, 6)) }, // TIM12
    Gate { base: 0x4000_1C00, en: &[(OFF_APB1ENR, 7)], rst: Some((OFF_APB1RSTR, 7)) }, // TIM13
    Gate { base: 0x4000_2000, en: &[(OFF_APB1ENR, 8)], rst: Some((OFF_APB1RSTR, 8)) }, // TIM14
    Gate { base: 0x4000_2C00, en: &[(OFF_APB1ENR, 11)], rst: Some((OFF_APB1RSTR, 11)) }, // WWDG
    Gate { base: 0x4000_3800, en: &[(OFF_APB1ENR, 14)], rst: Some((OFF_APB1RSTR, 14)) }, // SPI2
    Gate { base: 0x4000_3C00, en: &[(OFF_APB1ENR, 15)], rst: Some((OFF_APB1RSTR, 15)) }, // SPI3
    Gate { base: 0x4000_4400, en: &[(OFF_APB1ENR, 17)], rst: Some((OFF_APB1RSTR, 17)) }, // USART2
    Gate { base: 0x4000_4800, en: &[(OFF_APB1ENR, 18)], rst: Some((OFF_APB1RSTR, 18)) }, // USART3
    Gate { base: 0x4000_4C00, en: &[(OFF_APB1ENR, 19)], rst: Some((OFF_APB1RSTR, 19)) }, // UART4
    Gate { base: 0x4000_5000, en: &[(OFF_APB1ENR, 20)], rst: Some((OFF_APB1RSTR, 20)) }, // UART5
    Gate { base: 0x4000_5400, en: &[(OFF_APB1ENR, 21)], rst: Some((OFF_APB1RSTR, 21)) }, // I2C1
    Gate { base: 0x4000_5800, en: &[(OFF_APB1ENR, 22)], rst: Some((OFF_APB1RSTR, 22)) }, // I2C2
    Gate { base: 0x4000_5C00, en: &[(OFF_APB1ENR, 23)], rst: Some((OFF_APB1RSTR, 23)) }, // I2C3
    Gate { base: 0x4000_7000, en: &[(OFF_APB1ENR, 28)], rst: Some((OFF_APB1RSTR, 28)) }, // PWR
    Gate { base: 0x4000_7400, en: &[(OFF_APB1ENR, 29)], rst: Some((OFF_APB1RSTR, 29)) }, // DAC
    Gate { base: 0x4001_0000, en: &[(OFF_APB2ENR, 0)], rst: Some((OFF_APB2RSTR, 0)) }, // TIM1
    Gate { base: 0x4001_0400, en: &[(OFF_APB2ENR, 1)], rst: Some((OFF_APB2RSTR, 1)) }, // TIM8
    Gate { base: 0x4001_1000, en: &[(OFF_APB2ENR, 4)], rst: Some((OFF_APB2RSTR, 4)) }, // USART1
    Gate { base: 0x4001_1400, en: &[(OFF_APB2ENR, 5)], rst: Some((OFF_APB2RSTR, 5)) }, // USART6
    Gate { base: 0x4001_2000, en: &[(OFF_APB2ENR, 8)], rst: Some((OFF_APB2RSTR, 8)) }, // ADC1
    Gate { base: 0x4001_2100, en: &[(OFF_APB2ENR, 9)], rst: Some((OFF_APB2RSTR, 8)) }, // ADC2
    Gate { base: 0x4001_2200, en: &[(OFF_APB2ENR, 10)], rst: Some((OFF_APB2RSTR, 8)) }, // ADC3
    Gate { base: 0x4001_2300, en: &[(OFF_APB2ENR, 8), (OFF_APB2ENR, 9), (OFF_APB2ENR, 10)], rst: Some((OFF_APB2RSTR, 8)) }, // ADC common
    Gate { base: 0x4001_3000, en: &[(OFF_APB2ENR, 12)], rst: Some((OFF_APB2RSTR, 12)) }, // SPI1
    Gate { base: 0x4001_3800, en: &[(OFF_APB2ENR, 14)], rst: Some((OFF_APB2RSTR, 14)) }, // SYSCFG
    Gate { base: 0x4001_4000, en: &[(OFF_APB2ENR, 16)], rst: Some((OFF_APB2RSTR, 16)) }, // TIM9
    Gate { base: 0x4001_4400, en: &[(OFF_APB2ENR, 17)], rst: Some((OFF_APB2RSTR, 17)) }, // TIM10
    Gate { base: 0x4001_4800, en: &[(OFF_APB2ENR, 18)], rst: Some((OFF_APB2RSTR, 18)) }, // TIM11
];

// CR bits (RM0390 §6.3.1).
const CR_HSION: u32 = 1 << 0;
const CR_HSIRDY: u32 = 1 << 1;
const CR_HSEON: u32 = 1 << 16;
const CR_HSERDY: u32 = 1 << 17;
const CR_HSEBYP: u32 = 1 << 18;
const CR_CSSON: u32 = 1 << 19;
const CR_PLLON: u32 = 1 << 24;
const CR_PLLRDY: u32 = 1 << 25;
const CR_PLLI2SON: u32 = 1 << 26;
const CR_PLLI2SRDY: u32 = 1 << 27;
const CR_PLLSAION: u32 = 1 << 28;
const CR_PLLSAIRDY: u32 = 1 << 29;

// CSR bits (RM0390 §6.3.21).
const CSR_LSION: u32 = 1 << 0;
const CSR_LSIRDY: u32 = 1 << 1;
const CSR_RMVF: u32 = 1 << 24;
pub const CSR_BORRSTF: u32 = 1 << 25;
pub const CSR_PINRSTF: u32 = 1 << 26;
pub const CSR_PORRSTF: u32 = 1 << 27;
pub const CSR_SFTRSTF: u32 = 1 << 28;
pub const CSR_IWDGRSTF: u32 = 1 << 29;
const CSR_FLAGS: u32 = 0xFE00_0000;

// BDCR bits (RM0390 §6.3.20).
const BDCR_LSEON: u32 = 1 << 0;
const BDCR_RTCSEL: u32 = 3 << 8;
const BDCR_BDRST: u32 = 1 << 16;

/// Reset values (RM0390 §6.3).
const PLLCFGR_RESET: u32 = 0x2400_3010;
const HSITRIM_RESET: u32 = 16;
/// Power-on reset flags: POR, PIN and BOR (CSR reset value 0x0E00 0000).
const CSR_POR_FLAGS: u32 = CSR_BORRSTF | CSR_PINRSTF | CSR_PORRSTF;

/// System clock switch positions (CFGR.SW/SWS, RM0390 §6.3.3): 00 HSI, 01 HSE, 10 PLL_P,
/// 11 PLL_R (the F446 can run SYSCLK from the PLL's R output).
const SW_HSI: u32 = 0;
const SW_HSE: u32 = 1;
const SW_PLLP: u32 = 2;
const SW_PLLR: u32 = 3;

/// AHB prescaler factor for HPRE (RM0390 §6.3.3; also RM0440 §7.4.3).
pub(crate) fn ahb_div(hpre: u32) -> u64 {
    match hpre & 0xF {
        0..=7 => 1,
        8 => 2,
        9 => 4,
        10 => 8,
        11 => 16,
        12 => 64,
        13 => 128,
        14 => 256,
        _ => 512,
    }
}

/// APB prescaler factor for PPREx.
pub(crate) fn apb_div(ppre: u32) -> u64 {
    match ppre & 7 {
        0..=3 => 1,
        4 => 2,
        5 => 4,
        6 => 8,
        _ => 16,
    }
}

/// STM32F446 RCC.
#[derive(Clone, Debug)]
pub struct RccF4 {
    hse_input: HseInput,
    delays: ReadyDelays,
    hsi: Osc,
    hse: Osc,
    lsi: Osc,
    pll: Pll,
    plli2s: Pll,
    pllsai: Pll,
    hsitrim: u32,
    hsebyp: bool,
    csson: bool,
    pllcfgr: u32,
    /// CFGR as written (SWS bits kept 0 here; `sws` holds them).
    cfgr: u32,
    sws: u32,
    /// AHB1RSTR .. APB2ENR in `BUS_REGS` order.
    bus: [u32; 10],
    bdcr: u32,
    csr_lsion: bool,
    csr_flags: u32,
    dckcfgr: u32,
    dckcfgr2: u32,
    backup_writable: bool,
    lsi_forced: bool,
    resets_out: Vec<u32>,
    last_clocks: Clocks,
    clocks_changed: bool,
    bdcr_writes_ignored: u32,
}

impl Default for RccF4 {
    fn default() -> Self {
        Self::new()
    }
}

impl RccF4 {
    /// Power-on state of the Nucleo board's chip (see `nucleo_f446re`).
    pub fn new() -> Self {
        Self::nucleo_f446re()
    }

    /// What the board puts on OSC_IN/OSC_OUT from now on (fault injection: `HseInput::None`
    /// for an F446 whose ST-LINK MCO is absent — solder bridges open, ST-LINK unpowered — or a
    /// dead crystal: HSERDY never sets).
    pub fn set_hse_input(&mut self, hse: HseInput) {
        self.hse_input = hse;
    }

    /// Power-on state with `hse` on the oscillator pins.
    pub fn with_hse(hse: HseInput) -> Self {
        let mut r = RccF4 {
            hse_input: hse,
            delays: ReadyDelays::default(),
            hsi: Osc::default(),
            hse: Osc::default(),
            lsi: Osc::default(),
            pll: Pll::default(),
            plli2s: Pll::default(),
            pllsai: Pll::default(),
            hsitrim: HSITRIM_RESET,
            hsebyp: false,
            csson: false,
            pllcfgr: PLLCFGR_RESET,
            cfgr: 0,
            sws: SW_HSI,
            bus: [0; 10],
            bdcr: 0,
            csr_lsion: false,
            csr_flags: CSR_POR_FLAGS,
            dckcfgr: 0,
            dckcfgr2: 0,
            backup_writable: false,
            lsi_forced: false,
            resets_out: Vec::new(),
            last_clocks: Clocks::default(),
            clocks_changed: false,
            bdcr_writes_ignored: 0,
        };
        r.reset_registers(0);
        r.last_clocks = r.clocks();
        r
    }

    /// NUCLEO-F446RE: HSE is the ST-LINK's 8 MHz MCO on OSC_IN (bypass mode required).
    pub fn nucleo_f446re() -> Self {
        Self::with_hse(HseInput::ExternalClock(8_000_000))
    }

    /// Start-up/lock times for the ready flags (default immediate).
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

    /// PWR_CR.DBP as the PWR model has it: RCC_BDCR is write-protected without it (RM0390
    /// §5.1.2, §6.3.20). The board copies `PwrF4::dbp()` here after PWR writes and resets.
    pub fn set_backup_domain_writable(&mut self, writable: bool) {
        self.backup_writable = writable;
    }

    /// BDCR writes dropped because DBP was 0.
    pub fn bdcr_writes_ignored(&self) -> u32 {
        self.bdcr_writes_ignored
    }

    /// The IWDG forces the LSI on while it runs (RM0390 §19.3.1): the board sets this when the
    /// watchdog starts (it is cleared by reset).
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
    /// enable bit (IWDG, RCC, FLASH interface, EXTI, DBGMCU) and blocks this model does not list.
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

    /// PLL enabled (for the voltage-scaling rule "scale 3 when the PLL is off").
    pub fn pll_on(&self) -> bool {
        self.pll.on()
    }

    fn bus_index(off: u32) -> Option<usize> {
        BUS_REGS.iter().position(|&(o, _, _)| o == off)
    }

    fn bus_reg(&self, off: u32) -> u32 {
        Self::bus_index(off).map_or(0, |i| self.bus[i])
    }

    fn pll_src_hse(&self) -> bool {
        self.pllcfgr & (1 << 22) != 0
    }
    fn pllm(&self) -> u64 {
        (self.pllcfgr & 0x3F) as u64
    }
    fn plln(&self) -> u64 {
        ((self.pllcfgr >> 6) & 0x1FF) as u64
    }
    fn pllp(&self) -> u64 {
        2 * (((self.pllcfgr >> 16) & 3) as u64 + 1)
    }
    fn pllq(&self) -> u64 {
        ((self.pllcfgr >> 24) & 0xF) as u64
    }
    fn pllr(&self) -> u64 {
        ((self.pllcfgr >> 28) & 7) as u64
    }
    fn pll_input_hz(&self) -> u64 {
        if self.pll_src_hse() {
            self.hse_input.hz()
        } else {
            HSI_HZ
        }
    }
    fn pll_input_osc(&self) -> &Osc {
        if self.pll_src_hse() {
            &self.hse
        } else {
            &self.hsi
        }
    }
    fn pll_ready_at(&self) -> Option<Time> {
        self.pll
            .ready_at(self.pll_input_osc().ready_at, self.delays.pll)
    }
    fn plli2s_ready_at(&self) -> Option<Time> {
        self.plli2s
            .ready_at(self.pll_input_osc().ready_at, self.delays.pll)
    }
    fn pllsai_ready_at(&self) -> Option<Time> {
        self.pllsai
            .ready_at(self.pll_input_osc().ready_at, self.delays.pll)
    }

    /// PLL output for divider `div` as an exact fraction (numerator, denominator) of Hz.
    fn pll_out(&self, div: u64) -> (u64, u64) {
        (self.pll_input_hz() * self.plln(), self.pllm() * div)
    }

    /// When the source selected by SW code `sw` is ready (None: off or not locked).
    fn source_ready_at(&self, sw: u32) -> Option<Time> {
        match sw {
            SW_HSI => self.hsi.ready_at,
            SW_HSE => self.hse.ready_at,
            _ => self.pll_ready_at(),
        }
    }

    fn sw(&self) -> u32 {
        self.cfgr & 3
    }

    /// The system clock follows SW once the selected source is ready (RM0390 §6.2.6).
    fn settle(&mut self, now: Time) {
        if self.sw() != self.sws && self.source_ready_at(self.sw()).is_some_and(|t| t <= now) {
            self.sws = self.sw();
        }
    }

    fn note_clocks(&mut self, out: &mut Signals) {
        let c = self.clocks();
        if c != self.last_clocks {
            self.last_clocks = c;
            self.clocks_changed = true;
            out.replan = true;
        }
    }

    fn sys_on_pll(&self) -> bool {
        self.sws == SW_PLLP || self.sws == SW_PLLR
    }
    /// HSI drives SYSCLK directly or through the PLL ("used directly or indirectly as the
    /// system clock", RM0390 §6.3.1).
    fn hsi_in_use(&self) -> bool {
        self.sws == SW_HSI || (self.sys_on_pll() && !self.pll_src_hse())
    }
    fn hse_in_use(&self) -> bool {
        self.sws == SW_HSE || (self.sys_on_pll() && self.pll_src_hse())
    }

    fn sysclk_frac(&self) -> (u64, u64) {
        match self.sws {
            SW_HSI => (HSI_HZ, 1),
            SW_HSE => (self.hse_input.hz(), 1),
            SW_PLLP => self.pll_out(self.pllp()),
            _ => self.pll_out(self.pllr()),
        }
    }

    /// The clock tree the registers configure now (RM0390 §6.2, figure 13).
    pub fn clocks(&self) -> Clocks {
        let (num, den) = self.sysclk_frac();
        let sysclk_hz = num.checked_div(den).unwrap_or(0);
        let hclk_hz = sysclk_hz / ahb_div(self.cfgr >> 4);
        let ppre1 = apb_div(self.cfgr >> 10);
        let ppre2 = apb_div(self.cfgr >> 13);
        let pclk1_hz = hclk_hz / ppre1;
        let pclk2_hz = hclk_hz / ppre2;
        // Timer clocks: DCKCFGR.TIMPRE = 0: PCLK if the APB prescaler is 1, else 2 x PCLK;
        // TIMPRE = 1: HCLK if the APB prescaler is 1, 2 or 4, else 4 x PCLK (RM0390 §6.3.25).
        let timpre = self.dckcfgr & (1 << 24) != 0;
        let tim = |pclk: u64, div: u64| match (timpre, div) {
            (false, 1) => pclk,
            (false, _) => 2 * pclk,
            (true, 1 | 2 | 4) => hclk_hz,
            (true, _) => 4 * pclk,
        };
        Clocks {
            sysclk_hz,
            hclk_hz,
            pclk1_hz,
            pclk2_hz,
            tim_apb1_hz: tim(pclk1_hz, ppre1),
            tim_apb2_hz: tim(pclk2_hz, ppre2),
            // The F446 ADC clocks from PCLK2 through ADC_CCR.ADCPRE.
            adc_kernel_hz: 0,
            // The LSI counts as running once enabled (LSION or forced by the IWDG); its start-up
            // delay only shows in LSIRDY.
            lsi_hz: if self.lsi.on() { LSI_HZ } else { 0 },
            lpuart1_hz: 0,
        }
    }

    /// The clock plan against RM0390's limits, as far as the RCC registers show it: the
    /// source of SYSCLK (HSE range), the PLL (PLLM 2..=63, PLLN 50..=432, VCO input 1–2 MHz,
    /// VCO output 100–432 MHz, P output ≤ 180 MHz, PLLR 2..=7 when used), SYSCLK/HCLK ≤ 180 MHz,
    /// PCLK1 ≤ 45 MHz, PCLK2 ≤ 90 MHz (RM0390 §6.2, §6.3.2, §6.3.3), a pending switch, and that
    /// every bus/timer clock is a whole number of Hz dividing the model's 3.6 GHz master clock.
    /// The voltage-dependent limits need the PWR and FLASH state: `check_power_and_flash`.
    pub fn clock_plan_valid(&self) -> Result<(), String> {
        let mut errs: Vec<String> = Vec::new();
        const MHZ: u64 = 1_000_000;
        if self.sw() != self.sws {
            errs.push(format!(
                "SW = {} selected but the source is not ready (SWS = {})",
                self.sw(),
                self.sws
            ));
        }
        let uses_hse = self.hse_in_use();
        if uses_hse {
            match self.hse_input {
                HseInput::None => errs.push("SYSCLK uses HSE but no HSE is fitted".into()),
                // Datasheet DS10693 (HSE user external clock 1–50 MHz, crystal 4–26 MHz).
                HseInput::ExternalClock(hz) if !(MHZ..=50 * MHZ).contains(&hz) => {
                    errs.push(format!("HSE external clock {hz} Hz outside 1–50 MHz"))
                }
                HseInput::Crystal(hz) if !(4 * MHZ..=26 * MHZ).contains(&hz) => {
                    errs.push(format!("HSE crystal {hz} Hz outside 4–26 MHz"))
                }
                _ => {}
            }
        }
        if self.sys_on_pll() {
            let m = self.pllm();
            let n = self.plln();
            if !(2..=63).contains(&m) {
                errs.push(format!("PLLM = {m}: wrong configuration (2..=63)"));
            }
            if !(50..=432).contains(&n) {
                errs.push(format!("PLLN = {n}: wrong configuration (50..=432)"));
            }
            if m > 0 {
                let vin = self.pll_input_hz() as f64 / m as f64;
                if !(1e6..=2e6).contains(&vin) {
                    errs.push(format!("VCO input {vin} Hz outside 1–2 MHz"));
                }
                let vco = vin * n as f64;
                if !(100e6..=432e6).contains(&vco) {
                    errs.push(format!("VCO output {vco} Hz outside 100–432 MHz"));
                }
            }
            if self.sws == SW_PLLP {
                let (num, den) = self.pll_out(self.pllp());
                if den > 0 && num / den > 180 * MHZ {
                    errs.push(format!("PLL P output {} Hz above 180 MHz", num / den));
                }
            } else if !(2..=7).contains(&self.pllr()) {
                errs.push(format!(
                    "PLLR = {}: wrong configuration (2..=7) but SYSCLK uses PLL_R",
                    self.pllr()
                ));
            }
        }
        let (num, den) = self.sysclk_frac();
        if den == 0 || num % den != 0 {
            errs.push(format!("SYSCLK {num}/{den} Hz is not a whole number of Hz"));
        }
        let c = self.clocks();
        if c.sysclk_hz > 180 * MHZ {
            errs.push(format!("SYSCLK {} Hz above 180 MHz", c.sysclk_hz));
        }
        if c.pclk1_hz > 45 * MHZ {
            errs.push(format!("PCLK1 {} Hz above 45 MHz", c.pclk1_hz));
        }
        if c.pclk2_hz > 90 * MHZ {
            errs.push(format!("PCLK2 {} Hz above 90 MHz", c.pclk2_hz));
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
        if errs.is_empty() {
            Ok(())
        } else {
            Err(errs.join("; "))
        }
    }

    /// Fields that hold values the manual calls wrong but that nothing uses now (the PLL's Q
    /// and R outputs when the PLL runs): worth knowing, not an error.
    pub fn plan_notes(&self) -> Vec<String> {
        let mut notes = Vec::new();
        if self.pll.on() {
            if self.pllq() < 2 {
                notes.push(format!(
                    "PLLQ = {} is a wrong configuration (2..=15); the Q output is unused",
                    self.pllq()
                ));
            }
            if self.pllr() < 2 && self.sws != SW_PLLR {
                notes.push(format!(
                    "PLLR = {} is a wrong configuration (2..=7); the R output is unused",
                    self.pllr()
                ));
            }
        }
        notes
    }

    /// `clock_plan_valid` plus the limits that depend on PWR and FLASH: the highest HCLK per
    /// voltage scale and over-drive (DS10693 general operating conditions: scale 1 168 MHz,
    /// 180 MHz with over-drive; scale 2 144 / 168 MHz; scale 3 120 MHz; with the PLL off the
    /// regulator is in scale 3, RM0390 §5.4.1 VOS) and the flash wait states for HCLK at
    /// 2.7–3.6 V (RM0390 §3.4.1 table 5).
    pub fn check_power_and_flash(&self, pwr: &PwrF4, flash: &FlashF4) -> Result<(), String> {
        let mut errs: Vec<String> = self.clock_plan_valid().err().into_iter().collect();
        let c = self.clocks();
        let scale = if self.pll.on() { pwr.vos_scale() } else { 3 };
        let od = pwr.overdrive_active();
        let max = match (scale, od) {
            (1, true) => 180_000_000,
            (1, false) => 168_000_000,
            (2, true) => 168_000_000,
            (2, false) => 144_000_000,
            _ => 120_000_000,
        };
        if c.hclk_hz > max {
            errs.push(format!(
                "HCLK {} Hz above {} Hz for voltage scale {scale}{}",
                c.hclk_hz,
                max,
                if od {
                    " with over-drive"
                } else {
                    " without over-drive"
                }
            ));
        }
        let need = f446_min_wait_states(c.hclk_hz);
        if flash.wait_states() < need {
            errs.push(format!(
                "FLASH_ACR.LATENCY = {} but HCLK {} Hz needs {need}",
                flash.wait_states(),
                c.hclk_hz
            ));
        }
        if errs.is_empty() {
            Ok(())
        } else {
            Err(errs.join("; "))
        }
    }

    fn cr_read(&self, now: Time) -> u32 {
        let mut v = self.hsitrim << 3; // HSICAL (15:8): factory calibration, not modelled (reads 0).
        let bit = |on: bool, b: u32| if on { b } else { 0 };
        v |= bit(self.hsi.on(), CR_HSION) | bit(self.hsi.ready(now), CR_HSIRDY);
        v |= bit(self.hse.on(), CR_HSEON) | bit(self.hse.ready(now), CR_HSERDY);
        v |= bit(self.hsebyp, CR_HSEBYP) | bit(self.csson, CR_CSSON);
        v |= bit(self.pll.on(), CR_PLLON)
            | bit(self.pll_ready_at().is_some_and(|t| t <= now), CR_PLLRDY);
        v |= bit(self.plli2s.on(), CR_PLLI2SON)
            | bit(
                self.plli2s_ready_at().is_some_and(|t| t <= now),
                CR_PLLI2SRDY,
            );
        v |= bit(self.pllsai.on(), CR_PLLSAION)
            | bit(
                self.pllsai_ready_at().is_some_and(|t| t <= now),
                CR_PLLSAIRDY,
            );
        v
    }

    fn cr_write(&mut self, now: Time, value: u32, mask: u32) -> Result<(), Unmodelled> {
        let old = self.cr_read(now);
        let req = merge(old, value, mask);
        // HSEBYP "can be written only if the HSE oscillator is disabled" (RM0390 §6.3.1).
        if !self.hse.on() {
            self.hsebyp = req & CR_HSEBYP != 0;
        }
        // HSION/HSEON/PLLON "cannot be reset if ... used directly or indirectly as the system
        // clock": such a clear is ignored.
        let hsi_on = req & CR_HSION != 0 || self.hsi_in_use();
        let hse_on = req & CR_HSEON != 0 || self.hse_in_use();
        let pll_on = req & CR_PLLON != 0 || self.sys_on_pll();
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
        self.plli2s.set(now, req & CR_PLLI2SON != 0);
        self.pllsai.set(now, req & CR_PLLSAION != 0);
        self.csson = req & CR_CSSON != 0;
        self.hsitrim = (req >> 3) & 0x1F;
        Ok(())
    }

    fn reset_registers(&mut self, now: Time) {
        // After reset the HSI runs and is the system clock (RM0390 §6.1.2).
        self.hsi = Osc {
            ready_at: Some(now),
        };
        self.hse = Osc::default();
        self.lsi = Osc::default();
        self.pll = Pll::default();
        self.plli2s = Pll::default();
        self.pllsai = Pll::default();
        self.hsitrim = HSITRIM_RESET;
        self.hsebyp = false;
        self.csson = false;
        self.pllcfgr = PLLCFGR_RESET;
        self.cfgr = 0;
        self.sws = SW_HSI;
        for (i, &(_, _, reset)) in BUS_REGS.iter().enumerate() {
            self.bus[i] = reset;
        }
        self.csr_lsion = false;
        self.dckcfgr = 0;
        self.dckcfgr2 = 0;
        // PWR_CR.DBP is reset with the PWR block.
        self.backup_writable = false;
        self.lsi_forced = false;
        self.resets_out.clear();
    }
}

impl Peripheral for RccF4 {
    fn name(&self) -> &'static str {
        "RCC"
    }

    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled> {
        self.settle(now);
        self.note_clocks(out);
        match offset {
            OFF_CR => Ok(self.cr_read(now)),
            OFF_PLLCFGR => Ok(self.pllcfgr),
            OFF_CFGR => Ok(self.cfgr | (self.sws << 2)),
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
            OFF_DCKCFGR => Ok(self.dckcfgr),
            OFF_DCKCFGR2 => Ok(self.dckcfgr2),
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
            OFF_PLLCFGR => {
                // PLLM, PLLN, PLLP, PLLSRC, PLLQ, PLLR.
                let new = merge(self.pllcfgr, value, mask & 0x7F43_7FFF);
                if new != self.pllcfgr && (self.pll.on() || self.plli2s.on() || self.pllsai.on()) {
                    // RM0390 §6.3.2: "These bits can be written only when the PLL is disabled"
                    // (PLLSRC also feeds PLLI2S and PLLSAI).
                    return Err(Unmodelled::write(
                        offset,
                        value,
                        "RCC_PLLCFGR changed while a PLL is on (allowed only with the PLL disabled)",
                    ));
                }
                self.pllcfgr = new;
            }
            OFF_CFGR => {
                // SW, HPRE, PPRE1, PPRE2, RTCPRE, MCO1, I2SSRC, MCO1PRE, MCO2PRE, MCO2; SWS is
                // read-only.
                self.cfgr = merge(self.cfgr, value, mask & 0xFFFF_FCF3);
                self.settle(now);
            }
            OFF_BDCR => {
                if !self.backup_writable {
                    // Write-protected (DBP = 0): the hardware ignores the write.
                    self.bdcr_writes_ignored += 1;
                } else {
                    // LSEON, LSEBYP, LSEMOD, RTCSEL, RTCEN, BDRST.
                    let req = merge(self.bdcr, value, mask & 0x0001_830D);
                    if req & BDCR_BDRST != 0 {
                        // BDRST resets the whole backup domain (RM0390 §6.3.20).
                        self.bdcr = BDCR_BDRST;
                    } else if req & BDCR_LSEON != 0 {
                        return Err(Unmodelled::write(
                            offset,
                            value,
                            "RCC_BDCR.LSEON: the LSE oscillator is not modelled",
                        ));
                    } else {
                        let mut new = req;
                        // RTCSEL: "Once the RTC clock source has been selected, it cannot be
                        // changed anymore unless the Backup domain is reset."
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
                    // RMVF clears the reset flags (RM0390 §6.3.21).
                    self.csr_flags &= !CSR_FLAGS;
                }
            }
            OFF_DCKCFGR => self.dckcfgr = merge(self.dckcfgr, value, mask & 0x1FF0_1F1F),
            OFF_DCKCFGR2 => self.dckcfgr2 = merge(self.dckcfgr2, value, mask & 0x3CC0_0000),
            _ => match Self::bus_index(offset) {
                Some(i) => {
                    let (_, writable, _) = BUS_REGS[i];
                    let old = self.bus[i];
                    let new = merge(old, value, mask & writable);
                    self.bus[i] = new;
                    if is_rstr(offset) {
                        rising_resets(GATES, offset, old, new, &mut self.resets_out);
                    }
                    // Enables take effect at once (the manual's two-cycle delay before the
                    // peripheral may be accessed is not modelled).
                }
                None => return Err(Unmodelled::write(offset, value, unmodelled_reg(offset))),
            },
        }
        self.note_clocks(out);
        Ok(())
    }

    fn advance(&mut self, now: Time, out: &mut Signals) {
        self.settle(now);
        self.note_clocks(out);
    }

    fn next_event(&self) -> Option<Time> {
        if self.sw() != self.sws {
            self.source_ready_at(self.sw())
        } else {
            None
        }
    }

    /// System reset: registers back to their reset values, except the backup domain (BDCR)
    /// and the reset flags, which only a power-on reset clears (RM0390 §6.3.21). The flags of
    /// the cause are set by `note_reset`: the cause's own flag and PINRSTF, because an internal
    /// reset source drives the NRST pin low (RM0390 §6.1.2, figure 11) and the pin-reset
    /// detector sees that too — the author's reading of the figure, not a sentence of the
    /// manual.
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
        0x0C => "RCC_CIR (clock interrupts)",
        0x50..=0x64 => "RCC low-power enable registers (xxxLPENR)",
        0x80 => "RCC_SSCGR (spread spectrum)",
        0x84 => "RCC_PLLI2SCFGR",
        0x88 => "RCC_PLLSAICFGR",
        0x90 => "RCC_CKGATENR",
        _ => "reserved RCC offset",
    };
    format!("{name} at offset {offset:#x} is not modelled")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::periph::misc::{FlashF4, PwrF4};

    /// The RCC, PWR and FLASH of an F446 with a clock that advances on every poll, to replay
    /// embassy's init sequence: modify = read then write; wait = poll until the bits match.
    struct Chip {
        now: Time,
        rcc: RccF4,
        pwr: PwrF4,
        flash: FlashF4,
        polls: u32,
    }

    #[derive(Clone, Copy)]
    enum B {
        Rcc,
        Pwr,
        Flash,
    }

    impl Chip {
        fn new(rcc: RccF4) -> Self {
            Chip {
                now: 1_000,
                rcc,
                pwr: PwrF4::new(),
                flash: FlashF4::new(),
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
        /// Poll until (reg & mask) == want, 1 µs of time per poll.
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

        /// embassy-stm32 0.6 `init` for the firmware's F446 plan, then the firmware's ART enable.
        fn embassy_init(&mut self) {
            self.enable_and_reset(OFF_APB2RSTR, OFF_APB2ENR, 14); // SYSCFG
            self.enable_and_reset(OFF_APB1RSTR, OFF_APB1ENR, 28); // PWR
            for port in 0..8 {
                self.modify(B::Rcc, OFF_AHB1ENR, 0, 1 << port);
            }
            self.modify(B::Rcc, OFF_AHB1ENR, 0, 1 << 21);
            self.modify(B::Rcc, OFF_AHB1ENR, 0, 1 << 22);
            // rcc/f247.rs
            self.modify(B::Pwr, 0x00, 3 << 14, 3 << 14);
            self.modify(B::Pwr, 0x00, 0, 1 << 16);
            self.wait(B::Pwr, 0x04, 1 << 16, 1 << 16);
            self.modify(B::Pwr, 0x00, 0, 1 << 17);
            self.wait(B::Pwr, 0x04, 1 << 17, 1 << 17);
            self.modify(B::Rcc, OFF_CR, 0, CR_HSION);
            self.wait(B::Rcc, OFF_CR, CR_HSIRDY, CR_HSIRDY);
            self.modify(B::Rcc, OFF_CFGR, 3, SW_HSI);
            self.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_HSI << 2);
            self.modify(B::Rcc, OFF_CR, 0, CR_HSEBYP);
            self.modify(B::Rcc, OFF_CR, 0, CR_HSEON);
            self.wait(B::Rcc, OFF_CR, CR_HSERDY, CR_HSERDY);
            self.modify(B::Rcc, OFF_CR, CR_PLLON, 0);
            self.wait(B::Rcc, OFF_CR, CR_PLLRDY, 0);
            // PLLCFGR.write: M 4, N 180, P /2 (0), SRC HSE; Q and R stay 0.
            self.wr(B::Rcc, OFF_PLLCFGR, 4 | (180 << 6) | (1 << 22));
            self.modify(B::Rcc, OFF_CR, 0, CR_PLLON);
            self.wait(B::Rcc, OFF_CR, CR_PLLRDY, CR_PLLRDY);
            self.modify(B::Rcc, OFF_CR, CR_PLLI2SON, 0);
            self.wait(B::Rcc, OFF_CR, CR_PLLI2SRDY, 0);
            self.modify(B::Rcc, OFF_CR, CR_PLLSAION, 0);
            self.wait(B::Rcc, OFF_CR, CR_PLLSAIRDY, 0);
            // rcc/bd.rs LsConfig::default_lsi().init()
            self.modify(B::Pwr, 0x00, 0, 1 << 8);
            self.wait(B::Pwr, 0x00, 1 << 8, 1 << 8);
            self.modify(B::Rcc, OFF_CSR, 0, CSR_LSION);
            self.wait(B::Rcc, OFF_CSR, CSR_LSIRDY, CSR_LSIRDY);
            let bdcr = self.rd(B::Rcc, OFF_BDCR);
            let ok = bdcr & BDCR_RTCSEL == 2 << 8 && bdcr & (1 << 15) != 0 && bdcr & 5 == 0;
            if !ok {
                self.modify(B::Rcc, OFF_BDCR, 0, BDCR_BDRST);
                self.modify(B::Rcc, OFF_BDCR, BDCR_BDRST, 0);
                self.modify(B::Rcc, OFF_BDCR, BDCR_RTCSEL, (1 << 15) | (2 << 8));
            }
            // Flash latency: (180 MHz - 1) / 30 MHz = 5, written whole, read back.
            self.wr(B::Flash, 0x00, 5);
            self.wait(B::Flash, 0x00, 0xF, 5);
            // SW = PLL_P, HPRE /1, PPRE1 /4 (101), PPRE2 /2 (100).
            self.modify(B::Rcc, OFF_CFGR, 0xFCF3, SW_PLLP | (5 << 10) | (4 << 13));
            self.wait(B::Rcc, OFF_CFGR, 3 << 2, SW_PLLP << 2);
            // ClockMux::init (all zero).
            self.modify(B::Rcc, OFF_BDCR, BDCR_RTCSEL, 0);
            self.modify(B::Rcc, OFF_DCKCFGR, (3 << 27) | (1 << 28), 0);
            self.modify(B::Rcc, OFF_DCKCFGR2, 0x3CC0_0000, 0);
            // time driver: TIM4.
            self.enable_and_reset(OFF_APB1RSTR, OFF_APB1ENR, 2);
            // firmware board::init: ART accelerator.
            self.modify(B::Flash, 0x00, 3 << 9, 0);
            self.modify(B::Flash, 0x00, 0, 3 << 11);
            self.modify(B::Flash, 0x00, 3 << 11, 0);
            self.modify(B::Flash, 0x00, 0, 7 << 8);
        }
    }

    #[test]
    fn reset_state_runs_on_hsi() {
        let mut r = RccF4::nucleo_f446re();
        let mut s = Signals::default();
        assert_eq!(r.read(0, OFF_CR, &mut s).unwrap(), 0x83);
        assert_eq!(r.read(0, OFF_CFGR, &mut s).unwrap(), 0);
        assert_eq!(r.read(0, OFF_PLLCFGR, &mut s).unwrap(), 0x2400_3010);
        assert_eq!(r.read(0, OFF_AHB1ENR, &mut s).unwrap(), 0x0010_0000);
        assert_eq!(r.read(0, OFF_CSR, &mut s).unwrap(), 0x0E00_0000);
        let c = r.clocks();
        assert_eq!(
            (c.sysclk_hz, c.hclk_hz, c.pclk1_hz, c.pclk2_hz),
            (16_000_000, 16_000_000, 16_000_000, 16_000_000)
        );
        assert_eq!(
            (c.tim_apb1_hz, c.tim_apb2_hz, c.lsi_hz),
            (16_000_000, 16_000_000, 0)
        );
        assert!(r.clock_plan_valid().is_ok());
    }

    /// The firmware's plan worked by hand: 8 MHz / 4 = 2 MHz VCO input, × 180 = 360 MHz VCO,
    /// / 2 = 180 MHz SYSCLK = HCLK; PCLK1 = 180 / 4 = 45 MHz, timers ×2 = 90 MHz;
    /// PCLK2 = 180 / 2 = 90 MHz, timers ×2 = 180 MHz.
    #[test]
    fn embassy_init_gives_the_firmware_plan() {
        let mut chip = Chip::new(RccF4::nucleo_f446re());
        chip.embassy_init();
        let c = chip.rcc.clocks();
        assert_eq!(c.sysclk_hz, 180_000_000);
        assert_eq!(c.hclk_hz, 180_000_000);
        assert_eq!(c.pclk1_hz, 45_000_000);
        assert_eq!(c.pclk2_hz, 90_000_000);
        assert_eq!(c.tim_apb1_hz, 90_000_000);
        assert_eq!(c.tim_apb2_hz, 180_000_000);
        assert_eq!(c.adc_kernel_hz, 0);
        assert_eq!(c.lsi_hz, 32_000);
        assert!(chip.rcc.take_clocks_changed());
        assert_eq!(chip.rcc.clock_plan_valid(), Ok(()));
        assert_eq!(
            chip.rcc.check_power_and_flash(&chip.pwr, &chip.flash),
            Ok(())
        );
        // embassy's whole-register PLLCFGR write leaves PLLQ = PLLR = 0.
        assert_eq!(chip.rcc.plan_notes().len(), 2);
        // Every wait ended on its first poll (immediate ready flags).
        assert_eq!(chip.polls, 13);
        // RTC on LSI survived the zeroed mux write.
        assert_eq!(chip.rd(B::Rcc, OFF_BDCR), (1 << 15) | (2 << 8));
        // Blocks used by the firmware are clocked; IWDG has no enable bit.
        for base in [
            0x4002_0000,
            0x4002_0400,
            0x4002_0800,
            0x4002_6400,
            0x4000_0800,
            0x4000_7000,
            0x4001_3800,
        ] {
            assert_eq!(chip.rcc.clock_enabled(base), Some(true), "{base:#x}");
        }
        assert_eq!(chip.rcc.clock_enabled(0x4001_0000), Some(false)); // TIM1 not yet
        assert_eq!(chip.rcc.clock_enabled(0x4000_3000), None);
        // Resets asked for: SYSCFG, PWR, TIM4.
        assert_eq!(
            chip.rcc.take_peripheral_resets(),
            vec![0x4001_3800, 0x4000_7000, 0x4000_0800]
        );
        assert!(chip.flash.art_enabled());
    }

    #[test]
    fn timer_clock_rules() {
        let mut r = RccF4::nucleo_f446re();
        let mut s = Signals::default();
        // HSI 16 MHz, AHB /2, APB1 /1, APB2 /8.
        r.write(0, OFF_CFGR, (8 << 4) | (6 << 13), 0xFFFF_FFFF, &mut s)
            .unwrap();
        let c = r.clocks();
        assert_eq!(
            (c.hclk_hz, c.pclk1_hz, c.pclk2_hz),
            (8_000_000, 8_000_000, 1_000_000)
        );
        assert_eq!((c.tim_apb1_hz, c.tim_apb2_hz), (8_000_000, 2_000_000));
        assert!(s.replan);
        // TIMPRE = 1: APB1 /1 → HCLK; APB2 /8 → 4 × PCLK2.
        r.write(0, OFF_DCKCFGR, 1 << 24, 0xFFFF_FFFF, &mut s)
            .unwrap();
        let c = r.clocks();
        assert_eq!((c.tim_apb1_hz, c.tim_apb2_hz), (8_000_000, 4_000_000));
        // APB2 /4 with TIMPRE: HCLK.
        r.write(0, OFF_CFGR, (8 << 4) | (5 << 13), 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert_eq!(r.clocks().tim_apb2_hz, 8_000_000);
    }

    #[test]
    fn ready_flags_and_switch_follow_lock_delays() {
        let mut r = RccF4::nucleo_f446re();
        let us = TICKS_PER_S / 1_000_000;
        r.set_ready_delays(ReadyDelays {
            hse: 100 * us,
            pll: 200 * us,
            ..Default::default()
        });
        let mut s = Signals::default();
        let t0 = 1_000;
        r.write(t0, OFF_CR, 0x83 | CR_HSEBYP, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(t0, OFF_CR, 0x83 | CR_HSEBYP | CR_HSEON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(
            t0,
            OFF_PLLCFGR,
            4 | (180 << 6) | (1 << 22) | (2 << 24) | (2 << 28),
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        r.write(
            t0,
            OFF_CR,
            0x83 | CR_HSEBYP | CR_HSEON | CR_PLLON,
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        assert_eq!(
            r.read(t0 + 100 * us - 1, OFF_CR, &mut s).unwrap() & CR_HSERDY,
            0
        );
        assert_ne!(
            r.read(t0 + 100 * us, OFF_CR, &mut s).unwrap() & CR_HSERDY,
            0
        );
        // The PLL locks 200 µs after its input is ready.
        let lock = t0 + 300 * us;
        assert_eq!(r.read(lock - 1, OFF_CR, &mut s).unwrap() & CR_PLLRDY, 0);
        // Switching to the PLL before it locks: SWS stays HSI until the lock.
        r.write(
            lock - 1,
            OFF_CFGR,
            SW_PLLP | (5 << 10) | (4 << 13),
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        assert_eq!(r.read(lock - 1, OFF_CFGR, &mut s).unwrap() >> 2 & 3, SW_HSI);
        assert_eq!(r.next_event(), Some(lock));
        assert!(r.clock_plan_valid().is_err());
        let mut s = Signals::default();
        r.advance(lock, &mut s);
        assert!(s.replan);
        assert_eq!(r.read(lock, OFF_CFGR, &mut s).unwrap() >> 2 & 3, SW_PLLP);
        assert_eq!(r.clocks().sysclk_hz, 180_000_000);
        assert_eq!(r.next_event(), None);
        assert!(r.plan_notes().is_empty());
    }

    #[test]
    fn clock_in_use_cannot_be_stopped() {
        let mut chip = Chip::new(RccF4::nucleo_f446re());
        chip.embassy_init();
        // SYSCLK runs on PLL ← HSE: clearing PLLON and HSEON is ignored; HSI may stop.
        chip.modify(B::Rcc, OFF_CR, CR_PLLON | CR_HSEON | CR_HSION, 0);
        let cr = chip.rd(B::Rcc, OFF_CR);
        assert_eq!(cr & (CR_PLLON | CR_HSEON | CR_HSION), CR_PLLON | CR_HSEON);
        // Back on HSI (turn it on first), then the PLL may stop.
        chip.modify(B::Rcc, OFF_CR, 0, CR_HSION);
        chip.modify(B::Rcc, OFF_CFGR, 3, SW_HSI);
        chip.modify(B::Rcc, OFF_CR, CR_PLLON, 0);
        assert_eq!(chip.rd(B::Rcc, OFF_CR) & CR_PLLRDY, 0);
        assert_eq!(chip.rcc.clocks().sysclk_hz, 16_000_000);
    }

    #[test]
    fn pll_config_locked_while_running() {
        let mut chip = Chip::new(RccF4::nucleo_f446re());
        chip.embassy_init();
        let e = chip.rcc.write(
            chip.now,
            OFF_PLLCFGR,
            8 | (180 << 6) | (1 << 22),
            0xFFFF_FFFF,
            &mut Signals::default(),
        );
        assert!(e.is_err());
        // Rewriting the same value is harmless.
        let v = chip.rd(B::Rcc, OFF_PLLCFGR);
        chip.wr(B::Rcc, OFF_PLLCFGR, v);
    }

    #[test]
    fn hse_mode_must_match_the_board() {
        let mut r = RccF4::nucleo_f446re();
        // Crystal mode on an external clock input.
        assert!(r
            .write(
                0,
                OFF_CR,
                0x83 | CR_HSEON,
                0xFFFF_FFFF,
                &mut Signals::default()
            )
            .is_err());
        // Nothing on OSC_IN (issue #32's absent ST-LINK MCO): HSEON is taken and HSERDY never
        // sets, a second of board time later as at once.
        let mut g = RccF4::with_hse(HseInput::None);
        g.write(
            0,
            OFF_CR,
            0x83 | CR_HSEBYP | CR_HSEON,
            0xFFFF_FFFF,
            &mut Signals::default(),
        )
        .expect("HSEON is taken without an input");
        let cr = g
            .read(TICKS_PER_S, OFF_CR, &mut Signals::default())
            .unwrap();
        assert_eq!(cr & CR_HSEON, CR_HSEON);
        assert_eq!(cr & CR_HSERDY, 0, "HSERDY set with nothing on OSC_IN");
    }

    #[test]
    fn iwdg_reset_sets_iwdgrstf_and_keeps_backup_domain() {
        let mut chip = Chip::new(RccF4::nucleo_f446re());
        chip.embassy_init();
        chip.rcc.take_peripheral_resets();
        // Clear the power-on flags first, as a firmware reading them would.
        chip.modify(B::Rcc, OFF_CSR, 0, CSR_RMVF);
        assert_eq!(chip.rd(B::Rcc, OFF_CSR) & CSR_FLAGS, 0);
        chip.rcc.note_reset(ResetCause::IndependentWatchdog);
        chip.rcc.reset(chip.now);
        chip.pwr.reset(chip.now);
        let csr = chip.rd(B::Rcc, OFF_CSR);
        assert_ne!(csr & CSR_IWDGRSTF, 0);
        assert_ne!(csr & CSR_PINRSTF, 0);
        assert_eq!(csr & (CSR_PORRSTF | CSR_SFTRSTF), 0);
        // LSI off again, clocks back to HSI, RTC selection kept.
        assert_eq!(csr & (CSR_LSION | CSR_LSIRDY), 0);
        assert_eq!(chip.rcc.clocks().sysclk_hz, 16_000_000);
        assert_eq!(chip.rd(B::Rcc, OFF_BDCR), (1 << 15) | (2 << 8));
        // A second init finds the RTC configured and does not reset the backup domain.
        chip.embassy_init();
        assert_eq!(chip.rd(B::Rcc, OFF_BDCR), (1 << 15) | (2 << 8));
        // Software reset afterwards adds SFTRSTF.
        chip.rcc.note_reset(ResetCause::Software);
        chip.rcc.reset(chip.now);
        assert_ne!(chip.rd(B::Rcc, OFF_CSR) & CSR_SFTRSTF, 0);
    }

    #[test]
    fn bdcr_needs_dbp() {
        let mut r = RccF4::nucleo_f446re();
        let mut s = Signals::default();
        r.write(0, OFF_BDCR, (1 << 15) | (2 << 8), 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert_eq!(r.read(0, OFF_BDCR, &mut s).unwrap(), 0);
        assert_eq!(r.bdcr_writes_ignored(), 1);
        r.set_backup_domain_writable(true);
        r.write(0, OFF_BDCR, (1 << 15) | (2 << 8), 0xFFFF_FFFF, &mut s)
            .unwrap();
        // RTCSEL is write-once until a backup domain reset.
        r.write(0, OFF_BDCR, (1 << 15) | (3 << 8), 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert_eq!(r.read(0, OFF_BDCR, &mut s).unwrap(), (1 << 15) | (2 << 8));
        r.write(0, OFF_BDCR, BDCR_BDRST, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(0, OFF_BDCR, 3 << 8, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(r.read(0, OFF_BDCR, &mut s).unwrap(), 3 << 8);
        assert!(r
            .write(0, OFF_BDCR, BDCR_LSEON, 0xFFFF_FFFF, &mut s)
            .is_err());
    }

    #[test]
    fn peripheral_resets_and_shared_adc_reset() {
        let mut r = RccF4::nucleo_f446re();
        let mut s = Signals::default();
        r.write(0, OFF_APB2RSTR, 1 << 8, 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert_eq!(
            r.take_peripheral_resets(),
            vec![0x4001_2000, 0x4001_2100, 0x4001_2200, 0x4001_2300]
        );
        assert_eq!(r.held_in_reset(0x4001_2000), Some(true));
        // Holding the bit set does not ask again.
        r.write(0, OFF_APB2RSTR, 1 << 8, 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert!(r.take_peripheral_resets().is_empty());
        r.write(0, OFF_APB2RSTR, 0, 0xFFFF_FFFF, &mut s).unwrap();
        assert_eq!(r.held_in_reset(0x4001_2000), Some(false));
        assert_eq!(r.held_in_reset(0x4000_3000), None);
        // ADC common is clocked by any ADC's enable.
        r.write(0, OFF_APB2ENR, 1 << 9, 0xFFFF_FFFF, &mut s)
            .unwrap();
        assert_eq!(r.clock_enabled(0x4001_2300), Some(true));
        assert_eq!(r.clock_enabled(0x4001_2000), Some(false));
    }

    #[test]
    fn plan_limits_are_checked() {
        let mut r = RccF4::nucleo_f446re();
        let mut s = Signals::default();
        // 8 MHz / 2 = 4 MHz VCO input (above 2 MHz), ×108 = 432 MHz, /2 = 216 MHz SYSCLK.
        r.write(0, OFF_CR, 0x83 | CR_HSEBYP, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(0, OFF_CR, 0x83 | CR_HSEBYP | CR_HSEON, 0xFFFF_FFFF, &mut s)
            .unwrap();
        r.write(
            0,
            OFF_PLLCFGR,
            2 | (108 << 6) | (1 << 22) | (2 << 24) | (2 << 28),
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        r.write(
            0,
            OFF_CR,
            0x83 | CR_HSEBYP | CR_HSEON | CR_PLLON,
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        r.write(
            0,
            OFF_CFGR,
            SW_PLLP | (5 << 10) | (4 << 13),
            0xFFFF_FFFF,
            &mut s,
        )
        .unwrap();
        assert_eq!(r.clocks().sysclk_hz, 216_000_000);
        let e = r.clock_plan_valid().unwrap_err();
        assert!(
            e.contains("VCO input") && e.contains("SYSCLK") && e.contains("PLL P output"),
            "{e}"
        );
        // 180 MHz without over-drive: the power check objects.
        let mut chip = Chip::new(RccF4::nucleo_f446re());
        chip.embassy_init();
        chip.modify(B::Pwr, 0x00, 3 << 16, 0);
        let e = chip
            .rcc
            .check_power_and_flash(&chip.pwr, &chip.flash)
            .unwrap_err();
        assert!(e.contains("over-drive"), "{e}");
        // Too few wait states.
        chip.modify(B::Pwr, 0x00, 0, 1 << 16);
        chip.modify(B::Pwr, 0x00, 0, 1 << 17);
        chip.modify(B::Flash, 0x00, 0xF, 4);
        let e = chip
            .rcc
            .check_power_and_flash(&chip.pwr, &chip.flash)
            .unwrap_err();
        assert!(e.contains("LATENCY"), "{e}");
    }

    #[test]
    fn unmodelled_registers_are_named() {
        let mut r = RccF4::nucleo_f446re();
        let e = r.read(0, 0x0C, &mut Signals::default()).unwrap_err();
        assert!(e.why.contains("RCC_CIR"));
        assert!(r
            .write(0, 0x84, 0, 0xFFFF_FFFF, &mut Signals::default())
            .is_err());
    }
}
