//! The saved scene in the board's flash: `saw-store` over the board's store region
//! (`saw_boards::StoreLayout`), read once at boot, written by the link's `save` — with RF off and
//! the watchdog lengthened for as long as the flash may stall the CPU. Around the flash, what
//! sequential-storage cannot see: the F446's flash caches flushed after every erase, and the
//! G474's double ECC errors (a save cut by a power loss) refused on read and, at boot, the double
//! words that raise them programmed to zeros, which sequential-storage then takes for the torn
//! write they are (`saw_store::SceneStore::zero_unreadable`). The 2D image keeps its 2D scene
//! in the same store and the same way (`load_2d_at_boot`; the item's tag keeps the kinds apart).

use defmt::{info, warn};
use saw_store::{Hooks, Saved, SceneStore, StoreError};

use crate::board::{StoreFlash, BOARD};

/// The board's hooks around the store's flash (`saw_store::Hooks`).
const HOOKS: Hooks = Hooks { after_erase: flush_flash_caches, read_corrupted: ecc_error_in, zeroed: ecc_zeroed };

/// F446: the ART accelerator's caches are flushed after every erase, as ST's HAL does
/// (`FLASH_FlushCaches`, called after each erase by `HAL_FLASHEx_Erase`). The data cache keeps 8
/// lines of 128 bits read through the D-code bus and has no coherency with the array (RM0390
/// §3.4.2 "Data management"): a line read before an erase — sequential-storage reads a page's
/// markers, erases it, reads them again — still returns the old bytes afterwards, and the store
/// takes an erased page for a full one (a refused save, a corrupt store, the wrong scene at
/// boot). embassy-stm32 0.6 resets the cache after an erase only on dual-bank F42x/F43x
/// (`flash/f4.rs`, errata 2.2.12). Both caches reset, each back as it was
/// (`board::reset_flash_caches`); the instruction cache too, as the HAL does (the store's
/// sectors hold no code, so it is only for symmetry with it).
#[cfg(feature = "nucleo-f446re")]
fn flush_flash_caches() {
    let was = embassy_stm32::pac::FLASH.acr().read();
    crate::board::reset_flash_caches(was.icen(), was.dcen());
}

/// G474: embassy-stm32 0.6's flash driver already turns the data cache off for every program
/// and erase and resets it (DCRST) before turning it on again (`flash/g.rs`,
/// `restore_data_cache_state`), RM0440 §5.3.4.
#[cfg(not(feature = "nucleo-f446re"))]
fn flush_flash_caches() {}

/// Whether a double ECC error was reported inside `len` bytes read at `offset` of the store's
/// region (`flash_ecc.rs`; never on the F446): those bytes are refused.
fn ecc_error_in(offset: u32, len: usize) -> bool {
    crate::flash_ecc::reported_in(BOARD.store.region_base + offset, len as u32)
}

/// The double word at `offset` of the store's region was programmed to zeros: its error is
/// forgotten, so the next one is recorded (`flash_ecc.rs` keeps only the first).
fn ecc_zeroed(offset: u32, len: usize) {
    crate::flash_ecc::forget_in(BOARD.store.region_base + offset, len as u32);
}

/// The boot's load: the saved scene, with the store repaired first if a save was cut by a
/// power loss. On the G474 such a cut leaves a double word — or, for a page erase, every double
/// word of the page — whose ECC is bad (RM0440 §5.3.2): reading it is a double error, its NMI
/// recorded by `flash_ecc.rs`. Every double word of the store is read once, and each one that
/// raises an error is programmed to all zeros: a valid code word, accepted over any content
/// (RM0440 §5.7.5 PROGERR "except if the data to write is 0x0000 0000"), the way ST's EEPROM
/// emulation (X-CUBE-EEPROM) neutralises a word a power loss corrupted. sequential-storage then
/// finds a torn write of its own kind — an item whose CRC fails, skipped for the one saved
/// before it; a written page marker; a closed page without live items, erased by the next save
/// — and the load returns the old scene or the new one (`saw_store::SceneStore::zero_unreadable`).
/// Only if the store still cannot be read is it erased (nothing loaded: the caller boots the
/// embedded or default scene); a scene read with an ECC error is never used.
pub async fn load_at_boot(store: &mut SceneStore<StoreFlash>) -> Result<Option<Saved>, StoreError> {
    load_repaired::<Saved, { saw_store::ITEM_BYTES }>(store).await
}

/// The 2D image's boot load (`load_at_boot`, the 2D scene: `SceneStore::load_2d`).
#[cfg(feature = "touch-2d")]
pub async fn load_2d_at_boot(
    store: &mut SceneStore<StoreFlash, { saw_store::ITEM_BYTES_2D }>,
) -> Result<Option<saw_store::Saved2d>, StoreError> {
    load_repaired::<saw_store::Saved2d, { saw_store::ITEM_BYTES_2D }>(store).await
}

/// A scene kind the store keeps, and how it is loaded.
#[allow(async_fn_in_trait)] // concrete types only
pub trait Stored: Sized {
    /// The store's load of this kind.
    async fn load<const N: usize>(store: &mut SceneStore<StoreFlash, N>) -> Result<Option<Self>, StoreError>;
}

impl Stored for Saved {
    async fn load<const N: usize>(store: &mut SceneStore<StoreFlash, N>) -> Result<Option<Self>, StoreError> {
        store.load().await
    }
}

#[cfg(feature = "touch-2d")]
impl Stored for saw_store::Saved2d {
    async fn load<const N: usize>(store: &mut SceneStore<StoreFlash, N>) -> Result<Option<Self>, StoreError> {
        store.load_2d().await
    }
}

/// `load_at_boot` for either kind of scene.
async fn load_repaired<T: Stored, const N: usize>(store: &mut SceneStore<StoreFlash, N>) -> Result<Option<T>, StoreError> {
    let base = BOARD.store.region_base;
    crate::flash_ecc::clear_corrected();
    let zeroed = if crate::flash_ecc::HAS_ECC { store.zero_unreadable().await } else { Ok(None) };
    let at = match zeroed {
        Ok(Some(z)) => {
            let loaded = T::load(store).await;
            let unreadable = matches!(
                loaded,
                Err(StoreError::Unreadable | StoreError::Corrupted | StoreError::Flash)
            );
            // An error the scan left (none should: every double word was read) refuses the load.
            if crate::flash_ecc::take().is_none() && !unreadable {
                warn!(
                    "store: double ECC error at {=u32:#010x} (a save cut by a power loss); {=u32} double word(s) zeroed, the store repaired",
                    base + z.first,
                    z.count
                );
                return loaded;
            }
            base + z.first
        }
        Ok(None) => {
            let loaded = T::load(store).await;
            let Some(at) = crate::flash_ecc::take() else {
                return loaded;
            };
            at
        }
        // A zeroing refused by the flash (its error still recorded), or a read that failed.
        Err(e) => match crate::flash_ecc::take() {
            Some(at) => at,
            None => return Err(e),
        },
    };
    match store.erase().await {
        Ok(()) => {
            warn!("store: double ECC error at {=u32:#010x} (a save cut by a power loss); store erased", at);
            Ok(None)
        }
        Err(e) => {
            warn!("store: double ECC error at {=u32:#010x} (a save cut by a power loss); the erase failed ({})", at, e);
            Err(e)
        }
    }
}

/// The store, or why there is none (logged once at boot).
/// (`N`: the item buffer, `saw_store::ITEM_BYTES` for 1D scenes, `ITEM_BYTES_2D` for 2D ones.)
pub fn open<const N: usize>(flash: Option<StoreFlash>) -> Option<SceneStore<StoreFlash, N>> {
    let s = BOARD.store;
    match SceneStore::<StoreFlash, N>::sized(flash?, s.region_range(), HOOKS) {
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
