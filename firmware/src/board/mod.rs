//! Board selection: exactly one of `board::f446` / `board::g474` is compiled, chosen by the
//! `nucleo-f446re` (default) / `nucleo-g474re` cargo features. Both expose the same items:
//! `BOARD`, `rcc_config()`, `Parts`, `split()` and `Sampler`.
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

/// The ADC's DMA ring buffer was lapped (samples lost); the next read restarts it.
#[derive(Clone, Copy, Debug, defmt::Format)]
pub struct AdcOverrun;
