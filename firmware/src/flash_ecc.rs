//! Flash double-ECC errors (G474): the NMI's report of one inside the scene store, kept for the
//! store's reads and the boot's load (`store.rs`). The F446's flash has no ECC.
//!
//! RM0440 §5.3.2 "Error code correction (ECC)": every 64-bit double word of the main flash
//! carries 8 ECC bits. A program or erase cut by a power loss can leave a double word whose bits
//! and ECC disagree in two or more places: reading it is a double error, which the flash
//! interface reports in FLASH_ECCR (§5.7.7: ECCD set, ADDR_ECC[18:0] the double word's offset in
//! its bank, BK_ECC the bank, SYSF_ECC set for system memory) and by an NMI; the load itself
//! completes, with wrong data. ECCD is write 1 to clear, and a new error is recorded only once
//! it is clear. With cortex-m-rt's default NMI (`loop {}`) such a word in the store hung the board
//! at its first boot after the cut, before the watchdog runs, until the store was erased with a
//! probe.

use core::sync::atomic::{AtomicU32, Ordering};

/// No error recorded (no store starts at address 0).
const NONE: u32 = 0;
/// The address of the first double ECC error inside the store not yet taken by `take`.
static IN_STORE: AtomicU32 = AtomicU32::new(NONE);

/// Called first by the NMI handler: true if this NMI was a double ECC error inside the scene
/// store, now recorded and cleared (the handler returns; the load that hit it completed with
/// wrong data, which `store.rs` refuses). False for anything else — an ECC error in the image
/// itself, in system memory, or an NMI of another cause — which the fault path handles.
#[cfg(feature = "nucleo-g474re")]
pub fn on_nmi() -> bool {
    use embassy_stm32::pac::FLASH;
    /// Dual-bank mode (FLASH_OPTR.DBANK = 1, checked at `store_flash`): bank 1 from the start
    /// of flash, bank 2 from 256 KiB on (RM0440 §5.3.1); ADDR_ECC counts from its bank's start.
    const BANK1: u32 = 0x0800_0000;
    const BANK2: u32 = 0x0804_0000;
    let eccr = FLASH.eccr().read();
    if !eccr.eccd() || eccr.sysf_ecc() {
        return false;
    }
    let at = if eccr.bk_ecc() { BANK2 } else { BANK1 } + eccr.addr_ecc();
    let store = crate::board::BOARD.store;
    if !(store.origin..store.end()).contains(&at) {
        return false;
    }
    // The first one is kept: it names where the cut save was.
    let _ = IN_STORE.compare_exchange(NONE, at, Ordering::Relaxed, Ordering::Relaxed);
    // ECCD and ECCC are write 1 to clear (a standing ECCC would keep the next double error from
    // being reported: `clear_corrected`); the interrupt enable kept.
    FLASH.eccr().write(|w| {
        w.set_eccd(true);
        w.set_eccc(eccr.eccc());
        w.set_eccie(eccr.eccie());
    });
    true
}

/// Clears a standing single-error (corrected) report. ECCD is set, and its NMI raised, "only if
/// ECCC/ECCD are previously cleared" (RM0440 FLASH_ECCR), so an ECCC left by any corrected read
/// — of the image itself, anywhere — would hide a torn double word in the store: the load would
/// get wrong data with no report. Called before the boot's load.
#[cfg(feature = "nucleo-g474re")]
pub fn clear_corrected() {
    use embassy_stm32::pac::FLASH;
    let eccr = FLASH.eccr().read();
    if eccr.eccc() {
        FLASH.eccr().write(|w| {
            w.set_eccc(true);
            w.set_eccie(eccr.eccie());
        });
    }
}

/// The F446's flash has no ECC.
#[cfg(not(feature = "nucleo-g474re"))]
pub fn clear_corrected() {}

/// The F446's flash has no ECC: an NMI is never an ECC report.
#[cfg(not(feature = "nucleo-g474re"))]
pub fn on_nmi() -> bool {
    false
}

/// Whether the recorded error lies in the `len` bytes from `addr` (its double word overlaps
/// them).
pub fn reported_in(addr: u32, len: u32) -> bool {
    let at = IN_STORE.load(Ordering::Relaxed);
    at != NONE && at < addr.saturating_add(len) && at.saturating_add(8) > addr
}

/// Whether this board's flash has ECC (the G474; the F446's has none): the boot's scan of the
/// store for double words to zero runs only there (`store::load_at_boot`).
pub const HAS_ECC: bool = cfg!(feature = "nucleo-g474re");

/// Forgets the recorded error if it lies in the `len` bytes from `addr`: that double word was
/// programmed to zeros, a valid code word (RM0440 §5.7.5 PROGERR: zeros are accepted over any
/// content), and reads back without error; the next double error is recorded again.
pub fn forget_in(addr: u32, len: u32) {
    if reported_in(addr, len) {
        IN_STORE.store(NONE, Ordering::Relaxed);
    }
}

/// The recorded error's address, cleared: the store has been dealt with.
pub fn take() -> Option<u32> {
    match IN_STORE.swap(NONE, Ordering::Relaxed) {
        NONE => None,
        at => Some(at),
    }
}
