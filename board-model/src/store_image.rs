//! Store images for the save checks: the flash a board's store is left in by earlier saves,
//! built on the host with the same `saw-store` the firmware runs, over sequential-storage's mock
//! NOR flash with the board's geometry (`saw_boards::StoreLayout`). 1D scenes (`before_an_erase`)
//! and 2D ones (`before_an_erase_2d`, the 2D image's item: issue #36).

use saw_core::scene::Config;
use saw_link::msg::PlaneScene;
use saw_store::{Saved, Saved2d, SceneStore, ITEM_BYTES_2D};
use sequential_storage::mock_flash::MockFlashBase;

/// A scene the store keeps, saved as its kind of board saves it.
pub trait Item: Clone {
    /// `self` saved into a store over `flash` (its whole range); the flash back.
    fn save_into<const P: usize, const W: usize, const PW: usize>(
        &self,
        flash: MockFlashBase<P, W, PW>,
    ) -> Result<MockFlashBase<P, W, PW>, String>;
}

impl Item for Saved {
    fn save_into<const P: usize, const W: usize, const PW: usize>(
        &self,
        flash: MockFlashBase<P, W, PW>,
    ) -> Result<MockFlashBase<P, W, PW>, String> {
        let mut store = SceneStore::new(flash, MockFlashBase::<P, W, PW>::FULL_FLASH_RANGE)
            .map_err(|e| e.to_string())?;
        embassy_futures::block_on(store.save(self)).map_err(|e| e.to_string())?;
        store.into_flash().ok_or("the store lost its flash".into())
    }
}

impl Item for Saved2d {
    fn save_into<const P: usize, const W: usize, const PW: usize>(
        &self,
        flash: MockFlashBase<P, W, PW>,
    ) -> Result<MockFlashBase<P, W, PW>, String> {
        let mut store = SceneStore::<_, ITEM_BYTES_2D>::sized(
            flash,
            MockFlashBase::<P, W, PW>::FULL_FLASH_RANGE,
            saw_store::Hooks::NONE,
        )
        .map_err(|e| e.to_string())?;
        embassy_futures::block_on(store.save_2d(self.scene_id, &self.scene))
            .map_err(|e| e.to_string())?;
        store.into_flash().ok_or("the store lost its flash".into())
    }
}

/// The store of `board` after as many saves of `scene(i)` (i = 0, 1, …) as fit before the next
/// one must erase a unit: its bytes (for `board.store.origin`), the last scene saved, and how
/// many saves that took.
pub fn before_an_erase(
    board: &saw_boards::BoardDef,
    scene: impl Fn(usize) -> Config,
) -> Result<(Vec<u8>, Saved, usize), String> {
    filled(board, &|i| {
        let config = scene(i);
        Saved {
            scene_id: saw_link::scene_id(&config),
            config,
        }
    })
}

/// The same for the 2D image: saves of the 2D scene `scene(i)`.
pub fn before_an_erase_2d(
    board: &saw_boards::BoardDef,
    scene: impl Fn(usize) -> PlaneScene,
) -> Result<(Vec<u8>, Saved2d, usize), String> {
    filled(board, &|i| {
        let scene = scene(i);
        Saved2d {
            scene_id: saw_link::plane_scene_id(&scene),
            scene,
        }
    })
}

fn filled<T: Item>(
    board: &saw_boards::BoardDef,
    saved: &dyn Fn(usize) -> T,
) -> Result<(Vec<u8>, T, usize), String> {
    /// `PAGES` erase units of `PAGE_WORDS` words of `W` bytes: sequential-storage's own mock
    /// NOR flash (erased 0xFF, each word written once, erases counted).
    fn fill<T: Item, const PAGES: usize, const W: usize, const PAGE_WORDS: usize>(
        saved: &dyn Fn(usize) -> T,
    ) -> Result<(Vec<u8>, T, usize), String> {
        let mut flash = MockFlashBase::<PAGES, W, PAGE_WORDS>::default();
        let start = flash.stats_snapshot();
        let mut last: Option<T> = None;
        for i in 0..100_000 {
            let before = flash.as_bytes().to_vec();
            let s = saved(i);
            flash = s.save_into(flash)?;
            if start.compare_to(flash.stats_snapshot()).erases > 0 {
                let last = last.ok_or("the first save already erased")?;
                return Ok((before, last, i));
            }
            last = Some(s);
        }
        Err("no erase after 100 000 saves".into())
    }
    let s = board.store;
    match (s.write_bytes, s.erase_bytes, s.bytes / s.erase_bytes) {
        (4, 0x2_0000, 2) => fill::<T, 2, 4, 0x8000>(saved),
        (8, 0x800, 8) => fill::<T, 8, 8, 0x100>(saved),
        (w, e, n) => Err(format!(
            "no mock flash for {n} units of {e} bytes written {w} at a time"
        )),
    }
}
