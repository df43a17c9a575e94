//! Store images for the save checks: the flash a board's store is left in by earlier saves,
//! built on the host with the same `saw-store` the firmware runs, over sequential-storage's mock
//! NOR flash with the board's geometry (`saw_boards::StoreLayout`).

use saw_core::scene::Config;
use saw_store::{Saved, SceneStore};
use sequential_storage::mock_flash::MockFlashBase;

/// The store of `board` after as many saves of `scene(i)` (i = 0, 1, …) as fit before the next
/// one must erase a unit: its bytes (for `board.store.origin`), the last scene saved, and how
/// many saves that took.
pub fn before_an_erase(
    board: &saw_boards::BoardDef,
    scene: impl Fn(usize) -> Config,
) -> Result<(Vec<u8>, Saved, usize), String> {
    /// `PAGES` erase units of `PAGE_WORDS` words of `W` bytes: sequential-storage's own mock
    /// NOR flash (erased 0xFF, each word written once, erases counted).
    fn fill<const PAGES: usize, const W: usize, const PAGE_WORDS: usize>(
        scene: &dyn Fn(usize) -> Config,
    ) -> Result<(Vec<u8>, Saved, usize), String> {
        let mut flash = MockFlashBase::<PAGES, W, PAGE_WORDS>::default();
        let start = flash.stats_snapshot();
        let mut last: Option<Saved> = None;
        for i in 0..100_000 {
            let before = flash.as_bytes().to_vec();
            let config = scene(i);
            let saved = Saved {
                scene_id: saw_link::scene_id(&config),
                config,
            };
            let mut store = SceneStore::new(
                flash,
                MockFlashBase::<PAGES, W, PAGE_WORDS>::FULL_FLASH_RANGE,
            )
            .map_err(|e| e.to_string())?;
            embassy_futures::block_on(store.save(&saved)).map_err(|e| e.to_string())?;
            flash = store.into_flash().ok_or("the store lost its flash")?;
            if start.compare_to(flash.stats_snapshot()).erases > 0 {
                let last = last.ok_or("the first save already erased")?;
                return Ok((before, last, i));
            }
            last = Some(saved);
        }
        Err("no erase after 100 000 saves".into())
    }
    let s = board.store;
    match (s.write_bytes, s.erase_bytes, s.bytes / s.erase_bytes) {
        (4, 0x2_0000, 2) => fill::<2, 4, 0x8000>(&scene),
        (8, 0x800, 8) => fill::<8, 8, 0x100>(&scene),
        (w, e, n) => Err(format!(
            "no mock flash for {n} units of {e} bytes written {w} at a time"
        )),
    }
}
