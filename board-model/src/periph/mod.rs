//! The interface every peripheral model implements, the signals that join them, and virtual time.
//!
//! A model owns one register block. The board (`crate::board`) maps it at its base address,
//! routes CPU and DMA accesses to it, advances it in time, and carries what it signals to the
//! others: timer trigger outputs to the ADC, ADC requests to the DMA, DMA data moves to memory,
//! channel output levels to the GPIO pins, interrupt lines to the NVIC, resets to the whole chip.
//! Behaviour follows the reference manuals (RM0390 for the STM32F446, RM0440 for the STM32G474);
//! each model cites the section it implements. What a model does not implement is an error
//! (`Unmodelled`), never a silent zero: a firmware that touches it must be noticed.

pub mod adc_f4;
pub mod adc_g4;
pub mod dac;
pub mod dma_f4;
pub mod dma_g4;
pub mod flash_prog;
pub mod gpio;
pub mod iwdg;
pub mod lpuart_g4;
pub mod misc;
pub mod rcc_f4;
pub mod rcc_g4;
pub mod tim;
pub mod usart_f4;

use std::any::Any;

/// Virtual time in master ticks: 3.6 GHz, the least common multiple of every clock the two boards
/// run (180, 150, 90, 45, 16, 24, 8 MHz, 32 kHz LSI), so each of their periods is a whole number
/// of ticks and a 15 MHz carrier edge lands exactly. u64 lasts 162 years.
pub type Time = u64;

/// Master ticks per second.
pub const TICKS_PER_S: u64 = 3_600_000_000;

/// Ticks of one period of a clock of `hz`. Panics if `hz` does not divide the master clock:
/// a clock plan the model cannot represent exactly must be noticed, not rounded.
pub fn ticks_per_cycle(hz: u64) -> u64 {
    assert!(
        hz > 0 && TICKS_PER_S.is_multiple_of(hz),
        "clock {hz} Hz does not divide the 3.6 GHz master clock"
    );
    TICKS_PER_S / hz
}

/// Seconds of virtual time.
pub fn seconds(t: Time) -> f64 {
    t as f64 / TICKS_PER_S as f64
}

/// Microseconds of virtual time, rounded down.
pub fn micros(t: Time) -> u64 {
    t / (TICKS_PER_S / 1_000_000)
}

/// The clock tree as the RCC model's registers configure it right now (RM0390 §6.2 / RM0440 §7.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Clocks {
    /// SYSCLK = core clock (HCLK before the AHB prescaler).
    pub sysclk_hz: u64,
    /// AHB clock (HCLK): the core and DMA.
    pub hclk_hz: u64,
    /// APB1 and APB2 peripheral clocks.
    pub pclk1_hz: u64,
    pub pclk2_hz: u64,
    /// Timer kernel clocks on APB1 and APB2: PCLKx, or 2 × PCLKx when the APB prescaler is not 1
    /// (RM0390 §6.2, fig. 13; RM0440 §7.2.15).
    pub tim_apb1_hz: u64,
    pub tim_apb2_hz: u64,
    /// ADC kernel clock where the RCC selects one (G474: ADC12SEL); 0 where the ADC clocks from
    /// PCLK2 through its own prescaler (F446, ADC_CCR.ADCPRE).
    pub adc_kernel_hz: u64,
    /// Low-speed internal RC (IWDG clock): 32 kHz on both chips.
    pub lsi_hz: u64,
    /// G474: LPUART1's kernel clock as RCC_CCIPR.LPUART1SEL selects it (RM0440 §7.4.26: 00
    /// PCLK1, 01 SYSCLK, 10 HSI16, 11 LSE); 0 when that source is off or not modelled (LSE),
    /// and on the F446, which has no LPUART.
    pub lpuart1_hz: u64,
}

/// Which bus clock a peripheral's kernel runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClockDomain {
    Ahb,
    Apb1,
    Apb2,
    /// Timer kernel clock on APB1 / APB2 (×2 when the APB prescaler is not 1).
    TimApb1,
    TimApb2,
    Lsi,
}

impl ClockDomain {
    /// The frequency of this domain in `c`.
    pub fn hz(self, c: &Clocks) -> u64 {
        match self {
            ClockDomain::Ahb => c.hclk_hz,
            ClockDomain::Apb1 => c.pclk1_hz,
            ClockDomain::Apb2 => c.pclk2_hz,
            ClockDomain::TimApb1 => c.tim_apb1_hz,
            ClockDomain::TimApb2 => c.tim_apb2_hz,
            ClockDomain::Lsi => c.lsi_hz,
        }
    }
}

/// A DMA request source, named by function (each DMA model maps it to its stream/channel or
/// DMAMUX request ID from the chip's table).
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Request {
    Adc1,
    /// USART2 receive (RXNE with DMAR).
    Usart2Rx,
    /// USART2 transmit (TXE with DMAT), a level: see [`Event::DmaLevel`].
    Usart2Tx,
    /// LPUART1 receive (RXNE/RXFNE with DMAR).
    Lpuart1Rx,
    /// LPUART1 transmit (TXE/TXFNF with DMAT), a level: see [`Event::DmaLevel`].
    Lpuart1Tx,
    /// A timer's capture/compare channel (CCxDE): a pulse at each compare match.
    TimCc {
        timer: u8,
        channel: u8,
    },
    /// DAC1 channel 1 (DMAEN1): a pulse at each selected trigger.
    Dac1Ch1,
}

/// What one peripheral tells the others. Delivered by the board to every peripheral's `on_event`;
/// each ignores what is not for it.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// A timer's TRGO pulsed (timer number, 1 = TIM1).
    Trgo { timer: u8 },
    /// A timer's TRGO changed level where it is a level (master mode "enable", MMS = 001:
    /// TRGO = CNT_EN). The rising edge also comes as a `Trgo` pulse (what edge-triggered inputs
    /// see); a slave timer in gated mode follows the level.
    TrgoLevel { timer: u8, high: bool },
    /// A peripheral raised a DMA request (F4: to the DMA stream whose CHSEL selects it; G4: to
    /// the DMAMUX, which forwards it as `DmaChannelRequest`).
    DmaRequest(Request),
    /// G4: the DMAMUX routed a request to a DMA controller's channel (controller 1 or 2,
    /// channel 1..=8).
    DmaChannelRequest { controller: u8, channel: u8 },
    /// A level-sensitive DMA request changed level (a USART's TXE while DMAT = 1): the DMA
    /// serves it while it is high, also when a stream is enabled with it already high.
    DmaLevel { request: Request, high: bool },
    /// G4: the DMAMUX forwards a level-sensitive request's level to a DMA controller's channel
    /// (also when a DMAMUX channel starts or stops selecting a request that is high).
    DmaChannelLevel {
        controller: u8,
        channel: u8,
        high: bool,
    },
}

/// A data move a DMA controller performs: read `size` bytes at `from`, write them at `to`.
/// The board carries it out at once (a read of a peripheral register has its side effects,
/// e.g. reading ADC_DR clears EOC).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Copy {
    pub from: u32,
    pub to: u32,
    /// 1, 2 or 4.
    pub size: u8,
}

/// Why the chip resets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// IWDG counter reached 0 (RM0390 §19.3; RM0440 §41.3).
    IndependentWatchdog,
    /// SCB AIRCR.SYSRESETREQ.
    Software,
}

/// A timer channel output level change (after CCxE/CCxP/MOE), for the GPIO pins to show.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChannelLevel {
    pub at: Time,
    /// Timer number (1 = TIM1).
    pub timer: u8,
    /// Channel 1..=4.
    pub channel: u8,
    pub high: bool,
}

/// Effects of a register access or of time passing, carried out by the board.
#[derive(Debug, Default)]
pub struct Signals {
    pub events: Vec<(Time, Event)>,
    pub copies: Vec<Copy>,
    pub levels: Vec<ChannelLevel>,
    pub reset: Option<ResetCause>,
    /// The schedule changed (a timer started, an interrupt was enabled): the CPU slice ends after
    /// this access so the board can re-plan.
    pub replan: bool,
}

/// An access the model does not implement (register or field), or one the hardware forbids.
/// The run stops with this sentence and the address.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Unmodelled {
    /// Offset from the block's base.
    pub offset: u32,
    /// The value written, None for a read.
    pub write: Option<u32>,
    /// What is missing, as a sentence fragment ("TIM1_SMCR slave mode 5 is not modelled").
    pub why: String,
}

impl Unmodelled {
    pub fn read(offset: u32, why: impl Into<String>) -> Self {
        Self {
            offset,
            write: None,
            why: why.into(),
        }
    }
    pub fn write(offset: u32, value: u32, why: impl Into<String>) -> Self {
        Self {
            offset,
            write: Some(value),
            why: why.into(),
        }
    }
}

/// `reg` with the bits of `mask` replaced by those of `value`: a byte or halfword store only
/// changes its lanes.
pub fn merge(reg: u32, value: u32, mask: u32) -> u32 {
    (reg & !mask) | (value & mask)
}

/// One register block.
///
/// Accesses arrive word-aligned: `offset` is a multiple of 4, and a byte or halfword store comes
/// as `value` already shifted into its lanes with `mask` covering them (`merge` applies it). A
/// sub-word read reads the whole word (the board extracts the lanes).
pub trait Peripheral: Any {
    /// Short name for messages ("TIM2", "ADC1/common", "DMA2").
    fn name(&self) -> &'static str;
    /// Register read at `offset` at time `now`.
    fn read(&mut self, now: Time, offset: u32, out: &mut Signals) -> Result<u32, Unmodelled>;
    /// Register write at `offset` at time `now`.
    fn write(
        &mut self,
        now: Time,
        offset: u32,
        value: u32,
        mask: u32,
        out: &mut Signals,
    ) -> Result<(), Unmodelled>;
    /// Run on its own up to and including `now`: counters, conversions, timeouts. Everything that
    /// happens is signalled with its own time stamp (≤ now).
    fn advance(&mut self, _now: Time, _out: &mut Signals) {}
    /// The next time it will do something on its own that others can see (an interrupt flag, a
    /// trigger, a DMA request, a recorded edge, a reset), if any. The board never lets the CPU
    /// run past it.
    fn next_event(&self) -> Option<Time> {
        None
    }
    /// An event from another peripheral, at `now`.
    fn on_event(&mut self, _now: Time, _event: Event, _out: &mut Signals) {}
    /// The clock tree changed at `now`.
    fn set_clocks(&mut self, _now: Time, _clocks: &Clocks) {}
    /// Calls `raise` with every NVIC interrupt number whose line is high now (flag and enable).
    fn irq_lines(&self, _raise: &mut dyn FnMut(u16)) {}
    /// System reset: registers back to their reset values (recorded history is kept).
    fn reset(&mut self, now: Time);
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}
