//! NUCLEO-F446RE binding: RCC from `saw_boards::NUCLEO_F446RE`, pins, ADC acquisition.
//!
//! ADC: TIM3 TRGO (update, 10 kHz) triggers ADC1 (EXTSEL 8 = TIM3_TRGO); one trigger runs a
//! 16-rank regular sequence that converts the wiper (PA1 = IN1) 16 times; DMA2 stream 0 moves
//! the 16 results into a circular buffer; the sampler task sums them into one 16-bit sample.
#[cfg(not(feature = "dual-adc"))]
use embassy_stm32::adc::{Adc, AdcChannel, Exten, RingBufferedAdc, SampleTime};
use embassy_stm32::gpio::{Level, Output, OutputType, Speed};
use embassy_stm32::pac;
#[cfg(not(feature = "dual-adc"))]
use embassy_stm32::peripherals::ADC1;
use embassy_stm32::peripherals::{DAC1, PA4, TIM1, TIM2, TIM3, TIM8};
use embassy_stm32::rcc::{Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllSource, Sysclk};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::MasterMode;
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{Ch1, Ch3};
use embassy_stm32::mode::Async;
use embassy_stm32::usart::{self, RingBufferedUartRx, Uart, UartTx};
use embassy_stm32::{bind_interrupts, dma, flash, peripherals, Config, Peri, Peripherals};
#[cfg(not(feature = "dual-adc"))]
use embassy_time::with_timeout;
use saw_boards::{BoardDef, OscSource, PllOut};
use static_cell::StaticCell;

#[cfg(not(feature = "dual-adc"))]
use super::{AdcFault, Batch};

/// FLASHSIZE, the flash size data register (RM0390 §39.2).
pub const FLASH_SIZE_REG: u32 = 0x1FFF_7A22;

#[cfg(not(feature = "dual-adc"))]
pub const BOARD: &BoardDef = &saw_boards::NUCLEO_F446RE;
/// `dual-adc`: ADC1 + ADC2 interleaved on the wiper (`f446_dual.rs`).
#[cfg(all(feature = "dual-adc", not(feature = "dual-adc-128")))]
pub const BOARD: &BoardDef = &saw_boards::NUCLEO_F446RE_DUAL;
/// `dual-adc-128`: the same at 128 conversions per sample (four triggers), an experiment.
#[cfg(feature = "dual-adc-128")]
pub const BOARD: &BoardDef = &saw_boards::NUCLEO_F446RE_DUAL128;

// The dual interleaved acquisition replaces the single-ADC one below (every item of which is
// `cfg(not(feature = "dual-adc"))`).
#[cfg(all(feature = "dual-adc", feature = "touch-2d"))]
compile_error!("touch-2d replaces the wiper's acquisition: not with dual-adc");
#[cfg(feature = "dual-adc")]
#[path = "f446_dual.rs"]
mod dual;
#[cfg(feature = "dual-adc")]
pub use dual::{Sampler, SAMPLES_PER_READ};

// The numbers below are what the embassy RCC config is built from; make sure the plan is the one
// this file knows how to express (HSE bypass, PLL P output).
const C: saw_boards::ClockPlan = BOARD.clocks;
const _: () = assert!(matches!(C.source, OscSource::HseBypass));
const _: () = assert!(matches!(C.pll_out, PllOut::P));
const _: () = assert!(BOARD.clocks.is_valid() && BOARD.is_consistent());

// F4 register encodings: PLLM = M, PLLN = N, PLLP = P/2 - 1.
const PLLM: PllPreDiv = PllPreDiv::from_bits(C.pll_m as u8);
const PLLN: PllMul = PllMul::from_bits(C.pll_n as u16);
const PLLP: PllPDiv = PllPDiv::from_bits((C.pll_out_div / 2 - 1) as u8);
const _: () = assert!(matches!(PLLM, PllPreDiv::DIV4));
const _: () = assert!(matches!(PLLN, PllMul::MUL180));
const _: () = assert!(matches!(PLLP, PllPDiv::DIV2));

/// Embassy configuration: HSE 8 MHz bypass → PLL (M 4, N 180, P 2) → SYSCLK 180 MHz,
/// AHB /1, APB1 /4 (timers 90 MHz), APB2 /2 (timers 180 MHz). Over-drive is enabled by embassy.
fn rcc_config() -> Config {
    let mut config = Config::default();
    config.rcc.hse = Some(Hse { freq: Hertz(C.osc_hz), mode: HseMode::Bypass });
    config.rcc.pll_src = PllSource::HSE;
    config.rcc.pll = Some(Pll { prediv: PLLM, mul: PLLN, divp: Some(PLLP), divq: None, divr: None });
    config.rcc.sys = Sysclk::PLL1_P;
    config.rcc.ahb_pre = super::ahb_pre(C.ahb_div);
    config.rcc.apb1_pre = super::apb_pre(C.apb1_div);
    config.rcc.apb2_pre = super::apb_pre(C.apb2_div);
    config
}

/// embassy init with [`rcc_config`], then the flash accelerator. embassy's F4 RCC code writes
/// FLASH_ACR whole (`FLASH.acr().write(|w| w.set_latency(..))`, embassy-stm32 0.6 rcc/f247.rs),
/// which leaves prefetch and both ART caches off (their reset state too): at 180 MHz and 5 wait
/// states every flash fetch would stall. Caches are reset while disabled, then ICEN, DCEN and
/// PRFTEN set (RM0390 §3.4.2 ART accelerator, §3.8.1 FLASH_ACR).
///
/// None if HSE is not ready in time (`super::start_hse`): the board has no exact clock. HSI is
/// no substitute: its factory trim is ±1 % at 25 °C and −8/+4.5 % over temperature (DS10693,
/// HSI oscillator characteristics), so the carrier would be 15 MHz ± 150 kHz or worse, off the
/// transducer's frequency; the caller refuses to run (RF off, a log line).
pub fn init() -> Option<Peripherals> {
    if !super::start_hse(true) {
        return None;
    }
    let p = embassy_stm32::init(rcc_config());
    reset_flash_caches(true, true);
    pac::FLASH.acr().modify(|w| w.set_prften(true));
    Some(p)
}

/// Resets both ART caches, then turns each on or off as asked: RM0390 §3.8.1 FLASH_ACR — ICRST
/// (bit 11) and DCRST (bit 12) reset a cache only while it is disabled (ICEN bit 9, DCEN bit
/// 10 = 0), so both off, reset set, reset cleared, then the enables (ST's FLASH_FlushCaches).
/// At boot, and after every store erase (`store.rs`: a stale data-cache line would return the
/// erased sector's old bytes).
pub fn reset_flash_caches(icen: bool, dcen: bool) {
    let acr = pac::FLASH.acr();
    acr.modify(|w| {
        w.set_icen(false);
        w.set_dcen(false);
    });
    acr.modify(|w| {
        w.set_icrst(true);
        w.set_dcrst(true);
    });
    acr.modify(|w| {
        w.set_icrst(false);
        w.set_dcrst(false);
    });
    acr.modify(|w| {
        w.set_icen(icen);
        w.set_dcen(dcen);
    });
}

/// What HSE is on this board, for the log line of a board that never got it.
pub const HSE_SOURCE: &str = "the ST-LINK's 8 MHz MCO on OSC_IN: SB50/SB16 closed, the ST-LINK powered (UM1724 §6.7)";

/// Clocks for the GPIO ports of the RF lines (PA0, PB10, PB5) when embassy never ran:
/// RCC_AHB1ENR.GPIOAEN/GPIOBEN (RM0390 §6.3.10); writes to an unclocked port are ignored.
pub fn enable_rf_gpio_clocks() {
    pac::RCC.ahb1enr().modify(|w| {
        w.set_gpioaen(true);
        w.set_gpioben(true);
    });
}

/// Fault path only, after RF is off: with a debugger attached (DHCSR.C_DEBUGEN, ARMv7-M ARM
/// C1.6.2) stop the IWDG while the core is halted (RM0390 DBG chapter, DBGMCU_APB1_FZ.DBG_IWDG_STOP), so the watchdog does
/// not reset the chip under probe-rs's backtrace. Never at boot: a CPU halted mid-burst must
/// still be reset.
pub fn freeze_watchdog_if_debugged() {
    if cortex_m::peripheral::DCB::is_debugger_attached() {
        pac::DBGMCU.apb1fzr().modify(|w| w.set_iwdg(true));
    }
}

bind_interrupts!(struct Irqs {
    DMA2_STREAM0 => dma::InterruptHandler<peripherals::DMA2_CH0>;
    USART2 => usart::InterruptHandler<peripherals::USART2>;
    DMA1_STREAM6 => dma::InterruptHandler<peripherals::DMA1_CH6>;
    DMA1_STREAM5 => dma::InterruptHandler<peripherals::DMA1_CH5>;
    FLASH => flash::InterruptHandler;
});

/// The saved scene's flash: embassy's region 3 of bank 1 (sectors 5–7, 128 KiB each, RM0390
/// §3.3 table 4); the store uses sectors 6–7 (`BOARD.store`), addressed from the region's start.
pub type StoreFlash = flash::Bank1Region3<'static, flash::Async>;

fn store_flash(p: Peri<'static, peripherals::FLASH>) -> Option<StoreFlash> {
    const _: () = assert!(BOARD.store.region_base == 0x0802_0000);
    if !super::store_fits() {
        return None;
    }
    Some(flash::Flash::new(p, Irqs).into_regions().bank1_region3)
}

/// The link's receive ring: 1 KiB is 11 ms of bytes at 921 600 baud, longer than the link task
/// ever waits (a scene's compile), so a request is never overrun.
const LINK_RX_BYTES: usize = 1024;
static LINK_RX: StaticCell<[u8; LINK_RX_BYTES]> = StaticCell::new();

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
    // RF arm first and low: nothing can reach the amplifier until main says so.
    let rf_arm = Output::new(p.PB5, Level::Low, Speed::Low);
    // PA0: TIM2_CH1 AF1 (burst / RF enable). PwmPin::new drives the pin low before switching
    // it to AF, and the channel is held at force-inactive until the first Start.
    let burst_pin = PwmPin::new(p.PA0, OutputType::PushPull);
    // PA8: TIM1_CH1 AF1 (15 MHz carrier).
    let carrier_pin = PwmPin::new(p.PA8, OutputType::PushPull);
    // PB10: TIM2_CH3 AF1 (second RF enable, IDT B).
    let burst_b_pin = PwmPin::new(p.PB10, OutputType::PushPull);
    #[cfg(not(any(feature = "dual-adc", feature = "touch-2d")))]
    let sampler = Sampler::new(p.ADC1, p.PA1, p.DMA2_CH0, p.TIM3);
    #[cfg(feature = "touch-2d")]
    let touch = crate::touch2d::Acquisition {
        adc: p.ADC1,
        dma: p.DMA2_CH0,
        tim: p.TIM3,
        pins: [p.PC2.into(), p.PC3.into(), p.PB0.into(), p.PB1.into()],
    };
    #[cfg(feature = "dual-adc")]
    let sampler = Sampler::new(p.ADC1, p.ADC2, p.PA1, p.DMA2_CH0, p.TIM3);
    // The link: USART2 on PA2 (TX) / PA3 (RX), AF7, wired to the ST-LINK/V2-1's virtual COM port
    // (UM1724 §6.8 "USART communication": SB13/SB14 closed by default). DMA1 stream 6 channel 4
    // transmits, stream 5 channel 4 receives into a ring buffer (RM0390 §9.3.3 Table 28).
    let mut cfg = usart::Config::default();
    cfg.baudrate = crate::link::BAUD;
    let uart = defmt::unwrap!(Uart::new(p.USART2, p.PA3, p.PA2, p.DMA1_CH6, p.DMA1_CH5, Irqs, cfg));
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
        store: store_flash(p.FLASH),
        link_tx,
        link_rx,
        envelope_tim: p.TIM8,
        dac: p.DAC1,
        dac_pin: p.PA4,
        envelope_dma: EnvelopeDma { _stream: p.DMA2_CH2 },
    }
}

/// Where the envelope DMA is, for the boot log.
pub const ENVELOPE_DMA: &str = "DMA2 stream 2 channel 7";

/// The stream that plays a triangle envelope into DAC_DHR12R1: DMA2 stream 2, channel 7 =
/// TIM8_CH1 (RM0390 §9.3.3 table 29, DMA2 request mapping; metapac's F446 data lists TIM8 CH1
/// on DMA2_CH2 with requests 0 (the shared TIM8_CH1/CH2/CH3 request) and 7 (TIM8_CH1 alone)).
/// Free here: DMA2 stream 0 is the ADC's, DMA1 streams 5/6 the link's, and the DAC's own
/// requests (DMA1 streams 5/6, table 28) collide with the link, which is why TIM8 paces the
/// table. DMA2's peripheral port reaches APB1, where the DAC sits, through the bus matrix
/// (RM0390 §2.1 "System architecture", bus matrix figure; DMA1's peripheral port could
/// not).
pub struct EnvelopeDma {
    _stream: Peri<'static, peripherals::DMA2_CH2>,
}

const ENV_STREAM: usize = 2;
const ENV_CHSEL: u8 = 7;

impl EnvelopeDma {
    /// EN = 0, then wait until it reads 0: the stream finishes the transfer in progress first
    /// (RM0390 §9.5.5 DMA_SxCR.EN; §9.3 "Stream configuration procedure", step 1).
    pub fn stop(&mut self) {
        let st = pac::DMA2.st(ENV_STREAM);
        st.cr().modify(|w| w.set_en(false));
        while st.cr().read().en() {}
    }

    /// Memory → peripheral, `src` (16-bit entries) to the 16-bit register at `dst`: one entry
    /// per TIM8 CC1 request, normal mode (the stream disables itself after the last, NDTR = 0).
    /// Programmed in the order of RM0390 §9.3 "Stream configuration procedure" with EN = 0 (after `stop`), the stream's
    /// flags cleared before EN (§9.5.3 DMA_LIFCR; the procedure: EN with a flag set does not start). Direct
    /// mode (FIFO off, §9.3 "Direct mode"): sizes are equal; in memory → peripheral the stream fetches the
    /// first entry at EN and writes it on the first request. No interrupt: this is played
    /// blind, the control loop never waits on it (its vector is not bound).
    pub fn arm(&mut self, src: &[u16], dst: u32) {
        use pac::dma::vals;
        let (dma, st) = (pac::DMA2, ENV_STREAM);
        let s = dma.st(st);
        clear_stream_flags(dma, st);
        s.par().write_value(dst);
        s.m0ar().write_value(src.as_ptr() as u32);
        s.ndtr().write(|w| w.set_ndt(src.len() as u16));
        s.fcr().write(|w| w.set_dmdis(vals::Dmdis::ENABLED));
        s.cr().write(|w| {
            w.set_chsel(ENV_CHSEL);
            w.set_dir(vals::Dir::MEMORY_TO_PERIPHERAL);
            w.set_msize(vals::Size::BITS16);
            w.set_psize(vals::Size::BITS16);
            w.set_minc(true);
            w.set_pinc(false);
            w.set_circ(false);
            w.set_pl(vals::Pl::HIGH);
        });
        s.cr().modify(|w| w.set_en(true));
    }
}

/// DAC channel 1's output buffer on: DAC_CR.BOFF1 = 0 (RM0390 §14.3 "DAC output buffer
/// enable", §14.5.1 DAC_CR). Its reset value; written so the choice is visible.
pub fn dac_configure() {
    pac::DAC1.cr().modify(|w| w.set_boff(0, false));
}

/// The F446's DAC has no ready flag: t_WAKEUP (DS10693 DAC characteristics, 6.5 µs max with the
/// buffer on; value from memory, not re-checked) passes long before the first burst.
pub fn dac_wait_ready() {
    cortex_m::asm::delay(10 * (BOARD.sysclk_hz / 1_000_000));
}

/// Sampling time against the rheostat's source impedance (assumed 10 kΩ divider, ≤ 2.5 kΩ
/// mid-travel; see g474.rs). STM32F446 datasheet, ADC characteristics: R_AIN < (k − 0.5) /
/// (f_ADC · C_ADC · ln 2^(N+2)) − R_ADC with N = 12, R_ADC = 6 kΩ max, C_ADC = 4 pF typ (7 pF
/// max taken), f_ADC = 90 MHz / 4 = 22.5 MHz (embassy's ADCPRE for ≤ 36 MHz): 56 cycles allow
/// < 30 kΩ. 16 × (56 + 12) cycles = 48 µs per trigger.
#[cfg(not(feature = "dual-adc"))]
const SAMPLE_TIME: SampleTime = match BOARD.adc.sample_half_cycles {
    112 => SampleTime::CYCLES56,
    _ => panic!("F446 binding: a sampling time this board plan does not use"),
};

/// 16 conversions per trigger (one 16-rank sequence).
#[cfg(not(feature = "dual-adc"))]
const RANKS: usize = saw_boards::ADC_OVERSAMPLE as usize;
/// Samples delivered per `read` (one trigger's worth).
#[cfg(not(feature = "dual-adc"))]
pub const SAMPLES_PER_READ: usize = 1;
#[cfg(not(feature = "dual-adc"))]
const DMA_LEN: usize = 2 * RANKS * SAMPLES_PER_READ;
/// DMA2 stream of `DMA2_CH0` (for the raw re-initialisation in `Sampler::restart`).
#[cfg(not(feature = "dual-adc"))]
const DMA_STREAM: usize = 0;
#[cfg(not(feature = "dual-adc"))]
static DMA_BUF: StaticCell<[u16; DMA_LEN]> = StaticCell::new();

/// Timer-triggered, DMA-fed rheostat acquisition.
#[cfg(not(feature = "dual-adc"))]
pub struct Sampler {
    adc: RingBufferedAdc<'static, ADC1>,
    trigger: Timer<'static, TIM3>,
    buf: [u16; DMA_LEN / 2],
}

#[cfg(not(feature = "dual-adc"))]
impl Sampler {
    fn new(
        adc: Peri<'static, ADC1>,
        pin: Peri<'static, peripherals::PA1>,
        dma: Peri<'static, peripherals::DMA2_CH0>,
        tim: Peri<'static, TIM3>,
    ) -> Self {
        // TIM3 first, completely, counter stopped. Every UG it takes is a TRGO pulse (with
        // MMS = 000 UG itself is TRGO; with MMS = 010, set first here, UG is an update event and
        // so TRGO: RM0390 §17.4.2 TIMx_CR2.MMS), and embassy's `set_max_compare_value` writes one. Had ADC1 been armed already (EXTEN rising, EXTSEL
        // TIM3_TRGO, DMA = 1), that pulse would start a sequence into a DMA stream that is not
        // running yet: overrun, after which the ADC blocks DMA requests and ignores regular
        // triggers until OVR is cleared and the DMA re-initialised (RM0390 §13.8.1) — no sample,
        // ever. `Adc::new` below resets ADC1 through RCC, so nothing here can reach it.
        let trigger = trigger_timer(tim);
        // The EXTSEL code documented in saw-boards must be the one embassy uses for TIM3_TRGO.
        defmt::assert_eq!(
            embassy_stm32::adc::RegularTrigger::<ADC1>::signal(&embassy_stm32::triggers::TIM3_TRGO),
            BOARD.adc.trigger_extsel
        );
        let adc = Adc::new(adc);
        let ch = BOARD.adc.channel;
        let buf = DMA_BUF.init([0; DMA_LEN]);
        // embassy-stm32 0.6's adc_v2 `configure_sequence` writes every rank into SQR3, which has
        // only 6 slots (rank 7+ panics). So hand embassy a 1-rank sequence (it sets SMPR for the
        // channel, SCAN, DMA, EXTSEL/EXTEN) and extend it to 16 ranks of the same channel below.
        let adc = adc.into_ring_buffered(
            dma,
            buf,
            Irqs,
            [(pin.degrade_adc(), SAMPLE_TIME)].into_iter(),
            embassy_stm32::triggers::TIM3_TRGO,
            Exten::RISING_EDGE,
        );
        let r = pac::ADC1;
        r.sqr3().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
        r.sqr2().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
        r.sqr1().write(|w| {
            (0..4).for_each(|i| w.set_sq(i, ch));
            w.set_l((RANKS - 1) as u8);
        });
        const _: () = assert!(RANKS == 16);
        // Powered down until `start` (into_ring_buffered left ADON = 1): see there.
        r.cr2().modify(|w| w.set_adon(false));
        let mut adc = adc;
        // Overrun recovery must restart on a sequence boundary.
        adc.set_alignment(RANKS);
        Sampler { adc, trigger, buf: [0; DMA_LEN / 2] }
    }

    /// DMA stream first, then the ADC, then the trigger timer: the first TRGO (one period after
    /// this) starts rank 1 into a running stream. Call from the task that reads, right before the
    /// first `read`.
    pub fn start(&mut self) {
        // embassy's `start` enables the stream and also writes SWSTART, which would start an
        // extra, unaligned sequence now — but SWSTART "can be set only when ADON = 1, otherwise no
        // conversion is launched" (RM0390 §13.13.3 ADC_CR2), and the ADC is still off.
        self.adc.start();
        power_up();
        self.trigger.start();
    }

    /// Wait for the next trigger's conversions; returns the 16-bit sums (sum of 16 × 12 bit).
    /// On an overrun or a stall the acquisition is restarted before this returns the fault.
    pub async fn read(&mut self) -> Result<Batch, AdcFault> {
        let fault = match with_timeout(super::READ_TIMEOUT, self.adc.read(&mut self.buf)).await {
            Ok(Ok(remaining)) => {
                let mut codes = [0u16; SAMPLES_PER_READ];
                for (o, chunk) in codes.iter_mut().zip(self.buf.chunks_exact(RANKS)) {
                    *o = chunk.iter().map(|&x| x as u32).sum::<u32>() as u16;
                }
                return Ok(Batch { codes, backlog: (remaining / RANKS) as u32 });
            }
            Ok(Err(_)) => AdcFault::Overrun,
            Err(_) => AdcFault::Stalled,
        };
        self.restart();
        Err(fault)
    }

    /// Recovery from an ADC overrun in DMA mode (RM0390 §13.8.1: re-initialise the DMA —
    /// address and NDTR —, clear OVR, trigger again), also used after a ring-buffer lap: ADC off
    /// (ADON = 0 aborts any conversion; the next trigger starts at rank 1) and its DMA requests
    /// off, stream stopped and reloaded with the whole buffer, flags cleared, ring buffer emptied,
    /// then the order of `start`. TIM3 keeps running throughout.
    fn restart(&mut self) {
        // Triggers stop first: `start` restarts TIM3 only after the ADC's stabilisation time
        // (t_STAB), so no sequence can begin on an ADC that is still powering up (RM0390 §13.3.1).
        self.trigger.stop();
        let adc = pac::ADC1;
        adc.cr2().modify(|w| {
            w.set_adon(false);
            w.set_dma(false);
        });
        // Stream EN = 0.
        self.adc.stop();
        // RM0390 §9.3.17: EN must read 0 and the stream's flags must be cleared before the
        // stream is reprogrammed and re-enabled. NDTR = full length puts the stream back at the
        // buffer's start, where `clear` puts the ring buffer's indices.
        let (dma, st) = (pac::DMA2, DMA_STREAM);
        while dma.st(st).cr().read().en() {}
        clear_stream_flags(dma, st);
        dma.st(st).ndtr().write(|w| w.set_ndt(DMA_LEN as u16));
        // SR flags are rc_w0.
        adc.sr().modify(|w| {
            w.set_ovr(false);
            w.set_eoc(false);
            w.set_strt(false);
        });
        adc.cr2().modify(|w| w.set_dma(true));
        self.adc.clear();
        self.start();
    }
}

/// ADON = 1, then wait t_STAB (3 µs max, STM32F446 datasheet ADC characteristics) before the
/// first trigger can come (RM0390 §13.3.1).
#[cfg(not(feature = "dual-adc"))]
fn power_up() {
    pac::ADC1.cr2().modify(|w| w.set_adon(true));
    cortex_m::asm::delay(3 * (BOARD.sysclk_hz / 1_000_000));
}

/// TIM3: `sample_rate_hz` period, TRGO = update event; counter stopped until `Sampler::start`.
fn trigger_timer(tim: Peri<'static, TIM3>) -> Timer<'static, TIM3> {
    let (psc, arr) = BOARD.adc_trigger_psc_arr();
    let t = Timer::new(tim);
    defmt::assert_eq!(t.get_clock_frequency().0, BOARD.adc.trigger_timer_clk_hz);
    t.set_master_mode(MasterMode::UPDATE);
    t.regs_core().psc().write_value(psc as u16);
    t.set_max_compare_value(arr as u16); // ARR, then UG latches PSC/ARR (a TRGO pulse)
    t
}

/// Clears every event flag of DMA stream `st` (LIFCR/HIFCR, RM0390 §9.5): a stream is only
/// re-enabled with its flags clear (RM0390 §9.3, "Stream configuration procedure").
fn clear_stream_flags(dma: pac::dma::Dma, st: usize) {
    dma.ifcr(st / 4).write(|w| {
        w.set_tcif(st % 4, true);
        w.set_htif(st % 4, true);
        w.set_teif(st % 4, true);
        w.set_dmeif(st % 4, true);
        w.set_feif(st % 4, true);
    });
}
