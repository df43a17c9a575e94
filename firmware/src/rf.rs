//! RF timers: the free-running 15 MHz carrier (TIM1) and the burst timer (TIM2) whose PWM output
//! is the RF enable line; TIM2's TRGO also times the RF level (`level.rs`, docs/rf-level.md).
//!
//! Gating: the carrier never stops; the burst timer's channel output gates the RF
//! amplifier/switch. Stopping the carrier instead (master/slave gated mode) would freeze the
//! carrier pin at whatever level it had — possibly high, i.e. DC into the amplifier — while a
//! force-inactive on the enable line is an immediate, hardware-level off.
use defmt::{assert_eq, Format};
use embassy_stm32::peripherals::{TIM1, TIM2};
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch3, Channel};
use embassy_stm32::Peri;
use embassy_stm32::pac::timer::vals::Mms;
use saw_boards::BoardDef;
use saw_core::burst::TimerSettings;
use saw_core::gate::{BurstOutput, DriveMode, Envelope, GateAction};

use crate::board::BOARD;
use crate::level::RfLevel;

/// The 15 MHz carrier: TIM1 CH1, PSC 0, ARR = divider − 1, CCR = divider / 2 (50 %).
pub struct Carrier {
    tim: Timer<'static, TIM1>,
    _pin: PwmPin<'static, TIM1, Ch1>,
}

impl Carrier {
    pub fn start(tim: Peri<'static, TIM1>, pin: PwmPin<'static, TIM1, Ch1>, board: &BoardDef) -> Self {
        let t = Timer::new(tim);
        // The plan is only as good as the clock embassy actually configured.
        assert_eq!(t.get_clock_frequency().0, board.carrier_timer_clk_hz);
        t.regs_core().psc().write_value(0);
        t.set_autoreload_preload(true);
        t.set_output_compare_mode(Channel::Ch1, OutputCompareMode::PwmMode1);
        t.set_output_compare_preload(Channel::Ch1, true);
        t.set_compare_value(Channel::Ch1, board.carrier_ccr() as u16);
        t.set_max_compare_value(board.carrier_arr() as u16); // writes ARR and latches with UG
        t.enable_channel(Channel::Ch1, true);
        t.enable_outputs(); // BDTR.MOE (TIM1 is an advanced timer)
        t.start();
        Carrier { tim: t, _pin: pin }
    }

    /// Carrier frequency derived from the live registers.
    pub fn frequency_hz(&self) -> u32 {
        let psc = self.tim.regs_core().psc().read() as u32;
        let arr = self.tim.regs_core().arr().read().arr() as u32;
        self.tim.get_clock_frequency().0 / ((psc + 1) * (arr + 1))
    }
}

/// Counters of what the burst port did.
#[derive(Clone, Copy, Default, Format)]
pub struct BurstStats {
    pub starts: u32,
    pub updates: u32,
    pub offs: u32,
    pub pulses: u32,
    /// Level requests (`set_amplitude`), and how many of them were written to the DAC at once
    /// (the line running; the others wait for the next start).
    pub levels_set: u32,
    pub levels_written: u32,
    /// Triangle envelopes armed, and the table rebuilds among them (new peak or pulse length).
    pub envelopes_played: u32,
    pub table_rebuilds: u32,
    /// Longest table rebuild so far, µs.
    pub rebuild_us_max: u32,
    /// Delayed one-pulses asked with a triangular envelope, refused (line off): TIM8 would play
    /// the table from the counter's start, not from the rise (`BurstGate::pulse`).
    pub delayed_triangles_refused: u32,
}

/// What the enable lines are doing.
#[derive(Clone, Copy, PartialEq, Eq, Format)]
pub enum Line {
    Off,
    Running,
    /// One-pulse fired; the hardware ends it and stops the counter by itself.
    Pulse,
}

// Channel roles are fixed by this driver; the board table must agree.
const A: Channel = Channel::Ch1;
const B: Channel = Channel::Ch3;
const _: () = assert!(crate::board::BOARD.burst.channel == 1 && crate::board::BOARD.burst_b_channel == 3);

/// The burst timer (TIM2, 32-bit) driving the RF enable lines: CH1 = IDT A, CH3 = IDT B.
/// PWM mode 1 with ARR/CCR preload (ARPE, OCxPE): new PSC/ARR/CCR take effect at the next update.
pub struct BurstGate {
    tim: Timer<'static, TIM2>,
    _pin_a: PwmPin<'static, TIM2, Ch1>,
    _pin_b: PwmPin<'static, TIM2, Ch3>,
    line: Line,
    drive: DriveMode,
    /// The RF level the core asked for, ‰ (kept while the line is off, for the next start).
    level_permille: u16,
    /// Shape of the next one-pulse's level.
    envelope: Envelope,
    level: RfLevel,
    pub stats: BurstStats,
}

impl BurstGate {
    /// Configures the timer with both lines held inactive and the counter stopped.
    pub fn new(
        tim: Peri<'static, TIM2>,
        pin_a: PwmPin<'static, TIM2, Ch1>,
        pin_b: PwmPin<'static, TIM2, Ch3>,
        level: RfLevel,
        board: &BoardDef,
    ) -> Self {
        let t = Timer::new(tim);
        assert_eq!(t.get_clock_frequency().0, board.burst_timer_clk_hz);
        t.stop();
        for ch in [A, B] {
            // Inactive before the outputs are even enabled.
            t.set_output_compare_mode(ch, OutputCompareMode::ForceInactive);
            t.set_output_compare_preload(ch, true);
            t.enable_channel(ch, true);
        }
        t.set_autoreload_preload(true);
        BurstGate {
            tim: t,
            _pin_a: pin_a,
            _pin_b: pin_b,
            line: Line::Off,
            drive: DriveMode::Standing,
            // Full level until the core says otherwise: a scene without random amplitude or
            // envelopes never calls set_amplitude, and must burst as before.
            level_permille: 1000,
            envelope: Envelope::Rectangular,
            level,
            stats: BurstStats::default(),
        }
    }

    /// Output-compare mode of both channels: A follows `mode`, B too in standing-wave drive.
    fn set_mode(&self, mode: OutputCompareMode) {
        self.tim.set_output_compare_mode(A, mode);
        let b = match self.drive {
            DriveMode::Standing => mode,
            DriveMode::Progressive => OutputCompareMode::ForceInactive,
        };
        self.tim.set_output_compare_mode(B, b);
    }

    fn write(&self, psc: u16, arr: u32, ccr: u32) {
        let r = self.tim.regs_gp32();
        r.psc().write_value(psc);
        r.arr().write_value(arr);
        r.ccr(A.index()).write_value(ccr);
        r.ccr(B.index()).write_value(ccr);
    }

    /// New settings for a running burst, taking effect together at the next update event.
    /// PSC, ARR, CCR1 and CCR3 are separate stores, and an update event between two of them
    /// would run a period with a mixed set (a new short ARR with the old long CCR is 100 % on,
    /// above the duty cap). UDIS = 1 holds every update event off while they are written: the
    /// shadow registers keep the old set, the counter still wraps (RM0390 §17.3.2 upcounting
    /// mode, §17.4.1 TIMx_CR1.UDIS; RM0440 TIMx_CR1 is the same). At most one period runs
    /// longer on the old set. The level's DHR is written in the same window: with no update
    /// event there is no TRGO (MMS = 010), so the DAC takes it at the same edge as the new
    /// settings (docs/rf-level.md).
    fn update(&self, s: &TimerSettings) {
        // The table lookup before the window, which stays a few stores long.
        let code = self.level_code();
        let cr1 = self.tim.regs_gp32().cr1();
        cr1.modify(|w| w.set_udis(true));
        self.write(s.psc, s.arr, s.ccr);
        self.level.hold(code);
        cr1.modify(|w| w.set_udis(false));
    }

    /// DAC code of the requested level (the board's calibration table).
    fn level_code(&self) -> u16 {
        BOARD.rf_level.table.code(self.level_permille)
    }

    /// TIM2's TRGO (RM0390 §17.4.2 TIMx_CR2.MMS; RM0440 TIMx_CR2 alike): 010 = update event for
    /// a periodic burst (every period's start latches the DAC through TIM8), 001 = enable
    /// (CNT_EN) for a one-pulse (the rising edge starts it, the level gates TIM8). Written only
    /// with the counter stopped, where both read low: no stray edge.
    fn set_trgo(&self, mms: Mms) {
        self.tim.regs_gp32().cr2().modify(|w| w.set_mms(mms));
    }

    /// Load, latch with UG, enable the counter: the first period starts (whole, bar the few
    /// ticks between CEN and the mode write) at CNT = 0.
    ///
    /// The level: TIM8 in slave reset mode, TRGO = update, DHR = code(level) before UG, so UG →
    /// TRGO → TIM8 reset → its UEV → its TRGO → DAC latches the level at the burst's first edge.
    fn start(&mut self, s: &TimerSettings) {
        self.tim.stop();
        self.set_mode(OutputCompareMode::ForceInactive);
        self.tim.regs_gp32().cr1().modify(|w| w.set_opm(false));
        self.level.periodic();
        self.set_trgo(Mms::UPDATE);
        self.level.hold(self.level_code());
        self.write(s.psc, s.arr, s.ccr);
        self.tim.reset(); // CNT = 0
        self.tim.generate_update_event(); // latch PSC/ARR/CCR from preload; TRGO: the level
                                          // In PWM mode OCxREF changes only when the comparison result changes or when the mode
                                          // switches from Frozen to PWM (RM0390 §17.3.9; RM0440 PWM mode alike). Straight from
                                          // force-inactive, CNT = 0 < CCR is no change: the line would stay low for the whole
                                          // first period. Frozen keeps the (low) level; Frozen → PWM 1 evaluates CNT < CCR at once.
                                          // The counter runs first, so the first pulse can only come out a few ticks short.
        self.set_mode(OutputCompareMode::Frozen);
        self.tim.start();
        self.set_mode(OutputCompareMode::PwmMode1);
        self.line = Line::Running;
    }

    /// One pulse (`GateAction::Pulse`): from a stopped counter, one-pulse mode counts
    /// CNT = 0..=ARR once and the update event at the wrap clears CEN (RM0390 §17.3.10 One-pulse
    /// mode, §17.4.1 CR1.OPM; RM0440's TIM2–TIM5 "One-pulse mode" alike). PWM mode 2 (OCxM = 111)
    /// holds OCxREF low while CNT < CCRx and high from CNT = CCRx (RM0390 §17.3.9 PWM mode;
    /// RM0440 "PWM mode" alike), so ARR = `s.arr` and CCR = `s.arr + 1 − s.ccr` (`pulse_ccr`)
    /// put the line high for the count's last `s.ccr` ticks, CNT = arr + 1 − ccr ..= arr: the
    /// rise comes (arr + 1 − ccr) ticks after CEN (`TimerSettings::pulse_delay_clocks`; one tick
    /// for `BurstTimer::one_pulse`, whose arr = ccr gives CCR = 1, the pulse the port always
    /// fired; up to a sample period for `BurstTimer::delayed_pulse`), and the update event stops
    /// the counter at 0, where PWM mode 2 is low again. The manual's condition for a correct
    /// pulse, CNT < CCRx ≤ ARR before the start (in particular 0 < CCRx), holds for 1 ≤ ccr ≤ arr.
    /// (PWM mode 1 + OPM would leave the line HIGH after the pulse: stopped at 0 < CCR.)
    ///
    /// The level, with TIM2's TRGO = enable (CNT_EN: high from CEN until the update event, the
    /// delay included): flat at code(level), TIM8 in reset mode, so CEN's rising TRGO latches it
    /// at the counter's start — before a delayed rise, which is harmless: the enable line is
    /// still low; or a triangle peaking at the level, TIM8 gated by TRGO from the counter's start
    /// and the DMA playing the table over `s.ccr` ticks. A delayed triangle would therefore
    /// start its table the delay early and end it the delay before the line falls. The core
    /// never asks for one (lines, the only triangles, use `BurstTimer::one_pulse`); if it did,
    /// the port refuses it: the line off, counted in `stats.delayed_triangles_refused`.
    fn pulse(&mut self, s: &TimerSettings) {
        if s.ccr == 0 {
            self.off();
            return;
        }
        let ccr = pulse_ccr(s);
        if self.envelope == Envelope::Triangular && ccr != 1 {
            self.off();
            self.stats.delayed_triangles_refused = self.stats.delayed_triangles_refused.wrapping_add(1);
            return;
        }
        self.tim.stop();
        self.set_mode(OutputCompareMode::ForceInactive);
        match self.envelope {
            Envelope::Rectangular => {
                self.level.periodic();
                self.level.hold(self.level_code());
            }
            Envelope::Triangular => {
                let armed = self.level.triangle(self.level_permille, crate::level::pulse_tim8_clocks(s));
                self.stats.envelopes_played = self.stats.envelopes_played.wrapping_add(1);
                if let Some(us) = armed.rebuilt_us {
                    self.stats.table_rebuilds = self.stats.table_rebuilds.wrapping_add(1);
                    self.stats.rebuild_us_max = self.stats.rebuild_us_max.max(us);
                }
            }
        }
        self.set_trgo(Mms::ENABLE);
        self.tim.regs_gp32().cr1().modify(|w| w.set_opm(true));
        self.write(s.psc, s.arr, ccr);
        self.tim.reset();
        self.tim.generate_update_event();
        // From force-inactive straight to PWM mode 2 at CNT = 0 < CCR: OCxREF stays low (no
        // comparison change), and rises at the CNT = CCR change.
        self.set_mode(OutputCompareMode::PwmMode2);
        self.tim.start();
        self.line = Line::Pulse;
    }

    /// Force both lines inactive now (OCxM is not preloaded), then stop the counter; then the
    /// level to 0 at once (TIM8 and its DMA stopped, DHR = 0, TIM8 UG latches it). The request
    /// is kept for the next start.
    pub fn off(&mut self) {
        self.set_mode(OutputCompareMode::ForceInactive);
        self.tim.stop();
        self.level.off();
        self.line = Line::Off;
    }

    /// The triangle table of a one-pulse `s` at `peak_permille`, built now (not played): see
    /// `RfLevel::prebuild_triangle`. The 2D image, at boot, for its scene's edge pulse.
    #[cfg(feature = "touch-2d")]
    pub fn prebuild_triangle(&mut self, s: &TimerSettings, peak_permille: u16) -> Option<u32> {
        self.level.prebuild_triangle(peak_permille, crate::level::pulse_tim8_clocks(s))
    }

    /// See `RfLevel::time_worst_rebuild_us`.
    pub fn time_worst_rebuild_us(&mut self) -> u32 {
        self.level.time_worst_rebuild_us()
    }

    pub fn line(&self) -> Line {
        self.line
    }

    /// TIM2's CR1.CEN: the counter runs (a one-pulse clears it at its update event).
    #[cfg(feature = "selftest-delayed-pulse")]
    pub fn counting(&self) -> bool {
        self.tim.regs_gp32().cr1().read().cen()
    }
}

/// CCR of a one-pulse in PWM mode 2 (see `BurstGate::pulse`): arr + 1 − ccr, the count at
/// which the line rises. The core gives 1 ≤ ccr ≤ arr (`delayed_pulse`: arr = delay + ccr − 1,
/// delay ≥ 1; `one_pulse`: arr = ccr), where this is exact and in 1..=arr. Saturating for
/// anything else, never a panic or a wrap on the sample path: ccr > arr gives CCR = 1, the
/// line high for CNT = 1..=arr, arr ticks — shorter than asked, never longer; `arr + 1` cannot
/// overflow at arr = u32::MAX, as arr − ccr ≤ u32::MAX − 1 once ccr ≥ 1 (`pulse` turns ccr = 0
/// into Off before this), and the add saturates regardless.
/// The planted defect `plant-pulse-no-delay` (never in a real image) writes CCR = 1, the
/// port's value before delayed pulses: the board model's delayed-pulse check must catch it.
fn pulse_ccr(s: &TimerSettings) -> u32 {
    if cfg!(feature = "plant-pulse-no-delay") {
        return 1;
    }
    s.arr.saturating_sub(s.ccr).saturating_add(1)
}

impl BurstOutput for BurstGate {
    fn apply(&mut self, action: GateAction) {
        match action {
            GateAction::Off => {
                self.off();
                self.stats.offs = self.stats.offs.wrapping_add(1);
            }
            GateAction::Start(s) => {
                self.start(&s);
                self.stats.starts = self.stats.starts.wrapping_add(1);
            }
            GateAction::Update(s) => {
                if self.line == Line::Running {
                    // Preloaded: the running period finishes untouched.
                    self.update(&s);
                } else {
                    self.start(&s);
                }
                self.stats.updates = self.stats.updates.wrapping_add(1);
            }
            GateAction::Pulse(s) => {
                self.pulse(&s);
                self.stats.pulses = self.stats.pulses.wrapping_add(1);
            }
        }
    }

    /// Remembered always; written to DHR at once only while a periodic burst runs, where the
    /// next TIM2 update (TRGO → TIM8 reset → TRGO) latches it: never inside a period. Off or
    /// during a one-pulse (a triangle's DMA owns DHR then) it waits for the next start.
    fn set_amplitude(&mut self, permille: u16) {
        self.level_permille = permille;
        self.stats.levels_set = self.stats.levels_set.wrapping_add(1);
        if self.line == Line::Running {
            self.level.hold(self.level_code());
            self.stats.levels_written = self.stats.levels_written.wrapping_add(1);
        }
    }

    fn set_envelope(&mut self, envelope: Envelope) {
        self.envelope = envelope;
    }

    fn set_drive(&mut self, mode: DriveMode) {
        self.drive = mode;
        // Re-apply B's mode to the line's current state (A is unaffected). Switching B on
        // mid-burst goes straight from force-inactive to PWM, deliberately *not* through Frozen
        // (compare `start`): OCxREF then keeps its forced-low level until the comparison result
        // next changes (RM0390 §17.3.9), i.e. B's first pulse starts whole at the next counter
        // wrap — never a partial pulse from mid-period. In a one-pulse the same rule makes B
        // rise with A at CNT = CCR if switched on during the delay, and stay low if switched on
        // after the rise (the next comparison change is the update event, to low).
        // Switching B off is immediate and may cut its current pulse short: less on-time only.
        let b = match (self.drive, self.line) {
            (DriveMode::Progressive, _) | (_, Line::Off) => OutputCompareMode::ForceInactive,
            (DriveMode::Standing, Line::Running) => OutputCompareMode::PwmMode1,
            (DriveMode::Standing, Line::Pulse) => OutputCompareMode::PwmMode2,
        };
        self.tim.set_output_compare_mode(B, b);
    }
}

/// Last-resort RF off for the panic and HardFault handlers: no ownership, no allocation, no
/// locks — raw register writes. Forces both burst outputs inactive (OCxM is not preloaded, so
/// this is immediate), stops the burst timer, then takes the enable pins (PA0, PB10) away from
/// the timer — ODR low, MODER = general-purpose output (RM0390 §7.4.1/§7.4.7; RM0440 GPIO
/// alike) — so they are low whatever TIM2 still does, and drops the RF arm line (PB5).
/// Then the RF level to 0 and the DAC released (`level::emergency_off`).
/// (Writes to a peripheral whose clock is still off, before `board::split`, are ignored.)
pub fn emergency_off() {
    use embassy_stm32::pac;
    use embassy_stm32::pac::timer::vals::Ocm;
    // CCMR1 channel 0 = CH1 (IDT A), CCMR2 channel 0 = CH3 (IDT B).
    pac::TIM2.ccmr_output(0).modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
    pac::TIM2.ccmr_output(1).modify(|w| w.set_ocm(0, Ocm::FORCE_INACTIVE));
    pac::TIM2.cr1().modify(|w| w.set_cen(false));
    rf_pins_low();
    crate::level::emergency_off();
}

/// The pin half of `emergency_off`: the enables (PA0, PB10) as GPIO outputs driving low, then
/// the RF arm (PB5) low. Needs only the GPIO ports' clocks.
pub fn rf_pins_low() {
    use embassy_stm32::pac;
    use embassy_stm32::pac::gpio::vals::Moder;
    pac::GPIOA.bsrr().write(|w| w.set_br(0, true));
    pac::GPIOB.bsrr().write(|w| w.set_br(10, true));
    pac::GPIOA.moder().modify(|w| w.set_moder(0, Moder::OUTPUT));
    pac::GPIOB.moder().modify(|w| w.set_moder(10, Moder::OUTPUT));
    pac::GPIOB.bsrr().write(|w| w.set_br(5, true));
}
const _: () = {
    let b = crate::board::BOARD;
    assert!(b.burst.pin.port == 'A' && b.burst.pin.pin == 0);
    assert!(b.burst_b_pin.port == 'B' && b.burst_b_pin.pin == 10);
    assert!(b.rf_arm_pin.port == 'B' && b.rf_arm_pin.pin == 5);
};
