//! NUCLEO-F446RE, feature `dual-adc`: ADC1 + ADC2 in dual regular interleaved mode on the wiper
//! (issue #35; `saw_boards::NUCLEO_F446RE_DUAL`).
//!
//! TIM3 TRGO (update, 10 kHz; 40 kHz in the experiment `dual-adc-128`) triggers ADC1 (EXTSEL
//! 8); in interleaved mode ADC1 starts at the trigger and ADC2 the configured delay later, each
//! converting its 16-rank sequence of PA1 = ADC123_IN1 (RM0390 §13.9.3). DMA mode 2 moves each
//! pair as one word from ADC_CDR (ADC2 in the upper half-word, ADC1 in the lower) into a
//! circular buffer through DMA2 stream 0 (ADC1's request, channel 0); the sampler sums a
//! sample's results (16 words, 32 results; 64 and 128 in the experiment) and shifts the sum
//! (rounded) into the core's 16-conversion code.
use embassy_stm32::dma::{ReadableRingBuffer, TransferOptions};
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals as adcv;
use embassy_stm32::pac::adccommon::vals as ccrv;
use embassy_stm32::peripherals::{ADC1, ADC2, TIM3};
use embassy_stm32::timer::low_level::Timer;
use embassy_stm32::{peripherals, Peri};
use embassy_time::with_timeout;
use saw_boards::{AdcMode, Oversampling};
use static_cell::StaticCell;

use super::{clear_stream_flags, trigger_timer, Irqs, BOARD};
use crate::board::{AdcFault, Batch};

/// Ranks per ADC and trigger: the regular sequence's 16 (RM0390 §13.13.9 SQR1.L); one pair per
/// rank.
const PAIRS: usize = 16;
/// Triggers per sample: 1 (`dual-adc`), or 4 for the experiment `dual-adc-128`.
const TRIGGERS: usize = BOARD.adc.triggers_per_sample as usize;
/// Pairs (DMA words) per sample.
const SAMPLE_PAIRS: usize = PAIRS * TRIGGERS;
// 16 pairs per trigger = the board plan's conversions, scaled to the core's code by its shift.
const SHIFT: u32 = match BOARD.adc.oversampling {
    Oversampling::Software { conversions, shift } if conversions == 2 * SAMPLE_PAIRS as u32 => {
        shift
    }
    _ => panic!("F446 dual binding: 2 × 16 conversions per trigger"),
};
const _: () =
    assert!(SHIFT >= 1 && (2 * SAMPLE_PAIRS as u32) >> SHIFT == saw_boards::ADC_OVERSAMPLE);

/// 15-cycle sampling (SMPx = 001, RM0390 §13.13.5 ADC_SMPR2); the rheostat settles in it
/// (`NUCLEO_F446RE_DUAL`'s const assertion, DS10693's R_AIN equation).
const SAMPLE_TIME: adcv::SampleTime = match BOARD.adc.sample_half_cycles {
    30 => adcv::SampleTime::CYCLES15,
    _ => panic!("F446 dual binding: a sampling time this board plan does not use"),
};

/// ADC_CCR.DELAY: the delay between the two ADCs' sampling phases is 5 + DELAY ADCCLK cycles
/// (0000 = 5 … 1111 = 20, RM0390 §13.13.16). The board plan's 17 cycles = the 15-cycle sampling
/// + 2, the least the manual allows (§13.9.3: an ADC cannot start while the other samples the
/// pin; the delay then becomes the sampling time + 2 cycles): written as it acts, not left to
/// that rule.
const DELAY: u8 = match BOARD.adc.mode {
    AdcMode::DualInterleaved { delay_cycles } if delay_cycles >= 5 && delay_cycles <= 20 => {
        (delay_cycles - 5) as u8
    }
    _ => panic!("F446 dual binding: DualInterleaved with a delay of 5..=20 cycles"),
};
// One trigger's pairs fit the period. Each ADC's next start waits for the other's sampling phase
// plus 2 cycles (§13.9.3), so with 15-cycle sampling and a 17-cycle delay a pair takes 2 × 17 =
// 34 cycles (each ADC's own 27-cycle conversion is shorter); the last ADC2 conversion ends 17 +
// 27 cycles after its pair's start. At ADCCLK = 22.5 MHz: 15 × 34 + 44 = 554 cycles, 24.6 µs.
const _: () = assert!(
    ((PAIRS as u64 - 1) * 2 * (DELAY as u64 + 5) + (DELAY as u64 + 5) + 15 + 12) * 1_000_000
        / (BOARD.adc.clk_hz as u64)
        < 1_000_000 / (BOARD.sample_rate_hz as u64 * TRIGGERS as u64)
);
// The board plan's ADC clock is the one ADCPRE = /4 gives (`common_dual_mode`).
const _: () = assert!(BOARD.adc.clk_hz == BOARD.clocks.pclk2_hz() / 4);

/// Samples delivered per `read`.
pub const SAMPLES_PER_READ: usize = 1;
/// Two samples of pairs: the ring buffer wakes the reader at half and full transfer.
const DMA_LEN: usize = 2 * SAMPLE_PAIRS * SAMPLES_PER_READ;
/// DMA2 stream of `DMA2_CH0` (RM0390 §9.3.3 table 29: stream 0 channel 0 = ADC1). The
/// multi-ADC mode's requests are taken on ADC1's (the master's) request, as ST's HAL
/// (HAL_ADCEx_MultiModeStart_DMA) does; §13.9 names no request of its own for ADC_CDR.
const DMA_STREAM: usize = 0;
const DMA_REQUEST_ADC1: u8 = 0;
static DMA_BUF: StaticCell<[u32; DMA_LEN]> = StaticCell::new();

/// Timer-triggered dual-interleaved acquisition: ADC1 and ADC2 on PA1, pairs by DMA.
pub struct Sampler {
    ring: ReadableRingBuffer<'static, u32>,
    trigger: Timer<'static, TIM3>,
    buf: [u32; SAMPLE_PAIRS * SAMPLES_PER_READ],
    _adcs: (
        Peri<'static, ADC1>,
        Peri<'static, ADC2>,
        Peri<'static, peripherals::PA1>,
    ),
}

impl Sampler {
    pub(super) fn new(
        adc1: Peri<'static, ADC1>,
        adc2: Peri<'static, ADC2>,
        pin: Peri<'static, peripherals::PA1>,
        dma: Peri<'static, peripherals::DMA2_CH0>,
        tim: Peri<'static, TIM3>,
    ) -> Self {
        // TIM3 first, stopped (see f446.rs: its UG pulses TRGO; the ADCs are off here).
        let trigger = trigger_timer(tim);
        // ADC1 and ADC2 clocks on, the ADC interface reset (RCC_APB2ENR ADC1EN/ADC2EN,
        // RCC_APB2RSTR.ADCRST — common to all ADCs; RM0390 §6.3.14, §6.3.9).
        pac::RCC.apb2enr().modify(|w| {
            w.set_adc1en(true);
            w.set_adc2en(true);
        });
        pac::RCC.apb2rstr().modify(|w| w.set_adcrst(true));
        pac::RCC.apb2rstr().modify(|w| w.set_adcrst(false));
        // PA1 analog (MODER = 11, RM0390 §7.4.1): the pin is owned by this sampler.
        pac::GPIOA
            .moder()
            .modify(|w| w.set_moder(1, pac::gpio::vals::Moder::ANALOG));
        let ch = BOARD.adc.channel;
        for adc in [pac::ADC1, pac::ADC2] {
            // SCAN: the 16 ranks (§13.3.8); 12-bit (RES = 00); EOC after each conversion
            // (EOCS = 1, §13.13.3) — in dual interleaved mode ADC2's EOC raises the pair's DMA
            // request (§13.9.3). Per-ADC DMA off: DMA mode 2 of ADC_CCR serves the pairs.
            adc.cr1().write(|w| w.set_scan(true));
            adc.cr2().write(|w| {
                w.set_eocs(adcv::Eocs::EACH_CONVERSION);
                w.set_dma(false);
                w.set_cont(false);
            });
            adc.smpr2().write(|w| w.set_smp(ch as usize, SAMPLE_TIME));
            adc.sqr3().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
            adc.sqr2().write(|w| (0..6).for_each(|i| w.set_sq(i, ch)));
            adc.sqr1().write(|w| {
                (0..4).for_each(|i| w.set_sq(i, ch));
                w.set_l((PAIRS - 1) as u8);
            });
        }
        const _: () = assert!(PAIRS == 16);
        // The trigger comes from ADC1's regular multiplexer (§13.9.3): TIM3_TRGO, rising edge;
        // ADC2's own trigger stays disabled.
        pac::ADC1.cr2().modify(|w| {
            w.set_extsel(BOARD.adc.trigger_extsel);
            w.set_exten(adcv::Exten::RISING_EDGE);
        });
        common_dual_mode(true);
        // SAFETY: the buffer is 'static and only this ring buffer touches it; ADC_CDR is a
        // read-only 32-bit register that the stream reads once per request.
        let ring = unsafe {
            ReadableRingBuffer::new(
                embassy_stm32::dma::Channel::new(dma, Irqs),
                DMA_REQUEST_ADC1,
                pac::ADC123_COMMON.cdr().as_ptr() as *mut u32,
                DMA_BUF.init([0; DMA_LEN]),
                TransferOptions::default(),
            )
        };
        Sampler {
            ring,
            trigger,
            buf: [0; SAMPLE_PAIRS * SAMPLES_PER_READ],
            _adcs: (adc1, adc2, pin),
        }
    }

    /// DMA stream first, then both ADCs on, then the trigger timer: the first TRGO starts pair
    /// 1 into a running stream. Call from the task that reads, right before the first `read`.
    pub fn start(&mut self) {
        self.ring.start();
        power_up();
        self.trigger.start();
    }

    /// Wait for the next sample's pairs (16 per trigger); returns their results summed and
    /// shifted to the 16-conversion code. On an overrun or a stall the acquisition is restarted first.
    pub async fn read(&mut self) -> Result<Batch, AdcFault> {
        let fault = match with_timeout(
            crate::board::READ_TIMEOUT,
            self.ring.read_exact(&mut self.buf),
        )
        .await
        {
            Ok(Ok(remaining)) => {
                let mut codes = [0u16; SAMPLES_PER_READ];
                for (o, pairs) in codes.iter_mut().zip(self.buf.chunks_exact(SAMPLE_PAIRS)) {
                    *o = code_of(pairs);
                }
                return Ok(Batch {
                    codes,
                    backlog: (remaining / SAMPLE_PAIRS) as u32,
                });
            }
            Ok(Err(_)) => AdcFault::Overrun,
            Err(_) => AdcFault::Stalled,
        };
        self.restart();
        Err(fault)
    }

    /// Recovery from an overrun (in multi-ADC mode an overrun on either ADC stops the DMA
    /// requests, RM0390 §13.9 "DMA requests in multi-ADC mode"; triggers are ignored until OVR
    /// is cleared, §13.8.1) or a ring-buffer lap: triggers stopped, both ADCs off (ADON = 0
    /// aborts a conversion), the multi-ADC sequencer reset by independent mode before
    /// interleaved mode is programmed again (§13.9.3 note), stream stopped and reloaded with
    /// the whole buffer, flags cleared, then the order of `start`.
    fn restart(&mut self) {
        self.trigger.stop();
        for adc in [pac::ADC1, pac::ADC2] {
            adc.cr2().modify(|w| w.set_adon(false));
        }
        common_dual_mode(false);
        self.ring.request_pause();
        let (dma, st) = (pac::DMA2, DMA_STREAM);
        while dma.st(st).cr().read().en() {}
        clear_stream_flags(dma, st);
        dma.st(st).ndtr().write(|w| w.set_ndt(DMA_LEN as u16));
        for adc in [pac::ADC1, pac::ADC2] {
            // SR flags are rc_w0.
            adc.sr().modify(|w| {
                w.set_ovr(false);
                w.set_eoc(false);
                w.set_strt(false);
            });
        }
        common_dual_mode(true);
        self.ring.clear();
        self.start();
    }
}

/// The 16-conversion code of one sample's pairs: each word is ADC2_DR << 16 | ADC1_DR (DMA
/// mode 2, RM0390 §13.9.3); the 12-bit results summed (32: ≤ 131 040; 128: ≤ 524 160) and
/// shifted right with rounding.
fn code_of(pairs: &[u32]) -> u16 {
    let sum: u32 = pairs.iter().map(|&w| (w & 0xFFFF) + (w >> 16)).sum();
    ((sum + (1 << (SHIFT - 1))) >> SHIFT) as u16
}

/// ADC_CCR (RM0390 §13.13.16): ADCCLK = PCLK2 / 4 (22.5 MHz ≤ 36 MHz), DELAY, DMA mode 2 with
/// DDS = 1 (requests go on after the ring's last transfer: the stream is circular), MULTI =
/// 00111 dual interleaved — or 00000 independent, which resets the multi-ADC sequencer.
fn common_dual_mode(dual: bool) {
    pac::ADC123_COMMON.ccr().write(|w| {
        w.set_adcpre(ccrv::Adcpre::DIV4);
        w.set_delay(DELAY);
        w.set_dds(ccrv::Dds::CONTINUOUS);
        w.set_dma(if dual {
            ccrv::Dma::MODE2
        } else {
            ccrv::Dma::DISABLED
        });
        w.set_multi(if dual {
            ccrv::Multi::DUAL_I
        } else {
            ccrv::Multi::INDEPENDENT
        });
    });
}

/// ADON = 1 on both, then t_STAB (3 µs max, DS10693) before the first trigger (§13.3.1).
fn power_up() {
    for adc in [pac::ADC1, pac::ADC2] {
        adc.cr2().modify(|w| w.set_adon(true));
    }
    cortex_m::asm::delay(3 * (BOARD.sysclk_hz / 1_000_000));
}
