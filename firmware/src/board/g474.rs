//! NUCLEO-G474RE binding: RCC from `saw_boards::NUCLEO_G474RE`, pins, ADC acquisition.
//!
//! ADC: TIM3 TRGO (update, 10 kHz) triggers ADC1 (TIM3_TRGO external trigger); each trigger runs
//! the 32× hardware oversampler on the wiper (PA1 = ADC1_IN2) with shift 1, so DR holds the
//! sum of 32 conversions halved: the core's 16-conversion code (0..=65 520); DMA1 channel 1
//! (via DMAMUX) moves it into a circular buffer.
use embassy_stm32::adc::{vals, Adc, AdcChannel, AdcConfig, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{ADC1, DAC1, PA4, TIM1, TIM2, TIM3, TIM8};
use embassy_stm32::rcc::{mux, Hse, HseMode, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::MasterMode;
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch3};
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::{bind_interrupts, dma, flash, peripherals, Config, Peri, Peripherals};
use embassy_time::with_timeout;
use saw_boards::{BoardDef, OscSource, Oversampling, PllOut};
use static_cell::StaticCell;

use super::{AdcFault, Batch};

/// FLASHSIZE, the flash size data register (RM0440 §48.2).
pub const FLASH_SIZE_REG: u32 = 0x1FFF_75E0;

pub const BOARD: &BoardDef = &saw_boards::NUCLEO_G474RE;

const C: saw_boards::ClockPlan = BOARD.clocks;
const _: () = assert!(matches!(C.source, OscSource::HseCrystal));
const _: () = assert!(matches!(C.pll_out, PllOut::R));
const _: () = assert!(BOARD.clocks.is_valid() && BOARD.is_consistent());
// 150 MHz is the range-1 normal-mode limit: no boost mode needed.
const BOOST: bool = C.sysclk_hz > 150_000_000;

// G4 register encodings: PLLM = M - 1, PLLN = N, PLLR = R/2 - 1.
const PLLM: PllPreDiv = PllPreDiv::from_bits((C.pll_m - 1) as u8);
const PLLN: PllMul = PllMul::from_bits(C.pll_n as u8);
const PLLR: PllRDiv = PllRDiv::from_bits((C.pll_out_div / 2 - 1) as u8);
const _: () = assert!(matches!(PLLM, PllPreDiv::DIV6));
const _: () = assert!(matches!(PLLN, PllMul::MUL75));
const _: () = assert!(matches!(PLLR, PllRDiv::DIV2));

// Hardware oversampler (RM0440 §21.4.30; ADC_CFGR2 OVSR/OVSS, §21.7.5): OVSR = log2(ratio) − 1
// (0b000 = 2×, 0b100 = 32×, 0b111 = 256×), OVSS = the right shift in bits, rounding to nearest.
// The board's 32 conversions shifted by 1: OVSR = 4, OVSS = 1, DR = (Σ32 + 1) >> 1.
const OVS: (u8, u8) = match BOARD.adc.oversampling {
    Oversampling::Hardware { ratio, shift }
        if Oversampling::is_hardware_ratio(ratio) && shift <= 8 =>
    {
        ((ratio.trailing_zeros() - 1) as u8, shift as u8)
    }
    _ => panic!("G474 binding expects the hardware oversampler, ratio 2..=256, shift <= 8"),
};
const _: () = assert!(OVS.0 == 4 && OVS.1 == 1);

/// Embassy configuration: HSE 24 MHz crystal → PLL (M 6, N 75, R 2) → SYSCLK 150 MHz,
/// AHB/APB1/APB2 /1 (all timers 150 MHz), ADC12 kernel clock = SYSCLK.
fn rcc_config() -> Config {
    let mut config = Config::default();
    config.rcc.hse = Some(Hse { freq: Hertz(C.osc_hz), mode: HseMode::Oscillator });
    config.rcc.pll =
        Some(Pll { source: PllSource::HSE, prediv: PLLM, mul: PLLN, divp: None, divq: None, divr: Some(PLLR) });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = BOOST;
    config.rcc.ahb_pre = super::ahb_pre(C.ahb_div);
    config.rcc.apb1_pre = super::apb_pre(C.apb1_div);
    config.rcc.apb2_pre = super::apb_pre(C.apb2_div);
    config.rcc.mux.adc12sel = mux::Adcsel::SYS;
    config
}

/// embassy init with [`rcc_config`]. Nothing to add for the flash: FLASH_ACR resets with ICEN
/// and DCEN set and embassy's G4 RCC code only modifies LATENCY (RM0440 FLASH_ACR; embassy-stm32
/// 0.6 rcc/g4.rs). Prefetch stays off, as in ST's G4 defaults.
///
/// None if the crystal does not start in time (`super::start_hse`): HSI16 is ±1 % at 25 °C
/// (DS12288), not an exact 15 MHz carrier; the caller refuses to run (RF off, a log line).
pub fn init() -> Option<Peripherals> {
    if !super::start_hse(false) {
        return None;
    }
    Some(embassy_stm32::init(rcc_config()))
}

/// What HSE is on this board, for the log line of a board that never got it.
pub const HSE_SOURCE: &str = "the 24 MHz crystal X3 (UM2505 §7.7.1)";

/// Clocks for the GPIO ports of the RF lines (PA0, PB10, PB5) when embassy never ran:
/// RCC_AHB2ENR.GPIOAEN/GPIOBEN (RM0440 §7.4.16); writes to an unclocked port are ignored.
pub fn enable_rf_gpio_clocks() {
    pac::RCC.ahb2enr().modify(|w| {
        w.set_gpioaen(true);
        w.set_gpioben(true);
    });
}

/// Fault path only, after RF is off: with a debugger attached (DHCSR.C_DEBUGEN, ARMv7-M ARM
/// C1.6.2) stop the IWDG while the core is halted (RM0440 DBG chapter, DBGMCU_APB1FZR1.DBG_IWDG_STOP), so the watchdog does
/// not reset the chip under probe-rs's backtrace. Never at boot: a CPU halted mid-burst must
/// still be reset.
pub fn freeze_watchdog_if_debugged() {
    if cortex_m::peripheral::DCB::is_debugger_attached() {
        pac::DBGMCU.apb1lfzr().modify(|w| w.set_iwdg(true));
    }
}

bind_interrupts!(struct Irqs {
    DMA1_CHANNEL1 => dma::InterruptHandler<peripherals::DMA1_CH1>;
    LPUART1 => usart::InterruptHandler<peripherals::LPUART1>;
    DMA1_CHANNEL3 => dma::InterruptHandler<peripherals::DMA1_CH3>;
    DMA1_CHANNEL2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
    FLASH => flash::InterruptHandler;
});

/// The link's receive ring: 1 KiB is 11 ms of bytes at 921 600 baud, longer than the link task
/// ever waits (a scene's compile), so a request is never overrun.
const LINK_RX_BYTES: usize = 1024;
static LINK_RX: StaticCell<[u8; LINK_RX_BYTES]> = StaticCell::new();

/// The saved scene's flash: embassy's bank 2 region (dual-bank mode: 128 pages of 2 KiB from
/// 0x0804_0000, RM0440 §5.3.1); the store uses its last 8 pages (`BOARD.store`).
pub type StoreFlash = flash::Bank2Region<'static, flash::Async>;

/// Only in dual-bank mode (FLASH_OPTR.DBANK = 1, the factory setting; RM0440 §5.3.1). With
/// DBANK = 0 there is no bank 2 (one bank of 4 KiB pages) and embassy's `dual-bank` driver would
/// panic: the board then runs without a store and says so.
fn store_flash(p: Peri<'static, peripherals::FLASH>) -> Option<StoreFlash> {
    const _: () = assert!(BOARD.store.region_base == 0x0804_0000);
    if !super::store_fits() {
        return None;
    }
    if !pac::FLASH.optr().read().dbank() {
        defmt::warn!("store: the flash is in single-bank mode (FLASH_OPTR.DBANK = 0); no store");
        return None;
    }
    Some(flash::Flash::new(p, Irqs).into_regions().bank2_region)
}

/// Peripherals bound to their roles.
pub struct Parts {
    pub carrier_tim: Peri<'static, TIM1>,
    pub carrier_pin: PwmPin<'static, TIM1, Ch1>,
    pub burst_tim: Peri<'static, TIM2>,
    pub burst_pin: PwmPin<'static, TIM2, Ch1>,
    pub burst_b_pin: PwmPin<'static, TIM2, Ch3>,
    pub rf_arm: Output<'static>,
    #[cfg(not(feature = "touch-2d"))]
    pub sampler: Sampler,
    /// The 4-wire overlay's ADC, DMA, timer and pins (the 2D image).
    #[cfg(feature = "touch-2d")]
    pub touch: crate::touch2d::Acquisition,
    pub iwdg: Peri<'static, peripherals::IWDG>,
    /// The saved scene's flash (None: this board has no usable store).
    pub store: Option<StoreFlash>,
    /// The host link's transmitter.
    pub link_tx: UartTx<'static, Async>,
    /// The host link's receiver, DMA into a ring buffer.
    pub link_rx: RingBufferedUartRx<'static>,
    /// The RF level: envelope timer, DAC, its pin (PA4) and the envelope DMA.
    pub envelope_tim: Peri<'static, TIM8>,
    pub dac: Peri<'static, DAC1>,
    pub dac_pin: Peri<'static, PA4>,
    pub envelope_dma: EnvelopeDma,
}

pub fn split(p: Peripherals) -> Parts {
    let rf_arm = Output::new(p.PB5, Level::Low, Speed::Low);
    // PA0: TIM2_CH1 AF1 (burst / RF enable).
    let burst_pin = PwmPin::new(p.PA0, OutputType::PushPull);
    // PA8: TIM1_CH1 AF6 (15 MHz carrier).
    let carrier_pin = PwmPin::new(p.PA8, OutputType::PushPull);
    // PB10: TIM2_CH3 AF1 (second RF enable, IDT B).
    let burst_b_pin = PwmPin::new(p.PB10, OutputType::PushPull);
    #[cfg(not(feature = "touch-2d"))]
    let sampler = Sampler::new(p.ADC1, p.PA1, p.DMA1_CH1, p.TIM3);
    #[cfg(feature = "touch-2d")]
    let touch = crate::touch2d::Acquisition {
        adc: p.ADC1,
        dma: p.DMA1_CH1,
        tim: p.TIM3,
        pins: [p.PC2.into(), p.PC3.into(), p.PB0.into(), p.PB1.into()],
    };
    let store = store_flash(p.FLASH);
    // The link: LPUART1 on PA2 (TX) / PA3 (RX), AF12, wired to the STLINK-V3E's virtual COM port
    // (UM2505 §7.9 "Virtual COM port (VCP)"). DMA1 channels 3 (TX) and 2 (RX) through the DMAMUX
    // (RM0440 §13.3.2); channel 1 is the ADC's.
    let mut cfg = usart::Config::default();
    cfg.baudrate = crate::link::BAUD;
    let uart = defmt::unwrap!(Uart::new(p.LPUART1, p.PA3, p.PA2, p.DMA1_CH3, p.DMA1_CH2, Irqs, cfg));
    let (link_tx, rx) = uart.split();
    let link_rx = rx.into_ring_buffered(LINK_RX.init([0; LINK_RX_BYTES]));
    Parts {
        carrier_tim: p.TIM1,
        carrier_pin,
        burst_tim: p.TIM2,
        burst_pin,
        burst_b_pin,
        rf_arm,
        #[cfg(not(feature = "touch-2d"))]
        sampler,
        #[cfg(feature = "touch-2d")]
        touch,
        iwdg: p.IWDG,
        store,
        link_tx,
        link_rx,
        envelope_tim: p.TIM8,
        dac: p.DAC1,
        dac_pin: p.PA4,
        envelope_dma: EnvelopeDma::new(p.DMA1_CH4),
    }
}

/// Where the envelope DMA is, for the boot log.
pub const ENVELOPE_DMA: &str = "DMA1 channel 4 via DMAMUX1 channel 3, request 49 (TIM8_CH1)";

/// The channel that plays a triangle envelope into DAC_DHR12R1: DMA1 channel 4 (PAC index 3),
/// fed by DMAMUX1 channel 3 (DMAMUX channels 0–7 serve DMA1 channels 1–8, RM0440 §13.3.2) with
/// request 49 = TIM8_CH1 (RM0440 DMAMUX chapter, §13.3.2 request table; metapac's G474 data: TIM8 CH1 request 49).
/// DMA1 channel 1 is the ADC's, channels 2 and 3 the link's (LPUART1 RX/TX).
pub struct EnvelopeDma {
    _ch: Peri<'static, peripherals::DMA1_CH4>,
}

const ENV_CH: usize = 3;
const ENV_MUX_CH: usize = 3;
const ENV_REQUEST_TIM8_CH1: u8 = 49;

impl EnvelopeDma {
    /// Routes TIM8_CH1's request to the channel once (DMAMUX1_C3CR: DMAREQ_ID = 49, no
    /// synchronization, no event generation; RM0440 DMAMUX_CxCR). DMA and DMAMUX clocks are on
    /// (embassy's init enables every DMA controller and the DMAMUX).
    fn new(ch: Peri<'static, peripherals::DMA1_CH4>) -> Self {
        pac::DMAMUX1.ccr(ENV_MUX_CH).write(|w| {
            w.set_dmareq_id(ENV_REQUEST_TIM8_CH1);
            w.set_nbreq(0);
            w.set_ege(false);
        });
        EnvelopeDma { _ch: ch }
    }

    /// EN = 0 (RM0440 DMA_CCRx.EN: the channel stops; CNDTR, CPAR and CMAR become
    /// writable). Read back until 0, as the F446's stream needs, so both boards share one
    /// sequence.
    pub fn stop(&mut self) {
        let c = pac::DMA1.ch(ENV_CH);
        c.cr().modify(|w| w.set_en(false));
        while c.cr().read().en() {}
    }

    /// Memory → peripheral, `src` (16-bit entries) to the 16-bit register at `dst`: one entry
    /// per TIM8 CC1 request, normal mode (the channel stops requesting after the last, CNDTR =
    /// 0). Programmed with EN = 0 (after `stop`), the channel's flags cleared (CGIF), then EN
    /// (RM0440 §12.4 "Channel configuration procedure"). No interrupt.
    pub fn arm(&mut self, src: &[u16], dst: u32) {
        use pac::bdma::vals;
        let (dma, ch) = (pac::DMA1, ENV_CH);
        let c = dma.ch(ch);
        dma.ifcr().write(|w| w.set_gif(ch, true));
        c.par().write_value(dst);
        c.mar().write_value(src.as_ptr() as u32);
        c.ndtr().write(|w| w.set_ndt(src.len() as u16));
        c.cr().write(|w| {
            w.set_dir(vals::Dir::FROM_MEMORY);
            w.set_msize(vals::Size::BITS16);
            w.set_psize(vals::Size::BITS16);
            w.set_minc(true);
            w.set_pinc(false);
            w.set_circ(false);
            w.set_mem2mem(false);
            w.set_pl(vals::Pl::HIGH);
        });
        c.cr().modify(|w| w.set_en(true));
    }
}

/// DAC1 channel 1: normal mode, external pin, buffer on (DAC_MCR.MODE1 = 000), and the
/// high-frequency interface mode HCLK needs above 80 MHz (DAC_MCR.HFSEL = 01 up to 160 MHz;
/// RM0440 DAC_MCR; embassy's DAC driver picks the same). MODE1 may only be written while
/// EN1 = 0.
pub fn dac_configure() {
    const _: () = assert!(BOARD.clocks.hclk_hz() > 80_000_000 && BOARD.clocks.hclk_hz() <= 160_000_000);
    pac::DAC1.mcr().modify(|w| {
        w.set_hfsel(0b01);
        w.set_mode(0, pac::dac::vals::Mode::NORMAL_EXT_BUFEN);
    });
}

/// DAC_SR.DAC1RDY rises once the channel is ready after EN1 (RM0440 DAC_SR). Bounded at 50 µs
/// (t_WAKEUP is a few µs, DS12288), so a chip or model that never sets it cannot hang the boot.
pub fn dac_wait_ready() {
    let sr = pac::DAC1.sr();
    let mut left = 50 * (BOARD.sysclk_hz / 1_000_000) / 10;
    while !sr.read().dacrdy(0) && left > 0 {
        cortex_m::asm::delay(10);
        left -= 1;
    }
}

/// Sampling time against the rheostat's source impedance. No rheostat value is stated in
/// boards/README.md or saw-boards; assumed: a 10 kΩ linear slide potentiometer wired as a divider
/// (core/src/position.rs), whose Thevenin resistance peaks at R/4 = 2.5 kΩ mid-travel. Datasheet
/// bound (STM32G474 DS12288, ADC characteristics): R_AIN < (k − 0.5) / (f_ADC · C_ADC ·
/// ln 2^(N+2)) − R_ADC for k sampling cycles, N = 12 (ln 2^14 = 9.70), C_ADC = 5 pF, f_ADC =
/// 150 MHz / 4 = 37.5 MHz (embassy's PRESC for ≤ 60 MHz). 24.5 cycles (653 ns): < 13.2 kΩ −
/// R_ADC by the formula, but the datasheet's "maximum ADC R_AIN" table (which includes pad and
/// parasitics; values from memory, not re-checked here) puts ~650 ns near 2 kΩ — no margin for
/// 2.5 kΩ. 47.5 cycles (1.27 µs): < 25.8 kΩ − R_ADC by the formula, < 14.3 kΩ with the 11.5 kΩ
/// the conversion budget fits to that table (¼ LSB there; the budget's ½-LSB rule leaves 24.5
/// cycles 3.5 % to spare); twice the 631 ns its settling rule needs at 2.5 kΩ
/// (docs/conversion-budget.md).
/// 32 × (47.5 + 12.5) cycles = 51.2 µs per trigger, inside the 100 µs period: the conversion
/// budget's G474 default (it was 16 conversions at 92.5 cycles, 44.8 µs: the same lag at √2
/// times this noise). The board model times it (`scripts/board-model.sh`: sensor-to-gate
/// latency and the rail fault's response, both against 100 µs).
const SAMPLE_TIME: SampleTime = match BOARD.adc.sample_half_cycles {
    95 => SampleTime::CYCLES47_5,
    185 => SampleTime::CYCLES92_5,
    49 => SampleTime::CYCLES24_5,
    _ => panic!("G474 binding: a sampling time this board plan does not use"),
};
const CONVERSIONS: u32 = BOARD.adc.oversampling.conversions();
// One trigger's conversions, (sampling + 12.5 SAR cycles) each at SYSCLK / 4, fit the period
// (RM0440 §21.4.12 sampling time, §21.4.16 t_CONV = t_SMPL + 12.5 cycles at 12 bits). In u64:
// 64 × 92.5 cycles would overflow u32 here before the comparison could refuse it.
const _: () = assert!(
    CONVERSIONS as u64 * (BOARD.adc.sample_half_cycles as u64 + 25) / 2 * 1_000_000
        / (BOARD.sysclk_hz as u64 / 4)
        < 1_000_000 / BOARD.sample_rate_hz as u64
);

/// Samples delivered per `read` (each is one trigger = 32 oversampled conversions).
pub const SAMPLES_PER_READ: usize = 2;
const DMA_LEN: usize = 2 * SAMPLES_PER_READ;
/// DMA1 channel index of `DMA1_CH1` (channel 1 in RM0440 numbering is index 0 in the PAC).
const DMA_CH: usize = 0;
static DMA_BUF: StaticCell<[u16; DMA_LEN]> = StaticCell::new();

/// Timer-triggered, hardware-oversampled, DMA-fed rheostat acquisition.
pub struct Sampler {
    adc: RingBufferedAdc<'static, ADC1>,
    trigger: Timer<'static, TIM3>,
}

impl Sampler {
    fn new(
        adc: Peri<'static, ADC1>,
        pin: Peri<'static, peripherals::PA1>,
        dma: Peri<'static, peripherals::DMA1_CH1>,
        tim: Peri<'static, TIM3>,
    ) -> Self {
        let mut cfg = AdcConfig::default();
        cfg.oversampling_ratio = Some(OVS.0);
        cfg.oversampling_shift = Some(OVS.1);
        // Regular oversampling, all 32 conversions done after a single trigger (TROVS = 0),
        // continued mode (ROVSM = 0).
        cfg.oversampling_mode = Some((vals::Rovsm::CONTINUED, vals::Trovs::AUTOMATIC, true));
        // The EXTSEL code documented in saw-boards must be the one embassy uses for TIM3_TRGO.
        defmt::assert_eq!(
            embassy_stm32::adc::RegularTrigger::<ADC1>::signal(&embassy_stm32::triggers::TIM3_TRGO),
            BOARD.adc.trigger_extsel
        );
        let adc = Adc::new(adc, cfg);
        let buf = DMA_BUF.init([0; DMA_LEN]);
        let adc = adc.into_ring_buffered(
            dma,
            buf,
            Irqs,
            [(pin.degrade_adc(), SAMPLE_TIME)].into_iter(),
            embassy_stm32::triggers::TIM3_TRGO,
            Exten::RISING_EDGE,
        );
        let trigger = trigger_timer(tim);
        Sampler { adc, trigger }
    }

    /// A dummy conversion, then arm DMA + ADC, then start the trigger timer: the first
    /// conversions land in a running ring buffer. Call from the task that reads, right before
    /// the first `read`.
    pub fn start(&mut self) {
        dummy_conversion();
        self.adc.start();
        self.trigger.start();
    }

    /// Wait for the next samples (each already the 16-conversion code: 32 conversions summed
    /// and halved). On an overrun or a stall the acquisition is restarted before this returns
    /// the fault.
    pub async fn read(&mut self) -> Result<Batch, AdcFault> {
        let mut codes = [0u16; SAMPLES_PER_READ];
        let fault = match with_timeout(super::READ_TIMEOUT, self.adc.read(&mut codes)).await {
            Ok(Ok(remaining)) => return Ok(Batch { codes, backlog: remaining as u32 }),
            Ok(Err(_)) => AdcFault::Overrun,
            Err(_) => AdcFault::Stalled,
        };
        self.restart();
        Err(fault)
    }

    /// Recovery from an ADC overrun (with DMA the requests stay blocked until OVR is cleared;
    /// RM0440 ADC chapter, "ADC overrun (OVR, OVRMOD)" and "Managing conversions using the DMA"),
    /// also used after a ring-buffer lap or a stall: ADSTP (aborts the oversampled conversion,
    /// clears ADSTART, so triggers are ignored from here on), channel stopped and reloaded with
    /// the whole buffer, flags cleared, DMAEN toggled (writable only while ADSTART = 0), ring
    /// buffer emptied, then `start`: ADSTART = 1 arms the next TIM3 trigger. TIM3 keeps running.
    fn restart(&mut self) {
        let adc = pac::ADC1;
        let cr = adc.cr().read();
        if cr.adstart() {
            // ADC_CR's other rs bits (ADEN, ADSTART, ...) written as 0 (no effect), as ST's LL
            // driver does: only ADVREGEN and ADCALDIF carry over.
            adc.cr().write(|w| {
                w.set_advregen(cr.advregen());
                w.set_adcaldif(cr.adcaldif());
                w.set_adstp(vals::Adstp::STOP);
            });
            while adc.cr().read().adstart() {}
        }
        // Channel EN = 0.
        self.adc.stop();
        // RM0440 DMA chapter, channel configuration: CNDTR is writable only while EN = 0; the
        // full length puts the channel back at the buffer's start, where `clear` puts the ring
        // buffer's indices. CGIF clears all of the channel's flags.
        let dma = pac::DMA1;
        dma.ifcr().write(|w| w.set_gif(DMA_CH, true));
        dma.ch(DMA_CH).ndtr().write(|w| w.set_ndt(DMA_LEN as u16));
        // ISR flags are rc_w1.
        adc.isr().write(|w| {
            w.set_ovr(true);
            w.set_eoc(true);
            w.set_eos(true);
        });
        adc.cfgr().modify(|w| w.set_dmaen(vals::Dmaen::DISABLE));
        adc.cfgr().modify(|w| w.set_dmaen(vals::Dmaen::ENABLE));
        self.adc.clear();
        self.start();
    }
}

/// ES0430 (STM32G47x/48x errata), "Wrong ADC result if conversion done late after calibration
/// or previous conversion": a conversion more than 1 ms after the calibration or the previous
/// conversion may be wrong; the workaround is a conversion whose result is thrown away. The
/// sampler converts every 100 µs, so only the first trigger after `start` — at boot after the
/// calibration, and after every restart — is late: one software-triggered sequence is converted
/// here and discarded, and the first TIM3 trigger comes one period later. With DMAEN = 0 the
/// result raises no DMA request (it would land in the ring buffer once the channel runs), and
/// with EXTEN = 0 ADSTART starts it at once and clears itself at its end of sequence (RM0440
/// §21.4.15 "Starting conversions", §21.4.18 single mode); CFGR (writable only while ADSTART =
/// 0, §21.7.4) is then put back as embassy set it. 32 conversions of 60 cycles at 37.5 MHz:
/// ~51 µs of busy wait, at boot and after a restart only.
fn dummy_conversion() {
    let adc = pac::ADC1;
    let cfgr = adc.cfgr().read();
    adc.cfgr().modify(|w| {
        w.set_dmaen(vals::Dmaen::DISABLE);
        w.set_exten(Exten::DISABLED);
        w.set_cont(false);
    });
    // ADSTART set with ADC_CR's other rs bits written 0 (RM0440 §21.7.3: ADEN may be written 1
    // only while every other bit but ADVREGEN and ADCALDIF is 0), as ST's
    // `LL_ADC_REG_StartConversion` does and `restart` below: a read-modify-write would write
    // ADEN's 1 back while the ADC is enabled.
    let cr = adc.cr().read();
    adc.cr().write(|w| {
        w.set_advregen(cr.advregen());
        w.set_adcaldif(cr.adcaldif());
        w.set_adstart(true);
    });
    while adc.cr().read().adstart() {}
    let _ = adc.dr().read();
    // ISR flags are rc_w1.
    adc.isr().write(|w| {
        w.set_ovr(true);
        w.set_eoc(true);
        w.set_eos(true);
        w.set_eosmp(true);
    });
    adc.cfgr().write_value(cfgr);
}

/// TIM3: `sample_rate_hz` period, TRGO = update event; started by `Sampler::start`. Its UG
/// (in `set_max_compare_value`, a TRGO pulse while MMS = 000) cannot start a conversion here:
/// the G474 ADC only accepts hardware triggers while ADSTART = 1 (RM0440 ADC chapter, "Conversion
/// on external trigger"), which only `start` sets.
fn trigger_timer(tim: Peri<'static, TIM3>) -> Timer<'static, TIM3> {
    let (psc, arr) = BOARD.adc_trigger_psc_arr();
    let t = Timer::new(tim);
    defmt::assert_eq!(t.get_clock_frequency().0, BOARD.adc.trigger_timer_clk_hz);
    t.regs_core().psc().write_value(psc as u16);
    t.set_max_compare_value(arr as u16);
    t.set_master_mode(MasterMode::UPDATE);
    t
}
