//! The saved scene in the board's flash: `saw-store` over the board's store region
//! (`saw_boards::StoreLayout`), read once at boot, written by the link's `save` — with RF off and
//! the watchdog lengthened for as long as the flash may stall the CPU.

use defmt::{info, warn};
use saw_store::SceneStore;

use crate::board::{StoreFlash, BOARD};

/// The store, or why there is none (logged once at boot).
pub fn open(flash: Option<StoreFlash>) -> Option<SceneStore<StoreFlash>> {
    let s = BOARD.store;
    match SceneStore::new(flash?, s.region_range()) {
        Ok(store) => {
            info!(
                "store: {} KiB at {=u32:#010x} ({} erase units of {} KiB){}",
                s.bytes / 1024,
                s.origin,
                s.bytes / s.erase_bytes,
                s.erase_bytes / 1024,
                if s.read_while_write { ", read-while-write" } else { "" }
            );
            Some(store)
        }
        Err(e) => {
            warn!("store: not usable ({}); save is refused", e);
            None
        }
    }
}

/// The independent watchdog's timeout while the flash may stall every fetch: the F446's
/// 128 KiB sector erase takes up to 2 s (DS10693, t_ERASE128KB at ×32 parallelism), and
/// sequential-storage erases at most one unit per save. PR = 6 (÷256) and RLR = 1000 give
/// 1001 × 256 / f_LSI: 8.0 s at the nominal 32 kHz, 5.5 s at the fastest LSI (47 kHz,
/// DS10693 table 41), more than two erases either way.
const SAVE_PR: u8 = 6;
const SAVE_RLR: u16 = 1000;

/// Prescaler and reload in force before `lengthen`, put back by `restore`.
#[derive(Clone, Copy)]
pub struct Timeout {
    pr: u8,
    rlr: u16,
}

/// Waits until PR and RLR writes have reached the LSI domain (SR.PVU = RVU = 0): a write while
/// one is under way is not taken, and the registers read back meaningless values until then
/// (RM0390's IWDG register descriptions; RM0440 §42.4.2–§42.4.4). "Up to five RC 40 kHz
/// cycles": ~160 µs at 32 kHz, ~300 µs at the slowest LSI.
fn wait_updated() {
    use embassy_stm32::pac::IWDG;
    while {
        let sr = IWDG.sr().read();
        sr.pvu() || sr.rvu()
    } {}
}

/// Sets the watchdog's prescaler and reload, then reloads the counter with it: KR = 0x5555 opens
/// PR/RLR, wait for SR = 0, KR = 0xAAAA reloads from RLR and closes them again (the IWDG's
/// "register access protection" and configuration sequence: RM0390's IWDG chapter, RM0440
/// §42.3). The dog is fed first, so the waits cannot run it out.
fn set(t: Timeout) {
    use embassy_stm32::pac::iwdg::vals::{Key, Pr};
    use embassy_stm32::pac::IWDG;
    IWDG.kr().write(|w| w.set_key(Key::RESET));
    wait_updated();
    IWDG.kr().write(|w| w.set_key(Key::ENABLE));
    IWDG.pr().write(|w| w.set_pr(Pr::from_bits(t.pr)));
    IWDG.rlr().write(|w| w.set_rl(t.rlr));
    wait_updated();
    IWDG.kr().write(|w| w.set_key(Key::RESET));
}

/// Lengthens the running watchdog to the save timeout; returns the timeout to restore.
pub fn lengthen_watchdog() -> Timeout {
    use embassy_stm32::pac::IWDG;
    wait_updated();
    let old = Timeout { pr: IWDG.pr().read().pr().to_bits(), rlr: IWDG.rlr().read().rl() };
    set(Timeout { pr: SAVE_PR, rlr: SAVE_RLR });
    old
}

/// Puts the watchdog's own timeout back.
pub fn restore_watchdog(t: Timeout) {
    set(t);
}
