//! The fault path: every way the firmware loses control — a panic, a HardFault, an NMI that is
//! not the store's ECC report, an interrupt with no handler — ends here: RF off first, then a
//! stop that never leaves the RF chain waiting on anyone (halted for a debugger, else reset at
//! once), with the cause kept across the reset for the next boot's log.
//!
//! Why each part:
//! - cortex-m-rt's default NMI and DefaultHandler are `loop {}`: RF armed and TIM2 bursting
//!   until the IWDG fired (up to ~94 ms at the slowest LSI). Both are defined in `main.rs` and
//!   come here.
//! - Without a debugger a `udf`/`bkpt` only waits for the IWDG; nobody reads the RTT log then
//!   either (defmt-rtt's control block is rebuilt at the next boot), so the chip resets at once
//!   after RF is off (SCB AIRCR.SYSRESETREQ, ARMv7-M ARM B3.2.6): every pin back to its reset
//!   state, the pull-downs hold the enables and the arm low.
//! - With a debugger (DHCSR.C_DEBUGEN, ARMv7-M ARM C1.6.2) the stop is a breakpoint, so
//!   probe-rs prints the backtrace, with the IWDG frozen for the halt.
//! - Re-entry (a panic inside the fault's own defmt write, a HardFault in the panic handler): RF
//!   off again, no second log line, straight to the stop.
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

/// Why the fault path ran.
#[derive(Clone, Copy, PartialEq, Eq, defmt::Format)]
#[repr(u8)]
pub enum Cause {
    Panic = 1,
    HardFault = 2,
    /// An NMI the firmware does not handle (on the G474, any but a flash double-ECC error in the
    /// store).
    Nmi = 3,
    /// An exception or interrupt with no handler of ours (cortex-m-rt's DefaultHandler); the
    /// number is IRQn (negative for a system exception).
    Unhandled = 4,
}

impl Cause {
    fn from_bits(b: u32) -> Option<Self> {
        Some(match b {
            1 => Self::Panic,
            2 => Self::HardFault,
            3 => Self::Nmi,
            4 => Self::Unhandled,
            _ => return None,
        })
    }
}

static ENTERED: AtomicBool = AtomicBool::new(false);

/// The cause, kept through the reset: `.uninit` is neither loaded nor zeroed by cortex-m-rt's
/// start-up, and SRAM keeps its contents across a system reset (RM0390 §5.1.2, RM0440 §7.1.2:
/// a system reset resets every register but the RCC_CSR flags and the backup domain, not SRAM).
#[link_section = ".uninit.saw_last_fault"]
static mut LAST_FAULT: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();
/// Marks `LAST_FAULT` as written by the fault path (power-on SRAM is random).
const MAGIC: u32 = 0x5A3F_A017;

/// RF off, then (first entry only) note the cause and run `log`, then stop: a breakpoint under
/// a debugger, else a reset at once. Never returns.
#[inline(never)]
pub fn stop(cause: Cause, irqn: i16, log: impl FnOnce()) -> ! {
    crate::rf::emergency_off();
    let first = !ENTERED.swap(true, Ordering::Relaxed);
    if first {
        let word = cause as u32 | ((irqn as u16 as u32) << 16);
        // SAFETY: written only here, once (ENTERED), with interrupts of lower priority unable to
        // run a second fault path to completion in between; a volatile write of plain words.
        unsafe { core::ptr::write_volatile(core::ptr::addr_of_mut!(LAST_FAULT).cast::<[u32; 2]>(), [MAGIC, word]) };
    }
    if debugger_reading() {
        crate::board::freeze_watchdog_if_debugged();
        if first {
            log();
        }
        loop {
            cortex_m::asm::bkpt();
        }
    }
    cortex_m::peripheral::SCB::sys_reset()
}

/// A debugger that will print the backtrace: DHCSR.C_DEBUGEN set *and* an RTT host that put the
/// log channel in block-when-full mode, as `probe-rs run` does at attach. C_DEBUGEN alone is not
/// enough: only a power-on reset clears it (ARMv7-M ARM C1.6.3; the DBGMCU freeze bits too), so
/// a tool that detached without clearing it — or a killed probe-rs — would leave a board that
/// halts at the next fault with the IWDG frozen, for good (stlink-org PR #1503 describes that
/// failure). The RTT control block is rebuilt at every boot, so its mode flag is only set by a
/// host attached since.
fn debugger_reading() -> bool {
    cortex_m::peripheral::DCB::is_debugger_attached() && defmt_rtt::in_blocking_mode()
}

/// The previous run's fault-path cause, if it ended there (read once at boot, then cleared).
pub fn take_last() -> Option<(Cause, i16)> {
    let p = core::ptr::addr_of_mut!(LAST_FAULT).cast::<[u32; 2]>();
    // SAFETY: any bit pattern is a valid [u32; 2]; boot runs this before any fault path can.
    let [magic, word] = unsafe { core::ptr::read_volatile(p) };
    unsafe { core::ptr::write_volatile(p, [0, 0]) };
    if magic != MAGIC {
        return None;
    }
    Some((Cause::from_bits(word & 0xFF)?, (word >> 16) as u16 as i16))
}

/// A board whose HSE never became ready: the RF lines driven low (their GPIO clocks turned on
/// first, since embassy never ran), one log line, then asleep for good. No reset: a boot loop
/// would only repeat the wait; no IWDG runs yet, so none comes.
pub fn halt_without_clock(hse: &str, waited_ms: u32) -> ! {
    crate::board::enable_rf_gpio_clocks();
    // Only the pins: TIM2, TIM8 and the DAC are not clocked yet (embassy never ran), and an
    // access to an unclocked block is not something to rely on.
    crate::rf::rf_pins_low();
    defmt::error!(
        "clocks: HSE not ready after at least {} ms ({}): HSI is not an exact 15 MHz carrier; RF off, halted",
        waited_ms,
        hse
    );
    // WFE, not WFI: the same sleep here (no interrupt is enabled, no event comes), and the one
    // the board model can show (Unicorn runs WFI as a no-op; docs/board-model.md).
    loop {
        cortex_m::asm::wfe();
    }
}
