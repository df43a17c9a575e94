//! A model of the NUCLEO-F446RE and NUCLEO-G474RE boards that runs the real firmware ELF: the
//! Cortex-M4F core on Unicorn, the NVIC/SysTick/SCB, and register-level models of the STM32
//! peripherals the firmware uses, in virtual time.
//!
//! License: GPL-2.0-or-later (links libunicorn). Test tooling only: nothing that ships links it.
pub mod board;
pub mod check;
pub mod elf;
pub mod machine;
pub mod panic_check;
pub mod periph;
pub mod run;
pub mod scs;
pub mod serve;
pub mod stack;
pub mod store_image;
pub mod touch;
