//! RF timers: the free-running 15 MHz carrier (TIM1) and the burst timer (TIM2) whose PWM output
//! is the RF enable line.
//!
//! Gating: the carrier never stops; the burst timer's channel output gates the RF
//! amplifier/switch. Stopping the carrier instead (master/slave gated mode) would freeze the
//! carrier pin at whatever level it had — possibly high, i.e. DC into the amplifier — while a
//! force-inactive on the enable line is an immediate, hardware-level off.
use defmt::{assert_eq, Format};
use embassy_stm32::peripherals::{TIM1, TIM2};
use embassy_stm32::timer::low_level::{OutputCompareMode, Timer};
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Channel};
use embassy_stm32::Peri;
use saw_boards::BoardDef;
use saw_core::burst::TimerSettings;
use saw_core::gate::{BurstOutput, GateAction};

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
}

/// The burst timer driving the RF enable line (TIM2 CH1, 32-bit, PWM mode 1, preloaded).
pub struct BurstGate {
    tim: Timer<'static, TIM2>,
    _pin: PwmPin<'static, TIM2, Ch1>,
    running: bool,
    pub stats: BurstStats,
}

impl BurstGate {
    /// Configures the timer with the line held inactive and the counter stopped.
    pub fn new(tim: Peri<'static, TIM2>, pin: PwmPin<'static, TIM2, Ch1>, board: &BoardDef) -> Self {
        let t = Timer::new(tim);
        assert_eq!(t.get_clock_frequency().0, board.burst_timer_clk_hz);
        t.stop();
        // Line inactive before the output is even enabled.
        t.set_output_compare_mode(Channel::Ch1, OutputCompareMode::ForceInactive);
        // ARPE + OC1PE: PSC/ARR/CCR writes take effect at the next update event only.
        t.set_autoreload_preload(true);
        t.set_output_compare_preload(Channel::Ch1, true);
        t.enable_channel(Channel::Ch1, true);
        BurstGate { tim: t, _pin: pin, running: false, stats: BurstStats::default() }
    }

    fn write(&self, s: &TimerSettings) {
        let r = self.tim.regs_gp32();
        r.psc().write_value(s.psc);
        r.arr().write_value(s.arr);
        r.ccr(0).write_value(s.ccr);
    }

    /// Load, latch with UG, enable the counter: the first period starts whole at CNT = 0.
    fn start(&mut self, s: &TimerSettings) {
        self.tim.stop();
        self.write(s);
        self.tim.reset(); // CNT = 0
        self.tim.generate_update_event(); // latch PSC/ARR/CCR from preload
        self.tim.set_output_compare_mode(Channel::Ch1, OutputCompareMode::PwmMode1);
        self.tim.start();
        self.running = true;
    }

    /// Force the line inactive now (OC1M is not preloaded), then stop the counter.
    pub fn off(&mut self) {
        self.tim.set_output_compare_mode(Channel::Ch1, OutputCompareMode::ForceInactive);
        self.tim.stop();
        self.running = false;
    }

    pub fn is_running(&self) -> bool {
        self.running
    }
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
                if self.running {
                    // Preloaded: the running period finishes untouched.
                    self.write(&s);
                } else {
                    self.start(&s);
                }
                self.stats.updates = self.stats.updates.wrapping_add(1);
            }
        }
    }
}
