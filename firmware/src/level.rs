//! RF level: DAC1 channel 1 on PA4 drives the RF amplifier's gain input; TIM8, slave of the burst
//! timer TIM2, is the DAC's only trigger, so a level written to DAC_DHR12R1 reaches the pin exactly
//! at a burst's edge; during a triangular line pulse a DMA stream plays the envelope table into
//! DHR12R1, one entry per TIM8 step. docs/rf-level.md is the register design this follows; the
//! burst timer's side (TIM2 CR2.MMS, when DHR is written) is in `rf.rs`.
//!
//! Register references: RM0390 (STM32F446) §14 DAC, §16 TIM1&TIM8, §17 TIM2–5, §9 DMA;
//! RM0440 (STM32G474) DAC, TIM1/TIM8/TIM20, DMA and DMAMUX chapters. Every piece that differs
//! between the chips (the DMA stream or channel, the DAC's buffer and interface-clock bits) is in
//! `board::{f446,g474}`.
use core::sync::atomic::{fence, Ordering};

use embassy_stm32::gpio::Flex;
use embassy_stm32::pac;
use embassy_stm32::pac::timer::vals::{Mms, Ocm, Sms, Ts};
use embassy_stm32::peripherals::{DAC1, PA4, TIM8};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::Peri;
use saw_boards::rf_level::{triangle, triangle_plan, EnvelopePlan, MAX_ENVELOPE_ENTRIES};
use saw_core::burst::TimerSettings;
use static_cell::StaticCell;

use crate::board::{self, EnvelopeDma, BOARD};

/// Channel 1's index in the PAC's per-channel DAC fields (EN1 = en(0), DHR12R1 = dhr12r(0)).
const DAC_CH1: usize = 0;
/// TIM8's time base in the periodic modes: PSC = ARR = 0xFFFF, one overflow every 2^32 clocks
/// (23.9 s at 180 MHz, 28.6 s at 150 MHz), far longer than any burst period (the slave reset
/// restarts it at every TIM2 update), so its own overflow never latches the DAC inside a burst.
const PERIODIC_PSC: u16 = 0xFFFF;
const PERIODIC_ARR: u16 = 0xFFFF;
/// TIM8 is a 16-bit counter: one envelope step is at most 2^16 prescaled clocks.
const MAX_STEP_CLOCKS: u64 = 1 << 16;

const fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}
/// TIM8 clocks per TIM2 clock, as a reduced fraction (F446: 180 / 90 MHz = 2/1; G474: 1/1).
const G: u32 = gcd(BOARD.rf_level.envelope_timer_clk_hz, BOARD.burst_timer_clk_hz);
const TIM8_PER_TIM2_NUM: u64 = (BOARD.rf_level.envelope_timer_clk_hz / G) as u64;
const TIM8_PER_TIM2_DEN: u64 = (BOARD.burst_timer_clk_hz / G) as u64;
// ccr × (psc + 1) < 2^48, so the product stays well inside u64.
const _: () = assert!(TIM8_PER_TIM2_NUM < 1 << 15);

/// The one-pulse's length in TIM8 clocks: ccr ticks of TIM2, each psc + 1 TIM2 clocks.
pub fn pulse_tim8_clocks(s: &TimerSettings) -> u64 {
    s.ccr as u64 * (s.psc as u64 + 1) * TIM8_PER_TIM2_NUM / TIM8_PER_TIM2_DEN
}

/// The envelope table the DMA reads: static, so it stays put while a stream points at it.
static TABLE: StaticCell<[u16; MAX_ENVELOPE_ENTRIES]> = StaticCell::new();

/// What TIM8 is set up for.
#[derive(Clone, Copy, PartialEq, Eq, defmt::Format)]
enum Mode {
    /// CEN = 0, no DMA request (after init, `off`).
    Stopped,
    /// Slave reset mode, PSC = ARR = 0xFFFF: every TRGI edge from TIM2 latches DHR into the DAC.
    Periodic,
    /// Slave gated mode, one DMA write per step: a triangle envelope.
    Triangle,
}

/// A triangle envelope as armed: its table's key and how it is played.
#[derive(Clone, Copy, defmt::Format)]
pub struct Armed {
    /// The table was rebuilt for this pulse, taking this long, µs (embassy-time's 1 MHz clock).
    pub rebuilt_us: Option<u32>,
    pub entries: usize,
    pub step_clocks: u32,
    pub psc: u16,
}

/// DAC1 channel 1 + TIM8 + the envelope DMA.
pub struct RfLevel {
    // Owned so nothing else can take them; the registers are written through `pac`.
    _tim: Timer<'static, TIM8>,
    _dac: Peri<'static, DAC1>,
    _pin: Flex<'static>,
    dma: EnvelopeDma,
    mode: Mode,
    table: &'static mut [u16; MAX_ENVELOPE_ENTRIES],
    /// (peak ‰, pulse length in TIM8 clocks) the table holds, if any.
    key: Option<(u16, u64)>,
    plan: EnvelopePlan,
    psc: u16,
}

impl RfLevel {
    /// PA4 analog, DAC1 channel 1 on (buffer on, TEN1 = 1, TSEL1 = TIM8 TRGO, DHR = 0), TIM8 a
    /// stopped slave of TIM2 whose TRGO is its update event. The output stays at code 0 (DOR's
    /// reset value) until the first trigger.
    pub fn new(tim: Peri<'static, TIM8>, dac: Peri<'static, DAC1>, pin: Peri<'static, PA4>, dma: EnvelopeDma) -> Self {
        // The TSEL1 code documented in saw-boards must be the one embassy's generated trigger
        // table gives TIM8 TRGO (metapac: DAC_CHX_TRG1 = TIM8_TRGO on both chips).
        defmt::assert_eq!(
            embassy_stm32::dac::ChannelTrigger::<DAC1>::signal(&embassy_stm32::triggers::TIM8_TRGO),
            BOARD.rf_level.dac_tsel
        );
        // Analog mode first: the DAC takes the pin over when EN1 is set, and an analog pin has
        // its digital input and pulls off (RM0390 §14.3 "DAC channel enable", §7.3 "Analog
        // configuration"; RM0440 DAC "DAC channel enable" and GPIO analog configuration).
        let mut pin = Flex::new(pin);
        pin.set_as_analog();

        // TIM8 first, so that its TRGO cannot reach a DAC that is already listening. Timer::new
        // enables and resets it through RCC (every register at its reset value).
        let tim = Timer::new(tim);
        defmt::assert_eq!(tim.get_clock_frequency().0, BOARD.rf_level.envelope_timer_clk_hz);
        let t = pac::TIM8;
        // TRGO = update event (RM0390 §16.4.2 TIMx_CR2.MMS = 010; RM0440 TIMx_CR2 alike): a
        // slave reset, every counter overflow and EGR.UG each latch the DAC.
        t.cr2().modify(|w| w.set_mms(Mms::UPDATE));
        // TRGI = ITR1 = TIM2's TRGO (RM0390 §16.4.3 TIMx_SMCR table "TIMx internal trigger
        // connection": TIM8 ITR1 = TIM2; RM0440 TIM8 ITR1 = tim2_trgo). TS is written while
        // SMS = 000, as the manuals ask ("to avoid wrong edge detections at the transition").
        t.smcr().modify(|w| {
            w.set_sms(Sms::DISABLED);
            w.set_ts(Ts::from_bits(BOARD.rf_level.envelope_ts));
        });
        // CC1: output compare, frozen (OC1REF unused, CC1E = 0: no pin), CCR1 not preloaded so
        // the step's half is written at once; its only job is the CC1 DMA request (CC1IF on
        // every match, RM0390 §16.3 "Output compare mode").
        t.ccmr_output(0).modify(|w| {
            w.set_ocm(0, Ocm::FROZEN);
            w.set_ocpe(0, false);
        });
        // ARR not preloaded (ARPE = 0): a new step is in force as written.
        t.cr1().modify(|w| {
            w.set_arpe(false);
            w.set_cen(false);
        });

        embassy_stm32::rcc::enable_and_reset::<DAC1>();
        let d = pac::DAC1;
        // Output buffer on (F446: BOFF1 = 0; G474: MCR.MODE1 = 000, plus HFSEL for HCLK > 80 MHz),
        // written while EN1 = 0.
        board::dac_configure();
        d.dhr12r(DAC_CH1).write(|w| w.set_dhr(0));
        // TSEL1 and TEN1 before EN1: with TEN1 = 1 DHR goes to DOR only on the selected trigger
        // (RM0390 §14.3 "DAC conversion" and "DAC trigger selection", §14.5.1 DAC_CR;
        // RM0440 DAC_CR: TSEL1 may only change while EN1 = 0). DMAEN1 stays 0: the DAC's own
        // DMA request (DMA1 stream 5 on the F446) is the link's.
        d.cr().modify(|w| {
            w.set_tsel(DAC_CH1, BOARD.rf_level.dac_tsel);
            w.set_ten(DAC_CH1, true);
            w.set_dmaen(DAC_CH1, false);
        });
        d.cr().modify(|w| w.set_en(DAC_CH1, true));
        board::dac_wait_ready();

        RfLevel {
            _tim: tim,
            _dac: dac,
            _pin: pin,
            dma,
            mode: Mode::Stopped,
            table: TABLE.init([0; MAX_ENVELOPE_ENTRIES]),
            key: None,
            plan: EnvelopePlan { entries: 0, step_clocks: 0 },
            psc: 0,
        }
    }

    /// Writes DAC_DHR12R1: the DAC outputs it at the next TIM8 TRGO (TEN1 = 1).
    pub fn hold(&self, code: u16) {
        pac::DAC1.dhr12r(DAC_CH1).write(|w| w.set_dhr(code));
    }

    /// TIM8 stopped, no CC1 DMA request, the stream stopped (EN reads 0).
    fn stop_envelope(&mut self) {
        let t = pac::TIM8;
        t.cr1().modify(|w| w.set_cen(false));
        t.dier().modify(|w| w.set_ccde(0, false));
        self.dma.stop();
    }

    /// TIM8 in slave reset mode (if it is not already): from here every TIM2 TRGO edge resets
    /// it, and the update event that reset makes is TRGO, which latches DHR into the DAC
    /// (RM0390 §16.3 "TIMx and external trigger synchronization": slave mode: reset mode,
    /// SMS = 100; §16.3.20 "Timer synchronization"). Call with TIM2 stopped. Switching in
    /// takes an EGR.UG (loading PSC, which is always preloaded: RM0390 §16.3.1 "Time-base
    /// unit"), itself a TRGO: DHR is 0 first, so what that latches is the off level.
    pub fn periodic(&mut self) {
        if self.mode == Mode::Periodic {
            return;
        }
        self.stop_envelope();
        let t = pac::TIM8;
        t.smcr().modify(|w| w.set_sms(Sms::RESET_MODE));
        t.psc().write_value(PERIODIC_PSC);
        t.arr().write(|w| w.set_arr(PERIODIC_ARR));
        self.hold(0);
        t.egr().write(|w| w.set_ug(true));
        t.sr().write_value(Default::default());
        t.cr1().modify(|w| w.set_cen(true));
        self.mode = Mode::Periodic;
    }

    /// The table for a triangle peaking at `peak_permille` over `pulse_clocks`, built unless it
    /// is the one already there; how long the build took, µs.
    fn build_table(&mut self, peak_permille: u16, pulse_clocks: u64) -> Option<u32> {
        if self.key == Some((peak_permille, pulse_clocks)) {
            return None;
        }
        let t0 = embassy_time::Instant::now();
        // Pulses longer than 128 steps of 2^16 clocks (46.6 ms at 180 MHz, 55.9 ms at
        // 150 MHz) count prescaled clocks, so the whole pulse still gets its triangle.
        let psc = ((pulse_clocks.saturating_sub(1)) / (MAX_ENVELOPE_ENTRIES as u64 * MAX_STEP_CLOCKS))
            .min(u16::MAX as u64) as u16;
        let div = psc as u64 + 1;
        let plan = triangle_plan(pulse_clocks / div, BOARD.rf_level.envelope_timer_clk_hz / div as u32);
        triangle(&BOARD.rf_level.table, peak_permille, &plan, &mut self.table[..]);
        self.plan = plan;
        self.psc = psc;
        self.key = Some((peak_permille, pulse_clocks));
        // Saturating: Instant − Instant panics if the clock went backwards (it cannot, but
        // this runs on the sample path: scripts/panic-check.sh).
        Some(embassy_time::Instant::now().saturating_duration_since(t0).as_micros() as u32)
    }

    /// Builds the table a pulse of `pulse_clocks` at `peak_permille` will play, without arming
    /// anything: the first such pulse finds it. The 2D image does this at boot for its scene's
    /// edge pulse, whose first build (~80 µs on the G474) would otherwise land on the sample path
    /// of the first edge crossed (board model: sensor-to-gate latency).
    pub fn prebuild_triangle(&mut self, peak_permille: u16, pulse_clocks: u64) -> Option<u32> {
        self.build_table(peak_permille, pulse_clocks)
    }

    /// Arms a triangle peaking at `peak_code_permille` over a one-pulse of `pulse_clocks` TIM8
    /// clocks. Call with TIM2 stopped; TIM2's TRGO must then be its enable (MMS = 001), so TIM8
    /// counts exactly while the one-pulse runs (RM0390 §16.3 "TIMx and external trigger
    /// synchronization": slave mode: gated mode, SMS = 101). Each CC1 match (half a step) DMA-writes the next entry into DHR12R1; each
    /// update (a whole step) is TRGO and latches it.
    pub fn triangle(&mut self, peak_permille: u16, pulse_clocks: u64) -> Armed {
        self.stop_envelope();
        let rebuilt_us = self.build_table(peak_permille, pulse_clocks);
        let (n, step) = (self.plan.entries, self.plan.step_clocks);
        let t = pac::TIM8;
        t.smcr().modify(|w| w.set_sms(Sms::GATED_MODE));
        t.psc().write_value(self.psc);
        t.arr().write(|w| w.set_arr((step - 1) as u16));
        t.ccr(0).write(|w| w.set_ccr((step / 2) as u16));
        // UG loads PSC and clears CNT; it is also TRGO: DHR = 0 is what the DAC latches
        // (the line is off: TIM2 is stopped).
        self.hold(0);
        t.egr().write(|w| w.set_ug(true));
        // UIF from the UG and any stale CC1IF cleared (rc_w0).
        t.sr().write_value(Default::default());
        // The table is complete before the stream can read it.
        fence(Ordering::SeqCst);
        let dhr = pac::DAC1.dhr12r(DAC_CH1).as_ptr() as u32;
        // `n` ≤ the table's length by triangle_plan; the min makes that visible to the compiler,
        // so the sample path has no bounds check here (scripts/panic-check.sh).
        self.dma.arm(&self.table[..n.min(MAX_ENVELOPE_ENTRIES)], dhr);
        // CC1 DMA request on (RM0390 §16.4.4 TIMx_DIER.CC1DE; CCDS = 0: on the CC1 event, not
        // on update, §16.4.2).
        t.dier().modify(|w| w.set_ccde(0, true));
        t.cnt().write(|w| w.set_cnt(0));
        // CEN = 1: in gated mode the counter still only counts while TRGI (TIM2's enable) is high.
        t.cr1().modify(|w| w.set_cen(true));
        self.mode = Mode::Triangle;
        Armed { rebuilt_us, entries: n, step_clocks: step, psc: self.psc }
    }

    /// Level 0 now: TIM8 stopped, its DMA request off, the stream disabled (EN reads 0, so no
    /// entry can land after this), DHR = 0, then EGR.UG: an update event, hence TRGO, hence
    /// DHR → DOR (the DAC latches 0 three APB1 cycles later, RM0390 §14.3 "DAC conversion").
    pub fn off(&mut self) {
        self.stop_envelope();
        self.hold(0);
        pac::TIM8.egr().write(|w| w.set_ug(true));
        self.mode = Mode::Stopped;
    }

    /// A worst-case table (full level, 128 entries) built once, timed; for the boot log. The
    /// cache key is cleared so the first real pulse builds its own.
    pub fn time_worst_rebuild_us(&mut self) -> u32 {
        let t0 = embassy_time::Instant::now();
        let plan = EnvelopePlan { entries: MAX_ENVELOPE_ENTRIES, step_clocks: 1 };
        triangle(&BOARD.rf_level.table, 1000, &plan, &mut self.table[..]);
        self.key = None;
        embassy_time::Instant::now().saturating_duration_since(t0).as_micros() as u32
    }
}

/// Panic / HardFault: level 0, then the DAC released. Raw register writes only (no ownership,
/// no locks): TIM8 stopped and its DMA request off, DHR = 0, TIM8 UG → TRGO → DAC latches 0,
/// then EN1 = 0: the pin is no longer driven and the reference circuit's divider pulls the gain
/// pin to 0 V (minimum gain). A write to a peripheral whose clock is still off is ignored.
pub fn emergency_off() {
    let t = pac::TIM8;
    t.cr1().modify(|w| w.set_cen(false));
    t.dier().write_value(Default::default());
    pac::DAC1.dhr12r(DAC_CH1).write(|w| w.set_dhr(0));
    t.egr().write(|w| w.set_ug(true));
    pac::DAC1.cr().modify(|w| w.set_en(DAC_CH1, false));
}
