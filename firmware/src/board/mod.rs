//! Board selection: exactly one of `board::f446` / `board::g474` is compiled, chosen by the
//! `nucleo-f446re` (default) / `nucleo-g474re` cargo features. Both expose the same items:
//! `BOARD`, `init()`, `Parts`, `split()` and `Sampler`.
#[cfg(all(feature = "nucleo-f446re", feature = "nucleo-g474re"))]
compile_error!("select exactly one board: `--no-default-features --features nucleo-g474re` for the G474");

#[cfg(feature = "nucleo-f446re")]
mod f446;
#[cfg(feature = "nucleo-f446re")]
pub use f446::*;

#[cfg(all(feature = "nucleo-g474re", not(feature = "nucleo-f446re")))]
mod g474;
#[cfg(all(feature = "nucleo-g474re", not(feature = "nucleo-f446re")))]
pub use g474::*;

use embassy_stm32::rcc::{AHBPrescaler, APBPrescaler};

/// The control core with this board's velocity window (`BoardDef::velocity_window`: the
/// acquisition's noise picks it, docs/conversion-budget.md).
pub type Controller =
    saw_core::Controller<saw_core::controller::WindowEstimator<{ BOARD.velocity_window }>>;

/// How long HSE may take to become ready: ST's HAL's HSE_STARTUP_TIMEOUT (100 ms). A crystal
/// starts in ~2 ms (t_SU(HSE), DS12288), an external clock at once.
pub const HSE_TIMEOUT_MS: u32 = 100;
/// The clock the core runs on from reset until the PLL: HSI, 16 MHz on both chips.
const HSI_HZ: u32 = 16_000_000;

/// Starts HSE (bypass: an external clock on OSC_IN) and waits at most [`HSE_TIMEOUT_MS`] for
/// HSERDY; true if it became ready. Called before `embassy_stm32::init`, whose RCC code waits
/// for HSERDY without a limit (embassy-stm32 0.6 rcc/f247.rs, rcc/g4.rs): a Nucleo-F446RE whose
/// ST-LINK MCO does not reach OSC_IN (early revisions, SB50 open, the ST-LINK side unpowered,
/// UM1724 §6.7.1) would never start and never say why. HSEBYP is writable only while HSEON = 0
/// (RM0390 §6.3.1 RCC_CR; RM0440 §7.4.1). embassy then finds HSE on and ready and goes on.
pub fn start_hse(bypass: bool) -> bool {
    use embassy_stm32::pac::RCC;
    RCC.cr().modify(|w| w.set_hseon(false));
    RCC.cr().modify(|w| w.set_hsebyp(bypass));
    RCC.cr().modify(|w| w.set_hseon(true));
    for _ in 0..HSE_TIMEOUT_MS {
        if RCC.cr().read().hserdy() {
            return true;
        }
        // On HSI16 from reset: at least a millisecond (`delay` takes at least its count of
        // core cycles; ~2 ms per step on an M4, whose loop takes two cycles an iteration). The
        // log says "at least".
        cortex_m::asm::delay(HSI_HZ / 1000);
    }
    RCC.cr().read().hserdy()
}

/// AHB prescaler from the saw-boards divider.
pub const fn ahb_pre(div: u32) -> AHBPrescaler {
    match div {
        1 => AHBPrescaler::DIV1,
        2 => AHBPrescaler::DIV2,
        4 => AHBPrescaler::DIV4,
        8 => AHBPrescaler::DIV8,
        16 => AHBPrescaler::DIV16,
        _ => panic!("unsupported AHB divider"),
    }
}

/// APB prescaler from the saw-boards divider.
pub const fn apb_pre(div: u32) -> APBPrescaler {
    match div {
        1 => APBPrescaler::DIV1,
        2 => APBPrescaler::DIV2,
        4 => APBPrescaler::DIV4,
        8 => APBPrescaler::DIV8,
        16 => APBPrescaler::DIV16,
        _ => panic!("unsupported APB divider"),
    }
}

/// Why `Sampler::read` returned no samples. Either way the sampler has already restarted the
/// acquisition (ADC overrun cleared, DMA re-initialised, armed for the next TIM3 trigger).
#[derive(Clone, Copy, Debug, defmt::Format)]
pub enum AdcFault {
    /// The DMA ring buffer was lapped: the reader fell behind, samples were lost.
    Overrun,
    /// Nothing arrived within [`READ_TIMEOUT`]: the ADC stopped converting or its DMA requests
    /// are blocked (an ADC overrun with DMA = 1, which embassy's ring buffer neither clears nor
    /// reports).
    Stalled,
}

/// One `Sampler::read`: the oldest unread samples (embassy's ring buffer hands them out in
/// order), and how many newer ones were already waiting behind them.
pub struct Batch {
    pub codes: [u16; SAMPLES_PER_READ],
    /// Whole samples left in the ring buffer after `codes` (0 while the reader keeps up).
    pub backlog: u32,
}

/// How long `Sampler::read` waits for a batch: the batch's own sample periods plus four.
pub const READ_TIMEOUT: embassy_time::Duration =
    embassy_time::Duration::from_micros((SAMPLES_PER_READ as u64 + 4) * 1_000_000 / BOARD.sample_rate_hz as u64);

/// The part's flash in KiB, from its flash size data register (FLASHSIZE, in system memory:
/// RM0390 §39.2 at 0x1FFF_7A22, RM0440 §48.2 at 0x1FFF_75E0). The same image runs on an
/// F446RC or a G474RB/RC, whose smaller flash has no store region.
fn flash_kib() -> u32 {
    // SAFETY: a read-only, always-mapped 16-bit register.
    unsafe { core::ptr::read_volatile(FLASH_SIZE_REG as *const u16) as u32 }
}

/// True if the part has the flash the store lives in; else says so once and the board runs
/// without a store (`saw save` is refused).
fn store_fits() -> bool {
    let s = BOARD.store;
    let have = flash_kib();
    let end = s.origin + s.bytes;
    let need_kib = (end - BOARD.flash_origin).div_ceil(1024);
    if have < need_kib {
        defmt::warn!(
            "store: this part has {} KiB of flash (FLASHSIZE); the store at {=u32:#010x} needs {} KiB: no store, save is refused",
            have,
            s.origin,
            need_kib
        );
        return false;
    }
    true
}
