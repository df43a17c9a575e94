//! The 2D image (feature `touch-2d`, issue #36): the 4-wire overlay read on the plate schedule,
//! each frame through `saw_core::touch::frame::TouchSensor` and `saw_core::plane::Controller2d`
//! onto the same burst gate as the 1D image.
//!
//! Acquisition (`docs/touch.md`, "Firmware"): TIM3 counts one frame (`FRAME_TICKS` at its
//! kernel clock, auto-reload) and its CC1 interrupt walks the frame's events (`EVENTS`, from
//! the core's `Schedule` by build.rs): at a phase's start it writes the four plate pins (BSRR
//! then MODER: RM0390 §7.4.1/§7.4.7, RM0440 §9.4.1/§9.4.7 — the output level is in ODR before
//! the pin becomes an output) and the ADC's sequence to the phase's channel; at its trigger (its
//! settling time later) it starts the conversions by software (F446 ADC_CR2.SWSTART, RM0390
//! §13.13.3; G474 ADC_CR.ADSTART with EXTEN = 0, RM0440 §21.4.15): one regular sequence of the
//! slot's `RANKS`, all its channel, the first `DISCARD` thrown away (the hold capacitor's charge
//! sharing after the channel switch), the rest summed (`saw_boards::touch::touch_adc`: 1 + 15
//! a position phase, 1 + 4 a pressure phase); and CCR1 is loaded with the next event's tick
//! (output compare frozen mode: the match only sets CC1IF, RM0390 §17.3.8, RM0440 §29.3.9). DMA
//! takes every conversion (normal mode, re-armed at each frame's start); the frame's first
//! event hands the previous frame to the control task, which runs it on the sample path's
//! interrupt executor. A software start is late by the interrupt's latency, never early: the
//! settling is a floor. `MARGIN_NS` after each phase's conversions keeps a late phase's last
//! conversion before the next switch, and every switch checks it did: the DMA count must be the
//! earlier slots' words exactly (F446 NDTR, RM0390 §9.5.6; G474 CNDTR, RM0440 §12.6.4), or the
//! frame is dropped and counted (`MIXED`), never delivered with two plates in one sum.
//!
//! The host link and the scene store are `link2d.rs`'s: the boot scene is the 2D scene saved in
//! flash, else the one built in (`SAW_SCENE_2D`, default `scenes/2d-fig12.toml`).

use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use defmt::{info, unwrap, warn};
use embassy_futures::select::{select3, Either3};
use embassy_stm32::gpio::Output;
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::Peri;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::Channel;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker};
use saw_boards::touch::TouchPins;
use saw_core::burst::BurstTimer;
use saw_core::gate::BurstOutput;
use saw_core::plane::{apply2d, Config2d, Controller2d};
use saw_core::touch::calibration::{Affine, CalPoint};
use saw_core::touch::fault::RailBands;
use saw_core::touch::frame::{Frame, TouchSensor};
use saw_core::touch::plates::{Phase, PinRole, Terminal, SEQUENCE};
use saw_core::touch::pressure::PressureConfig;

use crate::board::{self, BOARD};
use crate::rf::{BurstGate, Carrier};
use crate::{fault, level, EXECUTOR_HIGH, SAMPLE_PATH_PRIORITY};

/// One event of the frame: `kind` 0 switches the pins and the channel to slot `slot`'s phase
/// at `tick` of TIM3; 1 starts its conversions `tick` ticks after the switch's pin writes
/// (CNT read back after them: the settling counts from the switch as it happened, whatever the
/// interrupt's latency); 2 does both (Z2: Z1's drive, no settling) at `tick`.
#[derive(Clone, Copy)]
pub struct Event {
    pub tick: u32,
    pub kind: u8,
    pub slot: u8,
}

// TICKS_PER_US, FRAME_US, FRAME_TICKS, MARGIN_NS, EVENTS, CHANNELS, RANKS, DISCARD, CAL, SCENE_2D,
// SCENE_2D_FILE: written by build.rs.
include!(concat!(env!("OUT_DIR"), "/touch2d.rs"));

const _: () = assert!(FRAME_TICKS >= 2 && FRAME_TICKS <= 65_536);
const _: () = assert!(TICKS_PER_US * 1_000_000 == BOARD.adc.trigger_timer_clk_hz);

#[cfg(feature = "nucleo-f446re")]
const PINS: TouchPins = saw_boards::touch::NUCLEO_F446RE_TOUCH;
#[cfg(all(feature = "nucleo-g474re", not(feature = "nucleo-f446re")))]
const PINS: TouchPins = saw_boards::touch::NUCLEO_G474RE_TOUCH;

/// The two ports' writes for one phase: for port B and port C, the MODER bits of the overlay's
/// pins (mask, value) and the BSRR word.
#[derive(Clone, Copy)]
struct Drive {
    b: (u32, u32, u32),
    c: (u32, u32, u32),
}

const fn terminal_pin(t: Terminal) -> (char, u8) {
    let p = match t {
        Terminal::XPlus => PINS.x_plus.pin,
        Terminal::XMinus => PINS.x_minus.pin,
        Terminal::YPlus => PINS.y_plus.pin,
        Terminal::YMinus => PINS.y_minus.pin,
    };
    (p.port, p.pin)
}

/// Output high / low: MODER 01 with ODR set / reset; converted or floating: analog (MODER 11,
/// the Schmitt trigger off; RM0390 §7.3.12, RM0440 §9.3.12).
const fn drive(phase: Phase) -> Drive {
    let mut d = Drive {
        b: (0, 0, 0),
        c: (0, 0, 0),
    };
    let ts = [
        Terminal::XPlus,
        Terminal::XMinus,
        Terminal::YPlus,
        Terminal::YMinus,
    ];
    let mut i = 0;
    while i < 4 {
        let (port, pin) = terminal_pin(ts[i]);
        let n = pin as u32;
        let (mode, bsrr) = match phase.role(ts[i]) {
            PinRole::High => (0b01, 1 << n),
            PinRole::Low => (0b01, 1 << (n + 16)),
            PinRole::Sensed | PinRole::Floating => (0b11, 0),
        };
        let w = match port {
            'B' => &mut d.b,
            'C' => &mut d.c,
            _ => panic!("touch pins: ports B and C only"),
        };
        w.0 |= 0b11 << (2 * n);
        w.1 |= mode << (2 * n);
        w.2 |= bsrr;
        i += 1;
    }
    d
}

const DRIVES: [Drive; 4] = [
    drive(SEQUENCE[0]),
    drive(SEQUENCE[1]),
    drive(SEQUENCE[2]),
    drive(SEQUENCE[3]),
];
/// Every pin analog: before the acquisition starts.
const ALL_ANALOG: Drive = {
    let mut d = DRIVES[0];
    d.b.1 = d.b.0;
    d.b.2 = 0;
    d.c.1 = d.c.0;
    d.c.2 = 0;
    d
};

/// Releases first, then drives: the pins that float in the new phase go analog on both ports,
/// then each port's driven pins take their level (BSRR) and become outputs (MODER). So no two
/// terminals of different plates are ever driven at once (but Z's Y+ and X−, through the
/// contact), which a port-by-port switch would do for a few bus cycles.
fn write_drive(d: &Drive) {
    let ports = [(pac::GPIOB, d.b), (pac::GPIOC, d.c)];
    for (port, (mask, mode, _)) in ports {
        // Analog is 11: OR in the bits of the pins whose new mode is analog.
        let analog = mask & mode & (mode >> 1) & 0x5555_5555;
        let analog = analog | analog << 1;
        if analog != 0 {
            port.moder().modify(|w| w.0 |= analog);
        }
    }
    for (port, (mask, mode, bsrr)) in ports {
        if mask == 0 {
            continue;
        }
        port.bsrr().write_value(pac::gpio::regs::Bsrr(bsrr));
        port.moder().modify(|w| w.0 = (w.0 & !mask) | mode);
    }
}

/// Frames from the TIM3 interrupt to the control task.
static FRAMES: Channel<CriticalSectionRawMutex, Frame, 4> = Channel::new();
/// The next event's index in `EVENTS`.
static NEXT: AtomicU32 = AtomicU32::new(0);
/// Events whose tick had passed when CCR1 was loaded (each delays the rest of the frame a frame).
pub static LATE: AtomicU32 = AtomicU32::new(0);
/// Frames whose DMA had not moved every code by the frame's end (not delivered).
pub static INCOMPLETE: AtomicU32 = AtomicU32::new(0);
/// Frames dropped because a phase's conversions had not all reached memory when the next phase
/// switched the pins (the DMA count at the switch disagreed with the phase's): their sums could
/// mix two phases' plates.
pub static MIXED: AtomicU32 = AtomicU32::new(0);
/// This frame has failed the DMA count check at one of its switches.
static MIXED_NOW: AtomicBool = AtomicBool::new(false);
/// Frames the control task had no room for.
pub static DROPPED: AtomicU32 = AtomicU32::new(0);
/// Frames delivered.
pub static DELIVERED: AtomicU32 = AtomicU32::new(0);
/// The first frame boundary has passed (nothing was converted before it).
static RUNNING: AtomicBool = AtomicBool::new(false);

// ---- The telemetry line's window ------------------------------------------------------------
//
// defmt-rtt holds interrupts off (its critical section) for the whole encoding of a line, which
// delays TIM3's events; the switches are absolute, so a delay longer than `MARGIN_NS` cuts a
// phase's conversions at the next switch (a mixed frame, dropped: on the G474 the 1 Hz line cut
// a Y phase to 6 of its 16 conversions). So the periodic line waits for a window: the control
// task asks for it (`LOG_WANTED`), every event but the frame's first (whose delivery wakes the
// control task for the frame's own work) signals it (`LOG_WINDOW`), and the line is encoded only
// if, read inside the critical section that then holds through the encoding, the next event is
// at least `LOG_BUDGET_TICKS` away (`log_room_ticks`).

/// The control task wants to emit the telemetry line.
static LOG_WANTED: AtomicBool = AtomicBool::new(false);
/// An event has passed while `LOG_WANTED`: a gap without events may be starting.
static LOG_WINDOW: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The longest a telemetry line held the interrupts off (its encoding, inside the critical
/// section), TIM3 ticks: reported in the next line, to check `LOG_BUDGET_NS` on silicon.
static LOG_HELD_TICKS: AtomicU32 = AtomicU32::new(0);
/// Telemetry lines emitted without a window after `LOG_DEFER_MAX_US` of waiting (a budget no
/// gap of the frame holds): each may cut a phase (counted in `MIXED` then).
static LOG_FORCED: AtomicU32 = AtomicU32::new(0);
/// The room the telemetry line needs before the next event, ns: its encoding's longest hold on
/// the board model (`LOG_MODEL_NS`) and half again for silicon's loads, stores and branches
/// (the model runs an instruction a cycle). An event delayed less than `MARGIN_NS` costs
/// nothing, so this holds a silicon line up to 1.5 × model + 4 µs. Within the frame's settling
/// windows (45.9 / 49.2 / 57.5 µs) and, on the F446, its position conversions (52.4 µs).
const LOG_BUDGET_NS: u32 = LOG_MODEL_NS * 3 / 2;
/// The telemetry line's encoding on the board model, its longest hold over 3 s (2026-11-30,
/// `log_held_ns` in the line: 23 455 ns F446, 28 133 ns G474), rounded up.
const LOG_MODEL_NS: u32 = 28_200;
const LOG_BUDGET_TICKS: u32 = LOG_BUDGET_NS * TICKS_PER_US / 1_000;
const _: () = assert!(LOG_BUDGET_TICKS < FRAME_TICKS / 4);
/// Past this wait for a window the line is emitted anyway (counted in `LOG_FORCED`).
const LOG_DEFER_MAX_US: u64 = 100_000;

/// TIM3 ticks until the acquisition's next event, 0 if one is due (its interrupt pending).
/// Called with interrupts off: TIM3 cannot move CCR1 between the reads.
fn log_room_ticks() -> u32 {
    let r = pac::TIM3;
    // CNT first, CCR1, then SR: a compare that matches after CNT is read shows as CC1IF set or
    // as a small CCR1 − CNT, never as a frame of room. (Read SR first, a match between the SR
    // and CNT reads, a few timer ticks apart on APB1, would read as "next frame" with the
    // event's interrupt pending through the whole line.)
    let cnt = r.cnt().read().cnt() as u32;
    let ccr = r.ccr(0).read().ccr() as u32;
    // CC1IF set: an event's compare matched and its interrupt has not run (RM0390 §17.4.5,
    // RM0440 §29.6.5). CNT = CCR1: it matches on this tick.
    if r.sr().read().ccif(0) || ccr == cnt {
        return 0;
    }
    if ccr > cnt {
        ccr - cnt
    } else {
        // The next event is in the next frame (the counter reloads at FRAME_TICKS − 1).
        ccr + FRAME_TICKS - cnt
    }
}

// ---- ADC and DMA, per chip ------------------------------------------------------------------

/// Each slot's first word in the frame's DMA buffer (slots back to back, one word a rank).
const FIRST: [usize; 4] = [
    0,
    RANKS[0] as usize,
    RANKS[0] as usize + RANKS[1] as usize,
    RANKS[0] as usize + RANKS[1] as usize + RANKS[2] as usize,
];
/// The frame's DMA words: every rank of every slot.
pub const WORDS: usize = FIRST[3] + RANKS[3] as usize;
const _: () = assert!(DISCARD < RANKS[0] && DISCARD < RANKS[1] && DISCARD < RANKS[2]);
const _: () = assert!(DISCARD < RANKS[3] && WORDS <= 64);
/// The frame's codes, as the DMA writes them.
static mut BUF: [u16; WORDS] = [0; WORDS];

/// Slot `k`'s code: its summed conversions (the first `DISCARD` ranks left out: charge sharing
/// with the hold capacitor after the channel switch), scaled to 16 conversions' sum (the core's
/// code scale), rounded, as host-sim's overlay model scales it.
fn code(k: usize) -> u16 {
    let k = k % 4;
    let (from, to) = (FIRST[k] + DISCARD as usize, FIRST[k] + RANKS[k] as usize);
    let base = core::ptr::addr_of!(BUF) as *const u16;
    let mut sum = 0u32;
    for j in from..to.min(WORDS) {
        // SAFETY: j < WORDS; the DMA has stopped writing (the frame is complete).
        sum += unsafe { core::ptr::read_volatile(base.add(j)) } as u32;
    }
    let n = (to - from).max(1) as u32;
    ((sum * 16 + n / 2) / n).min(u16::MAX as u32) as u16
}

/// Bounded busy-waits on an ADC bit (a stop, the dummy conversion): never a hang; at least
/// ~10 µs at 180 MHz, longer than one conversion (3.0 µs F446, 1.6 µs G474).
const WAIT_LOOPS: u32 = 2_000;

#[cfg(feature = "nucleo-f446re")]
mod chip {
    //! F446: ADC1 scan of the slot's ranks (all its channel), 56-cycle sampling (the 1D
    //! plan's), DMA2 stream 0 channel 0 (RM0390 §9.3.3 table 29), one half-word a conversion.
    use super::*;
    use embassy_stm32::adc::{Adc, SampleTime};
    use embassy_stm32::pac::dma::vals;
    use embassy_stm32::peripherals::{ADC1, DMA2_CH0};

    const STREAM: usize = 0;

    pub fn init(adc: Peri<'static, ADC1>, _dma: Peri<'static, DMA2_CH0>) {
        // Clock, ADCPRE (PCLK2 / 4 = 22.5 MHz) and ADON by embassy; kept on for good.
        core::mem::forget(Adc::new(adc));
        let r = pac::ADC1;
        // SCAN: the slot's ranks in one start (RM0390 §13.3.5); 12 bits.
        r.cr1().modify(|w| w.set_scan(true));
        // DMA with DDS = 1: a request per conversion for as long as the stream runs (§13.8.1);
        // single (not continuous) mode; no external trigger: SWSTART starts it (§13.3.4).
        r.cr2().modify(|w| {
            w.set_dma(true);
            w.set_dds(embassy_stm32::pac::adc::vals::Dds::CONTINUOUS);
            w.set_cont(false);
            w.set_exten(embassy_stm32::adc::Exten::DISABLED);
        });
        for ch in CHANNELS {
            if ch < 10 {
                r.smpr2()
                    .modify(|w| w.set_smp(ch as usize, SampleTime::CYCLES56));
            } else {
                r.smpr1()
                    .modify(|w| w.set_smp(ch as usize - 10, SampleTime::CYCLES56));
            }
        }
        set_channel(CHANNELS[0], RANKS[0]);
        pac::RCC.ahb1enr().modify(|w| w.set_dma2en(true));
        let s = pac::DMA2.st(STREAM);
        s.cr().modify(|w| w.set_en(false));
        while s.cr().read().en() {}
        s.par().write_value(r.dr().as_ptr() as u32);
        s.m0ar().write_value(core::ptr::addr_of!(BUF) as u32);
        s.fcr().write(|w| w.set_dmdis(vals::Dmdis::ENABLED));
        s.cr().write(|w| {
            w.set_chsel(0);
            w.set_dir(vals::Dir::PERIPHERAL_TO_MEMORY);
            w.set_msize(vals::Size::BITS16);
            w.set_psize(vals::Size::BITS16);
            w.set_minc(true);
            w.set_pinc(false);
            w.set_circ(false);
            w.set_pl(vals::Pl::VERY_HIGH);
        });
        rearm();
    }

    /// Nothing to end: the F446's SQRs take a write while a sequence runs (RM0390 §13.13.9–11
    /// set no condition); a phase still converting is caught by the DMA count check.
    #[inline(always)]
    pub fn end_phase(_words_after: u32) {}

    /// `ranks` ranks (1..=16) of `ch`: SQR3 SQ1–6, SQR2 SQ7–12, SQR1 SQ13–16 and L = ranks − 1
    /// (RM0390 §13.13.9–11).
    pub fn set_channel(ch: u8, ranks: u8) {
        let r = pac::ADC1;
        r.sqr3().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
        r.sqr2().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
        r.sqr1().write(|w| {
            (0..4).for_each(|i| w.set_sq(i, ch));
            w.set_l(ranks.clamp(1, 16) - 1);
        });
    }

    pub fn start() {
        pac::ADC1.cr2().modify(|w| w.set_swstart(true));
    }

    /// Nothing before the acquisition: the F446 has no late-conversion erratum (ES0430 is the
    /// G474's).
    pub fn before_acquisition() {}

    /// Words the stream has still to move this frame (NDTR, RM0390 §9.5.6).
    pub fn remaining() -> u32 {
        pac::DMA2.st(STREAM).ndtr().read().ndt() as u32
    }

    /// Whether the stream moved every word of the frame (normal mode: NDTR counts to 0 and the
    /// stream disables itself, RM0390 §9.3.10), then re-armed for the next frame: EN = 0 read
    /// back, flags cleared, NDTR reloaded, EN = 1 (§9.3.17). An overrun (OVR, which with DMA
    /// stops the requests, §13.8.1) is cleared with the DMA bit toggled.
    pub fn rearm() -> bool {
        let s = pac::DMA2.st(STREAM);
        let complete = s.ndtr().read().ndt() == 0;
        s.cr().modify(|w| w.set_en(false));
        while s.cr().read().en() {}
        pac::DMA2.ifcr(0).write(|w| {
            w.set_tcif(STREAM, true);
            w.set_htif(STREAM, true);
            w.set_teif(STREAM, true);
            w.set_dmeif(STREAM, true);
            w.set_feif(STREAM, true);
        });
        let r = pac::ADC1;
        if r.sr().read().ovr() {
            r.sr().modify(|w| w.set_ovr(false));
            r.cr2().modify(|w| w.set_dma(false));
            r.cr2().modify(|w| w.set_dma(true));
        }
        s.ndtr().write(|w| w.set_ndt(WORDS as u16));
        s.cr().modify(|w| w.set_en(true));
        complete
    }
}

#[cfg(all(feature = "nucleo-g474re", not(feature = "nucleo-f446re")))]
mod chip {
    //! G474: ADC1, a regular sequence of the slot's ranks (all its channel; the oversampler
    //! off, so each conversion is a word and the first can be thrown away), 47.5-cycle sampling
    //! (the 1D plan's); DMA1 channel 1 through DMAMUX1 channel 0, request 5 = ADC1 (RM0440
    //! §13.3.2 table 91), one half-word a conversion.
    use super::*;
    use embassy_stm32::adc::{vals, Adc, AdcConfig, SampleTime};
    use embassy_stm32::peripherals::{ADC1, DMA1_CH1};

    const CH: usize = 0;

    /// ADC_CR's rs bits (RM0440 §21.7.3): ADCAL, JADSTP, ADSTP, JADSTART, ADSTART, ADDIS,
    /// ADEN. Software may set ADEN "only when all bits of ADC_CR are 0" but ADVREGEN and
    /// ADCALDIF, so a read-modify-write that sets ADSTART must not write ADEN's 1 back: the
    /// rs bits are written 0 (no effect) but the one being set, as ST's
    /// `LL_ADC_REG_StartConversion` does (`MODIFY_REG(CR, ADC_CR_BITS_PROPERTY_RS, ADSTART)`).
    const CR_RS: u32 = (1 << 31) | (1 << 5) | (1 << 4) | (1 << 3) | (1 << 2) | (1 << 1) | 1;
    const ADSTART: u32 = 1 << 2;
    const ADSTP: u32 = 1 << 4;

    fn cr_set(bit: u32) {
        let r = pac::ADC1;
        let cr = r.cr().read().0;
        r.cr().write_value(pac::adc::regs::Cr((cr & !CR_RS) | bit));
    }

    /// ADSTART = 0 (RM0440 §21.4.17, "Stopping an ongoing conversion"): ADSTP if a sequence
    /// runs, then a bounded wait for ADSTART to clear. SQR and CFGR are writable only then.
    fn stop() {
        let r = pac::ADC1;
        if !r.cr().read().adstart() {
            return;
        }
        cr_set(ADSTP);
        for _ in 0..WAIT_LOOPS {
            if !r.cr().read().adstart() {
                break;
            }
        }
    }

    /// Ends the running phase's sequence before a switch, `words_after` being the frame's words
    /// that come after it. ADSTP only while two or more of its conversions are still to reach
    /// memory: software may set ADSTP only while ADSTART = 1 (RM0440 §21.4.17), and ADSTART
    /// clears by itself at the sequence's end, so an ADSTP written as the last conversion ends
    /// lands on ADSTART = 0 (the board model caught that, during a push on the G474 link image).
    /// With one left (a conversion, 1.4 µs at most) its own end is waited for instead.
    pub fn end_phase(words_after: u32) {
        let r = pac::ADC1;
        if !r.cr().read().adstart() {
            return;
        }
        if remaining().saturating_sub(words_after) >= 2 {
            cr_set(ADSTP);
        }
        for _ in 0..WAIT_LOOPS {
            if !r.cr().read().adstart() {
                break;
            }
        }
    }

    pub fn init(adc: Peri<'static, ADC1>, _dma: Peri<'static, DMA1_CH1>) {
        // Calibration, ADEN (embassy); the oversampler left off; kept on for good.
        core::mem::forget(Adc::new(adc, AdcConfig::default()));
        let r = pac::ADC1;
        for ch in CHANNELS {
            if ch < 10 {
                r.smpr()
                    .modify(|w| w.set_smp(ch as usize, SampleTime::CYCLES47_5));
            } else {
                r.smpr2()
                    .modify(|w| w.set_smp(ch as usize - 10, SampleTime::CYCLES47_5));
            }
        }
        dummy_conversion();
        // DMA circular on the ADC side (DMACFG = 1: a request per result for as long as DMAEN,
        // §21.4.29), single mode, software start (EXTEN = 0). CFGR only while ADSTART = 0.
        r.cfgr().modify(|w| {
            w.set_dmaen(vals::Dmaen::ENABLE);
            w.set_dmacfg(vals::Dmacfg::CIRCULAR);
            w.set_cont(false);
            w.set_exten(vals::Exten::DISABLED);
        });
        set_channel(CHANNELS[0], RANKS[0]);
        pac::RCC.ahb1enr().modify(|w| {
            w.set_dma1en(true);
            w.set_dmamux1en(true);
        });
        pac::DMAMUX1.ccr(CH).write(|w| w.set_dmareq_id(5));
        let c = pac::DMA1.ch(CH);
        c.cr().modify(|w| w.set_en(false));
        c.par().write_value(r.dr().as_ptr() as u32);
        c.mar().write_value(core::ptr::addr_of!(BUF) as u32);
        c.cr().write(|w| {
            w.set_dir(embassy_stm32::pac::bdma::vals::Dir::FROM_PERIPHERAL);
            w.set_msize(embassy_stm32::pac::bdma::vals::Size::BITS16);
            w.set_psize(embassy_stm32::pac::bdma::vals::Size::BITS16);
            w.set_minc(true);
            w.set_pinc(false);
            w.set_circ(false);
            w.set_pl(embassy_stm32::pac::bdma::vals::Pl::VERY_HIGH);
        });
        rearm();
    }

    /// ES0430 ("Wrong ADC result if conversion done late after calibration or previous
    /// conversion"): the first conversion more than 1 ms after the calibration may be wrong, so
    /// one is converted and thrown away before the acquisition, as the 1D image does
    /// (`board::g474`, `dummy_conversion`). DMAEN = 0 (no request), EXTEN = 0 (ADSTART starts
    /// it at once and clears at its end of sequence, RM0440 §21.4.15, §21.4.18). Afterwards the
    /// 2D image converts at least once a frame (≤ 0.3 ms), so no later conversion is late.
    fn dummy_conversion() {
        let r = pac::ADC1;
        r.cfgr().modify(|w| {
            w.set_dmaen(vals::Dmaen::DISABLE);
            w.set_exten(vals::Exten::DISABLED);
            w.set_cont(false);
        });
        set_channel(CHANNELS[0], 1);
        cr_set(ADSTART);
        for _ in 0..WAIT_LOOPS {
            if !r.cr().read().adstart() {
                break;
            }
        }
        stop();
        let _ = r.dr().read();
        // ISR flags are rc_w1.
        r.isr().write(|w| {
            w.set_ovr(true);
            w.set_eoc(true);
            w.set_eos(true);
            w.set_eosmp(true);
        });
    }

    /// `ranks` ranks (1..=16) of `ch`: SQR1 L = ranks − 1 and SQ1–4, SQR2 SQ5–9, SQR3 SQ10–14,
    /// SQR4 SQ15–16 (RM0440 §21.7.11–14). Written only while ADSTART = 0 (§21.7.11): a phase
    /// whose conversions still run at its successor's switch is stopped first (its frame is
    /// dropped by the DMA count check).
    pub fn set_channel(ch: u8, ranks: u8) {
        stop();
        let r = pac::ADC1;
        r.sqr1().write(|w| {
            w.set_l(ranks.clamp(1, 16) - 1);
            (0..4).for_each(|i| w.set_sq(i, ch));
        });
        r.sqr2().write(|w| (0..5).for_each(|i| w.set_sq(i, ch)));
        r.sqr3().write(|w| (0..5).for_each(|i| w.set_sq(i, ch)));
        r.sqr4().write(|w| (0..2).for_each(|i| w.set_sq(i, ch)));
    }

    pub fn start() {
        cr_set(ADSTART);
    }

    /// Right before the acquisition starts: ES0430's dummy conversion again, then DMA requests
    /// back on and the first phase's sequence. The one at `init` can be more than 1 ms old by
    /// now: the boot scene is compiled between the two (~0.5 ms for fig. 12 on the board model,
    /// several ms for the largest scene from flash with its wait states), and the erratum's
    /// clock runs from the last conversion. ADSTART = 0 here (nothing converts before TIM3).
    pub fn before_acquisition() {
        dummy_conversion();
        let r = pac::ADC1;
        r.cfgr().modify(|w| {
            w.set_dmaen(vals::Dmaen::ENABLE);
            w.set_dmacfg(vals::Dmacfg::CIRCULAR);
        });
        set_channel(CHANNELS[0], RANKS[0]);
    }

    /// Words the channel has still to move this frame (CNDTR, RM0440 §12.6.4).
    pub fn remaining() -> u32 {
        pac::DMA1.ch(CH).ndtr().read().ndt() as u32
    }

    /// Whether the channel moved every word of the frame (CNDTR at 0, RM0440 §12.4.4), then
    /// re-armed: EN = 0, flags cleared, CNDTR reloaded (writable only while EN = 0), EN = 1. An
    /// overrun (OVR: with DMA, no request until it is cleared, §21.4.27) is recovered as the 1D
    /// image recovers it (`board::g474`, `Sampler::restart`): the ADC stopped, OVR/EOC/EOS
    /// cleared (rc_w1) and DMAEN toggled (CFGR writable only while ADSTART = 0), with the
    /// channel re-armed here.
    pub fn rearm() -> bool {
        let c = pac::DMA1.ch(CH);
        let complete = c.ndtr().read().ndt() == 0;
        c.cr().modify(|w| w.set_en(false));
        pac::DMA1.ifcr().write(|w| w.set_gif(CH, true));
        let r = pac::ADC1;
        if r.isr().read().ovr() {
            stop();
            r.isr().write(|w| {
                w.set_ovr(true);
                w.set_eoc(true);
                w.set_eos(true);
            });
            r.cfgr().modify(|w| w.set_dmaen(vals::Dmaen::DISABLE));
            r.cfgr().modify(|w| w.set_dmaen(vals::Dmaen::ENABLE));
        }
        c.ndtr().write(|w| w.set_ndt(WORDS as u16));
        c.cr().modify(|w| w.set_en(true));
        complete
    }
}

#[cfg(feature = "nucleo-f446re")]
pub type AdcDma = embassy_stm32::peripherals::DMA2_CH0;
#[cfg(all(feature = "nucleo-g474re", not(feature = "nucleo-f446re")))]
pub type AdcDma = embassy_stm32::peripherals::DMA1_CH1;

/// The overlay's peripherals, claimed by `board::split`.
pub struct Acquisition {
    pub adc: Peri<'static, embassy_stm32::peripherals::ADC1>,
    pub dma: Peri<'static, AdcDma>,
    pub tim: Peri<'static, embassy_stm32::peripherals::TIM3>,
    pub pins: [Peri<'static, embassy_stm32::gpio::AnyPin>; 4],
}

impl Acquisition {
    /// Pins analog, ADC and DMA configured, TIM3 loaded and stopped.
    fn configure(self) {
        write_drive(&ALL_ANALOG);
        // The pins stay claimed (and analog) for good.
        core::mem::forget(self.pins);
        chip::init(self.adc, self.dma);
        let t = embassy_stm32::timer::low_level::Timer::new(self.tim);
        defmt::assert_eq!(t.get_clock_frequency().0, BOARD.adc.trigger_timer_clk_hz);
        core::mem::forget(t);
        let r = pac::TIM3;
        r.cr1().modify(|w| w.set_cen(false));
        r.psc().write_value(0);
        r.arr().write(|w| w.set_arr((FRAME_TICKS - 1) as u16));
        // CC1 output compare, frozen (CCMR1 reset value): the match sets CC1IF only.
        r.ccr(0).write(|w| w.set_ccr(EVENTS[0].tick as u16));
        // UG: PSC and ARR loaded, CNT = 0; cleared before the interrupt is enabled.
        r.egr().write(|w| w.set_ug(true));
        r.sr().write_value(pac::timer::regs::SrGp16(0));
        r.dier().write(|w| w.set_ccie(0, true));
        NEXT.store(0, Ordering::Relaxed);
    }
}

fn start_timer() {
    chip::before_acquisition();
    // Above the sample path's executor, beside embassy's DMA and timer interrupts.
    interrupt::TIM3.set_priority(Priority::P0);
    // SAFETY: its handler is `TIM3` below.
    unsafe { interrupt::TIM3.enable() };
    pac::TIM3.cr1().modify(|w| w.set_cen(true));
}

#[interrupt]
fn TIM3() {
    on_event();
}

/// One event of the frame (the TIM3 CC1 interrupt). Never inlined: a root of the panic check.
#[inline(never)]
pub fn on_event() {
    let r = pac::TIM3;
    // CC1IF is rc_w0: written 0, every other flag written 1 (unchanged).
    r.sr().write_value(pac::timer::regs::SrGp16(!(1 << 1)));
    let i = NEXT.load(Ordering::Relaxed) as usize % EVENTS.len();
    let ev = EVENTS[i];
    let slot = ev.slot as usize % 4;
    // The pins first (their time is the design's), then the frame boundary's work.
    let mut switched = 0;
    if ev.kind != 1 {
        write_drive(&DRIVES[slot]);
        switched = r.cnt().read().cnt() as u32;
        // Every earlier slot's words in memory, or this frame mixes plates: a late start (an
        // interrupt held off past the margin) left conversions running across the switch. Read
        // after the pins: a word counted here had its sampling end a SAR conversion (12 / 12.5
        // ADC cycles: 533 / 333 ns) before it reached memory, longer than the pin writes take.
        // The frame boundary's check is `rearm`'s (all words moved).
        let words_after = if i == 0 { 0 } else { (WORDS - FIRST[slot]) as u32 };
        if i != 0 && chip::remaining() != words_after {
            MIXED_NOW.store(true, Ordering::Relaxed);
        }
        chip::end_phase(words_after);
        chip::set_channel(CHANNELS[slot], RANKS[slot]);
    }
    if ev.kind != 0 {
        chip::start();
    }
    if i == 0 {
        deliver();
    } else if LOG_WANTED.load(Ordering::Relaxed) {
        LOG_WINDOW.signal(());
    }
    let n = (i + 1) % EVENTS.len();
    NEXT.store(n as u32, Ordering::Relaxed);
    let next = match EVENTS[n].kind {
        1 => switched + EVENTS[n].tick,
        _ => EVENTS[n].tick,
    };
    r.ccr(0).write(|w| w.set_ccr(next as u16));
    if n != 0 && r.cnt().read().cnt() as u32 >= next {
        LATE.fetch_add(1, Ordering::Relaxed);
    }
}

/// The frame boundary: the last frame's codes, if the DMA moved them all, to the control task.
fn deliver() {
    let complete = chip::rearm();
    let mixed = MIXED_NOW.swap(false, Ordering::Relaxed);
    if !RUNNING.swap(true, Ordering::Relaxed) {
        return;
    }
    if mixed {
        MIXED.fetch_add(1, Ordering::Relaxed);
        return;
    }
    if !complete {
        INCOMPLETE.fetch_add(1, Ordering::Relaxed);
        return;
    }
    let frame = Frame {
        x_code: code(0),
        y_code: code(1),
        z1_code: code(2),
        z2_code: code(3),
        t_us: Instant::now().as_micros() as u32,
    };
    if queue_frame(frame) {
        DELIVERED.fetch_add(1, Ordering::Relaxed);
    } else {
        DROPPED.fetch_add(1, Ordering::Relaxed);
    }
}

/// Queues a frame for the control task; false if full. Never inlined: the panic check's allow
/// list names it for the channel's RefCell borrow, which cannot fail.
#[inline(never)]
fn queue_frame(frame: Frame) -> bool {
    FRAMES.try_send(frame).is_ok()
}

/// The 2D controller with the default velocity estimator (host-sim's).
pub type Controller = Controller2d;

static CONTROLLER: static_cell::StaticCell<Option<Controller>> = static_cell::StaticCell::new();

/// The controller, in its static (not main's frame).
#[inline(never)]
fn new_controller(timer: BurstTimer) -> &'static mut Controller {
    let ctrl = CONTROLLER.init_with(|| Controller::new(timer, FRAME_US).ok());
    let Some(ctrl) = ctrl.as_mut() else {
        defmt::panic!("touch: the 2D controller is refused")
    };
    ctrl
}

/// One frame through the sensor and the controller onto the burst gate. Never inlined: a root
/// of the panic check.
#[inline(never)]
pub fn frame_step(
    sensor: &mut TouchSensor,
    ctrl: &mut Controller,
    burst: &mut BurstGate,
    tap: &mut crate::link2d::Tap2d,
    frame: &Frame,
) {
    let reading = sensor.on_frame(frame);
    let out = ctrl.on_reading(frame.t_us, reading);
    apply2d(&out, burst);
    tap.record(frame.t_us, reading, &out, burst.line());
}

/// The stale watchdog's tick. Never inlined: a root of the panic check.
#[inline(never)]
pub fn tick_step2d(ctrl: &mut Controller, burst: &mut BurstGate, now_us: u32) {
    if let Some(a) = ctrl.on_tick(now_us) {
        burst.apply(a);
    }
}

const WATCHDOG_PERIOD: Duration = Duration::from_millis(1);
const TELEMETRY_PERIOD_US: u64 = 1_000_000;

#[embassy_executor::task]
async fn control2d(
    ctrl: &'static mut Controller,
    mut sensor: TouchSensor,
    mut burst: BurstGate,
    mut link: crate::link2d::ControlLink,
    mut wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
) {
    // The boot scene first (`ControlLink::boot`), then the acquisition.
    link.boot(ctrl, &mut burst, || wdg.pet()).await;
    let mut watchdog = Ticker::every(WATCHDOG_PERIOD);
    let mut next_log = Instant::now().as_micros() + TELEMETRY_PERIOD_US;
    // The task's state is in place: the acquisition may start.
    start_timer();
    loop {
        let window = match select3(FRAMES.receive(), watchdog.next(), LOG_WINDOW.wait()).await {
            Either3::First(frame) => {
                frame_step(&mut sensor, ctrl, &mut burst, &mut link.tap, &frame);
                false
            }
            Either3::Second(()) => {
                tick_step2d(ctrl, &mut burst, Instant::now().as_micros() as u32);
                false
            }
            Either3::Third(()) => true,
        };
        // The line first: a window's room is counted from the event that signalled it.
        let now = Instant::now().as_micros();
        if now >= next_log {
            // Outside a window only past the longest wait (a budget no gap holds).
            let forced = now >= next_log + LOG_DEFER_MAX_US;
            if (window || forced) && telemetry(ctrl, &burst, forced) {
                LOG_WANTED.store(false, Ordering::Relaxed);
                LOG_WINDOW.reset();
                next_log = now + TELEMETRY_PERIOD_US;
            } else {
                LOG_WANTED.store(true, Ordering::Relaxed);
            }
        }
        link.service(ctrl, &mut burst);
        wdg.pet();
    }
}

/// The telemetry line, emitted if the acquisition's next event is `LOG_BUDGET_TICKS` away (or
/// more, after a line held longer than that; or `forced`), inside one critical section with that check, so nothing moves the next event
/// between them; the encoding's hold measured on TIM3's counter. Whether it was emitted.
#[inline(never)]
fn telemetry(ctrl: &Controller, burst: &BurstGate, forced: bool) -> bool {
    cortex_m::interrupt::free(|_| {
        // Silicon may hold the line longer than the model's figure the budget is made from
        // (flash wait states, cold cache: the line runs once a second): once a line has held
        // longer than the budget, the longest hold seen and an eighth more is the room asked.
        let held = LOG_HELD_TICKS.load(Ordering::Relaxed);
        let need = LOG_BUDGET_TICKS.max(held + held / 8);
        if !forced && log_room_ticks() < need {
            return false;
        }
        if forced {
            LOG_FORCED.fetch_add(1, Ordering::Relaxed);
        }
        let t0 = pac::TIM3.cnt().read().cnt() as u32;
        info!(
            "telemetry2d frames {=u32} late {=u32} mixed {=u32} incomplete {=u32} dropped {=u32} log_held_ns {=u32} forced {=u32} {} burst {} line {}",
            DELIVERED.load(Ordering::Relaxed),
            LATE.load(Ordering::Relaxed),
            MIXED.load(Ordering::Relaxed),
            INCOMPLETE.load(Ordering::Relaxed),
            DROPPED.load(Ordering::Relaxed),
            LOG_HELD_TICKS.load(Ordering::Relaxed) * 1_000 / TICKS_PER_US,
            LOG_FORCED.load(Ordering::Relaxed),
            ctrl.telemetry(),
            burst.stats,
            burst.line()
        );
        // The counter reloads every frame; the line takes less than one.
        let held = (pac::TIM3.cnt().read().cnt() as u32 + FRAME_TICKS - t0) % FRAME_TICKS;
        LOG_HELD_TICKS.fetch_max(held, Ordering::Relaxed);
        true
    })
}

const IWDG_TIMEOUT_US: u32 = 50_000;

#[embassy_executor::main]
async fn main(spawner: embassy_executor::Spawner) {
    let Some(p) = board::init() else {
        fault::halt_without_clock(board::HSE_SOURCE, board::HSE_TIMEOUT_MS)
    };
    info!(
        "saw-firmware v{} on {} ({}), 2D image (touch-2d)",
        crate::VERSION,
        BOARD.name,
        BOARD.probe_rs_chip
    );
    if let Some((cause, irqn)) = fault::take_last() {
        warn!("boot: the previous run ended in the fault path ({}, exception {}): RF was turned off, then the chip reset", cause, irqn);
    }
    let parts = board::split(p);
    let rf_arm: Output<'static> = parts.rf_arm;
    let level = level::RfLevel::new(
        parts.envelope_tim,
        parts.dac,
        parts.dac_pin,
        parts.envelope_dma,
    );
    let burst = BurstGate::new(
        parts.burst_tim,
        parts.burst_pin,
        parts.burst_b_pin,
        level,
        BOARD,
    );
    let carrier = Carrier::start(parts.carrier_tim, parts.carrier_pin, BOARD);
    info!(
        "carrier: {} Hz (registers give {} Hz)",
        BOARD.carrier_hz(),
        carrier.frequency_hz()
    );
    defmt::assert_eq!(carrier.frequency_hz(), saw_boards::CARRIER_HZ);
    core::mem::forget(carrier);

    let timer = BurstTimer {
        clock_hz: BOARD.burst_timer_clk_hz,
        counter_bits: BOARD.burst_timer_bits,
        max_burst_hz: BOARD.max_burst_hz,
    };
    // The controller (~10 KB) is built in its static, with no scene (line off). The boot scene
    // (saved in flash, else built in: `link2d::boot`) is not compiled here: the link task hands
    // it to the control loop first thing, as a push (`link2d::boot_scene`), so
    // `Prepared2d::compile`'s ~36 KB frame stacks on an idle thread mode. Compiled under main's
    // poll frame, it left the G474 1 568 B of stack headroom with the largest 2D scene (board
    // model, tests/touch2d.rs's stack check).
    let ctrl = new_controller(timer);
    let booted = crate::link2d::boot(parts.store, SCENE_2D, SCENE_2D_FILE, FRAME_US).await;
    let stamp = booted.session.stamp();
    let Ok(map) = Affine::from_points(CAL, &RailBands::default()) else {
        defmt::panic!("touch: the built-in calibration is refused")
    };
    let Ok(sensor) = TouchSensor::new(PressureConfig::DEFAULT, RailBands::default(), map) else {
        defmt::panic!("touch: the default pressure thresholds are refused")
    };
    parts.touch.configure();
    info!(
        "touch: frame {=u32} us ({=u32} TIM3 ticks), {=usize} events, channels X {=u8} Y {=u8} Z1 {=u8} Z2 {=u8}, margin {=u32} ns",
        FRAME_US,
        FRAME_TICKS,
        EVENTS.len(),
        CHANNELS[0],
        CHANNELS[1],
        CHANNELS[2],
        CHANNELS[3],
        MARGIN_NS
    );
    // `rf_arm` stays low until the boot scene is installed (`ControlLink::service`).
    let mut wdg = IndependentWatchdog::new(parts.iwdg, IWDG_TIMEOUT_US);
    wdg.unleash();
    interrupt::UART4.set_priority(SAMPLE_PATH_PRIORITY);
    let high = EXECUTOR_HIGH.start(interrupt::UART4);
    let link = crate::link2d::ControlLink::new(rf_arm, stamp);
    high.spawn(unwrap!(control2d(ctrl, sensor, burst, link, wdg)));
    crate::link2d::start(spawner, parts.link_tx, parts.link_rx, booted);
}
