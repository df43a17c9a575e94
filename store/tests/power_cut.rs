//! The store under power loss: a save cut at every byte of every write and erase leaves, after a
//! reboot, the old scene or the new one, whole, and the store keeps working.

use embassy_futures::block_on;
use proptest::prelude::*;
use saw_core::scene::{default_config, Config};
use saw_store::{Saved, SceneStore, StoreError, ITEM_BYTES};
use sequential_storage::mock_flash::{MockFlashBase, WriteCountCheck};

/// Four 2 KiB pages of 4-byte words (the G474's page size; the F446's 128 KiB sectors only
/// make wrap-around rarer).
type Flash = MockFlashBase<4, 4, 512>;
const RANGE: core::ops::Range<u32> = Flash::FULL_FLASH_RANGE;
/// Four 512-byte pages: one or two scenes a page, so a few saves change page and erase, and the
/// power can be cut inside those steps too.
type Small = MockFlashBase<4, 4, 128>;
const SMALL: core::ops::Range<u32> = Small::FULL_FLASH_RANGE;

fn scenes() -> Vec<Config> {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes");
    let mut paths: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        // 1D scenes only: the store keeps no 2D scene (issue #36's `scenes/2d-*.toml`).
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            saw_core::scene_file::sensor_of(&p.display().to_string(), &text)
                == Ok(saw_core::scene_file::SensorKind::Rheostat)
        })
        .collect();
    paths.sort();
    paths
        .iter()
        .map(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            saw_core::scene_file::parse(&p.display().to_string(), &text)
                .unwrap()
                .config
        })
        .collect()
}

fn saved(i: u32, config: Config) -> Saved {
    Saved {
        scene_id: 0x5000 + i,
        config,
    }
}

fn fresh() -> Flash {
    Flash::new(WriteCountCheck::OnceOnly, None, true)
}

#[test]
fn every_scene_file_round_trips() {
    let mut store = SceneStore::new(fresh(), RANGE).unwrap();
    assert_eq!(
        block_on(store.load()),
        Ok(None),
        "an erased flash holds no scene"
    );
    for (i, c) in scenes().into_iter().enumerate() {
        let s = saved(i as u32, c);
        block_on(store.save(&s)).unwrap();
        assert_eq!(block_on(store.load()), Ok(Some(s.clone())));
        // And after a reboot.
        let mut again = SceneStore::new(store.into_flash().unwrap(), RANGE).unwrap();
        assert_eq!(block_on(again.load()), Ok(Some(s)));
        store = again;
    }
}

#[test]
fn largest_scene_fits() {
    let big = saw_core::scene::largest_config();
    let encoded = postcard::to_allocvec(&(u32::MAX, &big)).unwrap().len();
    assert!(encoded + 1 + 16 < ITEM_BYTES, "{encoded} bytes");
    let mut store = SceneStore::new(fresh(), RANGE).unwrap();
    let s = Saved {
        scene_id: u32::MAX,
        config: big,
    };
    block_on(store.save(&s)).unwrap();
    assert_eq!(block_on(store.load()), Ok(Some(s)));
}

/// Cuts the power at byte `cut` of saving `next` over a flash holding `old`; reboots; returns
/// what loads then, and whether the save had finished before the cut.
fn cut_at(
    base: &Small,
    next: &Saved,
    cut: u32,
) -> (Result<Option<Saved>, StoreError>, bool, Small) {
    let mut flash = base.clone();
    flash.bytes_until_shutoff = Some(cut);
    let mut store = SceneStore::new(flash, SMALL).unwrap();
    let result = block_on(store.save(next));
    let mut flash = store.into_flash().unwrap();
    let finished = flash.bytes_until_shutoff.is_some();
    assert_eq!(result.is_ok(), finished, "cut {cut}: {result:?}");
    flash.bytes_until_shutoff = None;
    let mut rebooted = SceneStore::new(flash, SMALL).unwrap();
    let loaded = block_on(rebooted.load());
    (loaded, finished, rebooted.into_flash().unwrap())
}

/// Saves A, then (`history` more saves to push the store towards a page change), then B with
/// the power cut at every byte: after each cut the old scene or B loads, and a further save
/// works. Returns the cut points tried.
fn cut_everywhere(history: usize) -> u32 {
    let scenes = scenes();
    let mut store =
        SceneStore::new(Small::new(WriteCountCheck::OnceOnly, None, true), SMALL).unwrap();
    let mut old = saved(0, scenes[0].clone());
    block_on(store.save(&old)).unwrap();
    for h in 0..history {
        old = saved(1 + h as u32, scenes[(1 + h) % scenes.len()].clone());
        block_on(store.save(&old)).unwrap();
    }
    let base = store.into_flash().unwrap();
    // The largest scene file, whatever the directory holds (a small one, as `rf-off.toml`, would
    // leave the page changes to chance).
    let largest = scenes
        .iter()
        .max_by_key(|c| postcard::to_allocvec(c).map_or(0, |v| v.len()))
        .expect("the scenes directory holds scenes");
    let next = saved(999, largest.clone());
    let mut cut = 0;
    loop {
        let (loaded, finished, flash) = cut_at(&base, &next, cut);
        let loaded = loaded.unwrap_or_else(|e| panic!("history {history}, cut {cut}: {e}"));
        assert!(
            loaded.as_ref() == Some(&old) || loaded.as_ref() == Some(&next),
            "history {history}, cut {cut}: neither the old scene nor the new one: {loaded:?}"
        );
        if finished {
            assert_eq!(loaded, Some(next.clone()));
        }
        // The store keeps working after the cut.
        let mut store = SceneStore::new(flash, SMALL).unwrap();
        let after = saved(7, scenes[1].clone());
        block_on(store.save(&after))
            .unwrap_or_else(|e| panic!("history {history}, cut {cut}: {e}"));
        assert_eq!(block_on(store.load()), Ok(Some(after)));
        if finished {
            return cut;
        }
        cut += 1;
    }
}

#[test]
fn a_cut_at_any_byte_of_a_save_leaves_the_old_or_the_new_scene() {
    // A save into a page with room.
    let cuts = cut_everywhere(0);
    // At least every byte of the item itself.
    let item = scenes()
        .iter()
        .map(|c| 1 + postcard::to_allocvec(&(999u32, c)).unwrap().len() as u32)
        .max()
        .unwrap();
    assert!(
        cuts >= item,
        "only {cuts} cut points for a {item}-byte item"
    );
    // Saves that fill pages: the cut save must move to the next page, and further on erase
    // one (each item is a few hundred bytes; 2 KiB pages hold a handful).
    let mut with_erase = 0;
    for history in 1..=24 {
        with_erase = with_erase.max(cut_everywhere(history));
    }
    // An erase is 512 cut points on its own: some history made the save erase a page first.
    assert!(
        with_erase > 512,
        "no save erased a page ({with_erase} cut points at most)"
    );
    println!(
        "cut points: {cuts} into a page with room, up to {with_erase} with a page change and erase"
    );
}

/// What a save over `flash` did: `None` if it failed (the error is typed: nothing to check), else
/// it checks that the scene it stored is what a boot loads. The load before the save only has to
/// return (a typed error or whatever the bytes hold).
fn save_over(flash: Flash) -> Option<()> {
    let mut store = SceneStore::new(flash, RANGE).unwrap();
    let _ = block_on(store.load());
    let s = saved(1, default_config());
    block_on(store.save(&s)).ok()?;
    // A reboot: the map's cache, which knows where the save wrote, is gone, as at boot.
    let mut rebooted = SceneStore::new(store.into_flash().unwrap(), RANGE).unwrap();
    assert_eq!(
        block_on(rebooted.load()),
        Ok(Some(s)),
        "the save said Ok; after a reboot"
    );
    Some(())
}

/// A flash of `bytes`, written over as a board's flash would be (a write only clears bits).
fn flash_of(bytes: &[u8]) -> Flash {
    let mut flash = Flash::new(WriteCountCheck::Disabled, None, true);
    flash.as_bytes_mut().copy_from_slice(bytes);
    flash
}

/// Erased flash (0xFF) with random words written over `permille` of its words: the garbage a
/// board's store region holds after other firmware used the sectors, where much of it is erased
/// and saves can succeed (a flash of random bytes throughout refuses nearly every save).
fn sprinkled(seed: &[u8], permille: u16) -> Vec<u8> {
    let mut bytes = vec![0xFF; 8192];
    for (w, chunk) in bytes.chunks_mut(4).enumerate() {
        // A hash of the word's index and the seed picks the words and their values.
        let h = (seed[w % seed.len()] as u32 ^ (w as u32) << 8).wrapping_mul(0x9E37_79B1);
        if (h >> 16) % 1000 < permille as u32 {
            chunk.copy_from_slice(&h.to_le_bytes());
        }
    }
    bytes
}

proptest! {
    /// A flash of random bytes: load answers with whatever it answers without a panic, and a
    /// save over it either says why it failed or, when it says Ok, stored the scene: it loads
    /// back, before and after a reboot.
    #[test]
    fn garbage_flash_never_panics_and_an_ok_save_loads_back(bytes in proptest::collection::vec(any::<u8>(), 8192)) {
        let _ = save_over(flash_of(&bytes));
    }

    /// The same over erased flash with a few random words: here saves do succeed (counted by
    /// `saves_over_garbage_do_succeed`), and each that says Ok loads back.
    #[test]
    fn a_save_over_sprinkled_flash_that_says_ok_loads_back(
        seed in proptest::collection::vec(any::<u8>(), 64),
        permille in 1u16..50,
    ) {
        let _ = save_over(flash_of(&sprinkled(&seed, permille)));
    }
}

/// The properties above are not vacuous: over the sprinkled flash most saves say Ok, so a save
/// that said Ok without storing its scene would show.
#[test]
fn saves_over_garbage_do_succeed() {
    let mut ok = 0;
    for i in 0..64u8 {
        let seed: Vec<u8> = (0..64u8)
            .map(|k| k.wrapping_mul(31).wrapping_add(i.wrapping_mul(97)))
            .collect();
        if save_over(flash_of(&sprinkled(&seed, 1 + (i as u16 % 49)))).is_some() {
            ok += 1;
        }
    }
    eprintln!("{ok} of 64 saves over sprinkled flash said Ok");
    assert!(ok >= 16, "{ok} of 64 saves over sprinkled flash said Ok");
}

#[test]
fn a_range_that_is_not_two_whole_pages_is_refused() {
    assert!(matches!(
        SceneStore::new(fresh(), 0..2048),
        Err(StoreError::BadRange)
    ));
    assert!(matches!(
        SceneStore::new(fresh(), 100..4196),
        Err(StoreError::BadRange)
    ));
    assert!(SceneStore::new(fresh(), 0..4096).is_ok());
}
