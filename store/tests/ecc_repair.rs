//! A save cut by a power loss on a flash with ECC (the G474, RM0440 §5.3.2): the write unit being
//! programmed when power went — or every unit of the page being erased — reads back with a
//! double ECC error, which the board reports through `Hooks::read_corrupted`. `zero_unreadable`
//! programs each such unit to zeros (a valid code word) and the store must then load the old
//! scene or the new one, whole, and take further saves: "nothing is lost".
//!
//! The cut is made at every byte of a save (sequential-storage's mock flash stops at the n-th
//! byte written or erased), across saves that only append and saves that close a page and
//! reclaim the next one with an erase.

use embassy_futures::block_on;
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use saw_core::scene::default_config;
use saw_store::{Hooks, Saved, SceneStore};
use sequential_storage::mock_flash::{MockFlashBase, MockFlashError, Operation, WriteCountCheck};
use std::collections::BTreeSet;
use std::sync::Mutex;

/// Four 512-byte pages of 8-byte double words, the G474's write unit.
type Mock = MockFlashBase<4, 8, 64>;
const RANGE: core::ops::Range<u32> = Mock::FULL_FLASH_RANGE;
const UNIT: u32 = 8;
const PAGE: u32 = 512;

/// Units whose ECC is bad (offsets, multiples of `UNIT`): reads overlapping one are refused.
static BAD: Mutex<BTreeSet<u32>> = Mutex::new(BTreeSet::new());
/// Keeps the tests, which share `BAD`, apart.
static LOCK: Mutex<()> = Mutex::new(());

fn bad() -> std::sync::MutexGuard<'static, BTreeSet<u32>> {
    BAD.lock().unwrap_or_else(|e| e.into_inner())
}

fn bad_read(offset: u32, len: usize) -> bool {
    bad()
        .range(offset & !(UNIT - 1)..offset + len as u32)
        .next()
        .is_some()
}

fn zeroed(offset: u32, _len: usize) {
    bad().remove(&offset);
}

const HOOKS: Hooks = Hooks {
    after_erase: || {},
    read_corrupted: bad_read,
    zeroed,
};

/// The mock with a note of where power went. Zeros may be written over anything (the write
/// check is off: the G474 allows it, and the test programs zeros only there).
struct Cut {
    mock: Mock,
    at: Option<(u32, Operation)>,
}

impl ErrorType for Cut {
    type Error = MockFlashError;
}

impl ReadNorFlash for Cut {
    const READ_SIZE: usize = Mock::READ_SIZE;
    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.mock.read(offset, bytes).await
    }
    fn capacity(&self) -> usize {
        self.mock.capacity()
    }
}

impl Cut {
    fn note<T>(&mut self, r: Result<T, MockFlashError>) -> Result<T, MockFlashError> {
        if let Err(MockFlashError::EarlyShutoff(a, op)) = &r {
            self.at = Some((*a, op.clone()));
        }
        r
    }
}

impl NorFlash for Cut {
    const WRITE_SIZE: usize = Mock::WRITE_SIZE;
    const ERASE_SIZE: usize = Mock::ERASE_SIZE;
    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let r = self.mock.erase(from, to).await;
        self.note(r)
    }
    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let r = self.mock.write(offset, bytes).await;
        self.note(r)
    }
}

fn flash(bytes: &[u8], shutoff: Option<u32>) -> Cut {
    let mut mock = Mock::new(WriteCountCheck::Disabled, shutoff, true);
    mock.as_bytes_mut().copy_from_slice(bytes);
    Cut { mock, at: None }
}

fn saved(i: u32) -> Saved {
    Saved {
        scene_id: 0x7000 + i,
        config: default_config()
            .with_boundary(0, 25_000 + i * 100)
            .expect("a boundary between 25 and 30 mm is valid"),
    }
}

/// For every store filled with 1..=`n` saves, a cut at every byte of the next save: returns how
/// many cuts were in an erase, and how many boots ran the old and the new scene (the new one
/// once per save: only the complete save holds it whole, a cut at its last byte fails its CRC).
fn sweep(n: u32) -> (u32, u32, u32) {
    let (mut erase_cuts, mut old, mut new) = (0, 0, 0);
    for filled in 1..=n {
        // The store before the save: `filled` saves made without a cut.
        let mut store =
            SceneStore::with_hooks(flash(&[0xFF; RANGE.end as usize], None), RANGE, HOOKS)
                .expect("a store over the mock");
        for i in 0..filled {
            block_on(store.save(&saved(i))).expect("a save without a cut");
        }
        let before = store
            .into_flash()
            .expect("the flash back")
            .mock
            .as_bytes()
            .to_vec();
        let (was, next) = (saved(filled - 1), saved(filled));
        for shutoff in 0.. {
            bad().clear();
            let mut store = SceneStore::with_hooks(flash(&before, Some(shutoff)), RANGE, HOOKS)
                .expect("a store over the mock");
            let done = block_on(store.save(&next)).is_ok();
            let mut cut = store.into_flash().expect("the flash back");
            let Some((at, op)) = cut.at.take() else {
                assert!(
                    done,
                    "{filled} saves, shutoff {shutoff}: the save failed without a cut"
                );
                // The save complete: nothing to zero, the new scene.
                let mut store = SceneStore::with_hooks(cut, RANGE, HOOKS).expect("a store");
                assert_eq!(block_on(store.zero_unreadable()), Ok(None));
                assert_eq!(
                    block_on(store.load()),
                    Ok(Some(next)),
                    "{filled} saves, complete"
                );
                new += 1;
                break;
            };
            // What the G474 leaves: the unit being programmed, or every unit of the page being
            // erased, with a bad ECC (the erase's content as the mock left it, partly erased).
            match op {
                Operation::Write => {
                    bad().insert(at & !(UNIT - 1));
                }
                Operation::Erase | Operation::Read => {
                    erase_cuts += 1;
                    let page = at & !(PAGE - 1);
                    bad().extend((page..page + PAGE).step_by(UNIT as usize));
                }
            }
            let step = format!("{filled} saves, cut at byte {shutoff} ({op:?} of {at:#x})");
            // The boot: repair, then load.
            let mut store = SceneStore::with_hooks(cut, RANGE, HOOKS).expect("a store");
            let z = block_on(store.zero_unreadable());
            assert!(matches!(z, Ok(Some(_))), "{step}: nothing zeroed: {z:?}");
            assert!(bad().is_empty(), "{step}: units left unzeroed: {:?}", bad());
            match block_on(store.load()) {
                Ok(Some(s)) if s == was => old += 1,
                Ok(Some(s)) if s == next => new += 1,
                other => panic!("{step}: neither the old nor the new scene: {other:?}"),
            }
            // Saves work again, and a reboot finds the last one.
            block_on(store.save(&saved(100)))
                .unwrap_or_else(|e| panic!("{step}: a save after the repair: {e:?}"));
            block_on(store.save(&saved(101)))
                .unwrap_or_else(|e| panic!("{step}: a second save: {e:?}"));
            let mut again =
                SceneStore::with_hooks(store.into_flash().expect("the flash"), RANGE, HOOKS)
                    .expect("a store");
            assert_eq!(
                block_on(again.load()),
                Ok(Some(saved(101))),
                "{step}: after a reboot"
            );
        }
    }
    (erase_cuts, old, new)
}

#[test]
fn a_power_cut_at_every_byte_of_a_save_on_an_ecc_flash_leaves_the_old_scene_or_the_new_after_zeroing(
) {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    // Up to 40 saves over four 512-byte pages: the default scene's item (~70 bytes) fills a
    // page in ~6 saves, so from ~20 saves on every page change erases the page after.
    let (erase_cuts, old, new) = sweep(40);
    eprintln!("{erase_cuts} cuts in an erase; {old} boots on the old scene, {new} on the new");
    assert!(
        erase_cuts > 0,
        "no save erased a page: the sweep missed the reclaim"
    );
    assert!(old > 0 && new > 0);
}

#[test]
fn a_store_without_bad_units_is_left_alone() {
    let _g = LOCK.lock().unwrap_or_else(|e| e.into_inner());
    bad().clear();
    let mut store = SceneStore::with_hooks(flash(&[0xFF; RANGE.end as usize], None), RANGE, HOOKS)
        .expect("a store");
    block_on(store.save(&saved(1))).expect("a save");
    let before = store
        .into_flash()
        .expect("the flash")
        .mock
        .as_bytes()
        .to_vec();
    let mut store = SceneStore::with_hooks(flash(&before, None), RANGE, HOOKS).expect("a store");
    assert_eq!(block_on(store.zero_unreadable()), Ok(None));
    assert_eq!(block_on(store.load()), Ok(Some(saved(1))));
    assert_eq!(
        store.into_flash().expect("the flash").mock.as_bytes(),
        &before[..]
    );
}
