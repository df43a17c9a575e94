//! The board's hooks around the store's flash: the work after every erase runs once per erase,
//! after it; a read the board reports as corrupted fails the load with `Unreadable`, and `erase`
//! brings the store back (nothing saved, saves work again).

use embassy_futures::block_on;
use saw_core::scene::default_config;
use saw_store::{Hooks, Saved, SceneStore, StoreError};
use sequential_storage::mock_flash::{MockFlashBase, WriteCountCheck};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Mutex;

/// Two 512-byte pages of 4-byte words: a few saves fill a page, so a save must erase.
type Flash = MockFlashBase<2, 4, 128>;
const RANGE: core::ops::Range<u32> = Flash::FULL_FLASH_RANGE;

fn fresh() -> Flash {
    Flash::new(WriteCountCheck::OnceOnly, None, true)
}

fn saved(i: u32) -> Saved {
    Saved {
        scene_id: 0x7000 + i,
        config: default_config()
            .with_boundary(0, 25_000 + i * 100)
            .expect("a boundary between 25 and 30 mm is valid"),
    }
}

// The hooks are plain `fn`s (the firmware's are), so the tests talk to them through statics;
// the lock keeps the two tests that use them apart.
static LOCK: Mutex<()> = Mutex::new(());
static AFTER_ERASE: AtomicU32 = AtomicU32::new(0);
/// Reads starting at this offset are reported corrupted (u32::MAX: none).
static BAD_OFFSET: AtomicU32 = AtomicU32::new(u32::MAX);

fn count_erase() {
    AFTER_ERASE.fetch_add(1, Ordering::SeqCst);
}

fn bad_read(offset: u32, len: usize) -> bool {
    let bad = BAD_OFFSET.load(Ordering::SeqCst);
    bad != u32::MAX && offset <= bad && bad < offset + len as u32
}

const HOOKS: Hooks = Hooks {
    after_erase: count_erase,
    read_corrupted: bad_read,
    zeroed: |_, _| {},
};

#[test]
fn the_after_erase_hook_runs_once_per_erase() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    AFTER_ERASE.store(0, Ordering::SeqCst);
    BAD_OFFSET.store(u32::MAX, Ordering::SeqCst);
    let flash = fresh();
    let start = flash.stats_snapshot();
    let mut store = SceneStore::with_hooks(flash, RANGE, HOOKS).unwrap();
    for i in 0..40 {
        block_on(store.save(&saved(i))).unwrap();
    }
    assert_eq!(block_on(store.load()), Ok(Some(saved(39))));
    let flash = store.into_flash().unwrap();
    let erases = start.compare_to(flash.stats_snapshot()).erases;
    assert!(
        erases >= 2,
        "40 saves over two 512-byte pages erase more than once: {erases}"
    );
    assert_eq!(u64::from(AFTER_ERASE.load(Ordering::SeqCst)), erases as u64);
}

#[test]
fn a_corrupted_read_fails_the_load_and_erase_recovers_the_store() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    BAD_OFFSET.store(u32::MAX, Ordering::SeqCst);
    let mut store = SceneStore::with_hooks(fresh(), RANGE, HOOKS).unwrap();
    block_on(store.save(&saved(1))).unwrap();
    // A reboot (no cached item location), and the first page's first word reported corrupted:
    // its state marker, which a load after boot reads first.
    let mut store = SceneStore::with_hooks(store.into_flash().unwrap(), RANGE, HOOKS).unwrap();
    BAD_OFFSET.store(0, Ordering::SeqCst);
    assert_eq!(block_on(store.load()), Err(StoreError::Unreadable));
    // A save over a store the board cannot read is refused too, never half done.
    assert_eq!(block_on(store.save(&saved(2))), Err(StoreError::Unreadable));
    BAD_OFFSET.store(u32::MAX, Ordering::SeqCst);
    block_on(store.erase()).unwrap();
    assert_eq!(
        block_on(store.load()),
        Ok(None),
        "nothing saved after the erase"
    );
    block_on(store.save(&saved(3))).unwrap();
    assert_eq!(block_on(store.load()), Ok(Some(saved(3))));
    // And after a reboot (a new store over the same flash).
    let mut again = SceneStore::new(store.into_flash().unwrap(), RANGE).unwrap();
    assert_eq!(block_on(again.load()), Ok(Some(saved(3))));
}
