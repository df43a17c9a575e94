//! 2D scenes in the store (issue #36, feature `plane`): a 2D scene round-trips through a store
//! of `ITEM_BYTES_2D`, the largest a scene file allows fits a G474 page, a 1D and a 2D item are
//! kept apart by their tag (a 1D load never decodes a 2D item, nor the reverse), and a 2D save
//! cut at any byte leaves the old scene or the new one.
#![cfg(feature = "plane")]

use embassy_futures::block_on;
use saw_core::burst::BurstTimer;
use saw_link::msg::PlaneScene;
use saw_store::Hooks;
use saw_store::{Saved, Saved2d, SceneStore, StoreError, FORMAT_2D, ITEM_BYTES, ITEM_BYTES_2D};
use sequential_storage::mock_flash::{MockFlashBase, WriteCountCheck};

/// Eight 2 KiB pages of 8-byte words: the G474's store (the smaller erase unit of the two
/// boards, so the one that bounds a 2D item).
type G474 = MockFlashBase<8, 8, 256>;
const G474_RANGE: core::ops::Range<u32> = G474::FULL_FLASH_RANGE;

/// The F446's timer, which only needs to accept the scenes' f_b.
const TIMER: BurstTimer = BurstTimer {
    clock_hz: 90_000_000,
    counter_bits: 32,
    max_burst_hz: 2_000,
};

fn plane(path: &str) -> PlaneScene {
    let p = concat!(env!("CARGO_MANIFEST_DIR"), "/../").to_string() + path;
    let text = std::fs::read_to_string(&p).unwrap();
    let config = saw_core::scene_file::load_2d_for_board(path, &text, TIMER, 355)
        .unwrap_or_else(|e| panic!("{path}: {e}"));
    let plate_um = saw_core::scene_file::plate_um_of(path, &text).unwrap();
    PlaneScene { plate_um, config }
}

fn fig12() -> Saved2d {
    let scene = plane("scenes/2d-fig12.toml");
    Saved2d {
        scene_id: saw_link::plane_scene_id(&scene),
        scene,
    }
}

fn largest() -> Saved2d {
    let scene = plane("board-model/scenes/2d-largest.toml");
    Saved2d {
        scene_id: saw_link::plane_scene_id(&scene),
        scene,
    }
}

fn store() -> SceneStore<G474, ITEM_BYTES_2D> {
    over(G474::new(WriteCountCheck::OnceOnly, None, true))
}

/// A 2D store over `flash` (a reboot: the store built afresh).
fn over(flash: G474) -> SceneStore<G474, ITEM_BYTES_2D> {
    SceneStore::sized(flash, G474_RANGE, Hooks::NONE).unwrap()
}

#[test]
fn a_2d_scene_round_trips_and_survives_a_reboot() {
    let mut s = store();
    assert_eq!(block_on(s.load_2d()), Ok(None));
    for saved in [fig12(), largest(), fig12()] {
        block_on(s.save_2d(saved.scene_id, &saved.scene)).unwrap();
        assert_eq!(block_on(s.load_2d()), Ok(Some(saved.clone())));
        let mut again = over(s.into_flash().unwrap());
        assert_eq!(block_on(again.load_2d()), Ok(Some(saved)));
        s = again;
    }
}

#[test]
fn the_largest_2d_scene_fits_the_item_and_a_g474_page() {
    let big = largest();
    // Its encoding, measured here: tag + (id, scene) must fit the item buffer with the map's key,
    // and a G474 page: 2 048 bytes less two 8-byte page markers and an 8-byte item header.
    let item = 1 + postcard::to_allocvec(&(u32::MAX, &big.scene))
        .unwrap()
        .len();
    assert!(item > ITEM_BYTES, "{item} bytes: a 1D item would hold it");
    assert!(item + 1 <= ITEM_BYTES_2D, "{item} bytes");
    assert!(item + 1 <= 2048 - 16 - 8, "{item} bytes");
    println!("the largest 2D scene's item: {item} bytes");
    // Saved eight times over (every page used, pages erased for room) and loaded back.
    let mut s = store();
    for i in 0..24u32 {
        let saved = Saved2d {
            scene_id: i,
            ..big.clone()
        };
        block_on(s.save_2d(saved.scene_id, &saved.scene))
            .unwrap_or_else(|e| panic!("save {i}: {e}"));
        assert_eq!(block_on(s.load_2d()), Ok(Some(saved)));
    }
}

#[test]
fn a_2d_scene_does_not_fit_a_1d_store() {
    let mut s: SceneStore<G474> =
        SceneStore::new(G474::new(WriteCountCheck::OnceOnly, None, true), G474_RANGE).unwrap();
    assert_eq!(
        block_on(s.save_2d(1, &largest().scene)),
        Err(StoreError::TooLarge)
    );
}

#[test]
fn a_1d_and_a_2d_item_are_kept_apart() {
    let one = Saved {
        scene_id: 0x1D,
        config: saw_core::default_config(),
    };
    // A 2D item read by a 1D board: refused by its tag, never decoded.
    let mut s = store();
    block_on(s.save_2d(fig12().scene_id, &fig12().scene)).unwrap();
    assert_eq!(
        block_on(s.load()),
        Err(StoreError::WrongKind { saved_2d: true })
    );
    assert_eq!(
        StoreError::WrongKind { saved_2d: true }.to_string(),
        "the saved scene is a 2D scene (windows on the touch overlay) and this firmware runs 1D scenes; the next save replaces it"
    );
    // The 1D save replaces it (one key: one scene to boot into), and the 2D board then refuses
    // the 1D item.
    block_on(s.save(&one)).unwrap();
    assert_eq!(block_on(s.load()), Ok(Some(one.clone())));
    assert_eq!(
        block_on(s.load_2d()),
        Err(StoreError::WrongKind { saved_2d: false })
    );
    // And a 2D save replaces the 1D one.
    block_on(s.save_2d(fig12().scene_id, &fig12().scene)).unwrap();
    assert_eq!(block_on(s.load_2d()), Ok(Some(fig12())));
}

#[test]
fn a_2d_item_of_another_layout_is_reported() {
    // fig12's body behind the next 2D layout's tag, as a later firmware would have left it.
    let mut s = store();
    let body = postcard::to_allocvec(&(7u32, &fig12().scene)).unwrap();
    // A raw item: tag FORMAT_2D + 1 ‖ body, written with sequential-storage's map under key 0.
    let mut flash = s.into_flash().unwrap();
    {
        use sequential_storage::cache::Cache;
        use sequential_storage::map::{MapConfig, MapStorage};
        let mut map = MapStorage::<u8, _, _>::new(
            flash,
            MapConfig::try_new(G474_RANGE).unwrap(),
            Cache::new_uncached(),
        );
        let mut item = vec![FORMAT_2D + 1];
        item.extend(&body);
        let mut buf = [0u8; ITEM_BYTES_2D];
        block_on(map.store_item(&mut buf, &0u8, &item.as_slice())).unwrap();
        flash = map.destroy().0;
    }
    s = over(flash);
    assert_eq!(
        block_on(s.load_2d()),
        Err(StoreError::OtherFormat2d {
            found: FORMAT_2D + 1
        })
    );
    assert_eq!(
        block_on(s.load()),
        Err(StoreError::OtherFormat {
            found: FORMAT_2D + 1
        })
    );
}

/// Four 2 KiB pages of 8-byte words: two of the largest 2D items a page, so the saves below change
/// page and erase.
type Small = MockFlashBase<4, 8, 256>;
const SMALL: core::ops::Range<u32> = Small::FULL_FLASH_RANGE;

fn small(flash: Small) -> SceneStore<Small, ITEM_BYTES_2D> {
    SceneStore::sized(flash, SMALL, Hooks::NONE).unwrap()
}

/// Saves fig12, then `history` saves of the largest scene, then the largest scene with another
/// id with the power cut at every byte of its save: after each cut the old or the new scene
/// loads, and the store saves again. Returns the cut points tried.
fn cut_everywhere(history: u32) -> u32 {
    let mut s = small(Small::new(WriteCountCheck::OnceOnly, None, true));
    let mut old = fig12();
    block_on(s.save_2d(old.scene_id, &old.scene)).unwrap();
    for h in 0..history {
        old = Saved2d {
            scene_id: 100 + h,
            ..largest()
        };
        block_on(s.save_2d(old.scene_id, &old.scene)).unwrap();
    }
    let base = s.into_flash().unwrap();
    let next = Saved2d {
        scene_id: 999,
        ..largest()
    };
    let mut cut = 0;
    loop {
        let mut flash = base.clone();
        flash.bytes_until_shutoff = Some(cut);
        let mut s = small(flash);
        let result = block_on(s.save_2d(next.scene_id, &next.scene));
        let mut flash = s.into_flash().unwrap();
        let finished = flash.bytes_until_shutoff.is_some();
        assert_eq!(result.is_ok(), finished, "cut {cut}: {result:?}");
        flash.bytes_until_shutoff = None;
        let mut s = small(flash);
        let loaded =
            block_on(s.load_2d()).unwrap_or_else(|e| panic!("history {history}, cut {cut}: {e}"));
        assert!(
            loaded.as_ref() == Some(&old) || loaded.as_ref() == Some(&next),
            "history {history}, cut {cut}: neither the old scene nor the new one"
        );
        if finished {
            assert_eq!(loaded, Some(next.clone()));
        }
        let after = fig12();
        block_on(s.save_2d(after.scene_id, &after.scene))
            .unwrap_or_else(|e| panic!("history {history}, cut {cut}: {e}"));
        assert_eq!(block_on(s.load_2d()), Ok(Some(after)));
        if finished {
            return cut;
        }
        cut += 1;
    }
}

#[test]
fn a_cut_at_any_byte_of_a_2d_save_leaves_the_old_or_the_new_scene() {
    let item = 1 + postcard::to_allocvec(&(999u32, &largest().scene))
        .unwrap()
        .len() as u32;
    let into_room = cut_everywhere(0);
    assert!(
        into_room >= item,
        "{into_room} cut points for a {item}-byte item"
    );
    // With 1 to 8 earlier saves of the largest scene (two to a 2 KiB page) the save changes
    // page, and once the four pages are used it must erase one first.
    let mut most = 0;
    for history in 1..=8 {
        most = most.max(cut_everywhere(history));
    }
    assert!(
        most > 2048,
        "no save erased a page ({most} cut points at most)"
    );
    println!("2D save cut points: {into_room} into a page with room, up to {most} with an erase");
}
