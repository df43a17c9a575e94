//! Items the store did not write as this firmware's scene: an item of another layout version, one
//! that does not decode, one with bytes after the scene, and a scene saved before
//! `limits.max_level_percent` was added (the layout of firmware before commit 6e8654e7, still
//! tagged format 1). Each load reports it (`OtherFormat`, `Undecodable`) and returns no scene, so
//! the boot runs the embedded or default scene (firmware `boot_scene`, host-sim
//! `VirtualBoard::boot`, `host-sim/tests/boot_fallback.rs`); the next save replaces it. The item
//! layout of format 1 is pinned byte for byte, so a change to `Config`'s encoding shows here and
//! prompts a bump of `FORMAT`.
//!
//! The foreign items are written with sequential-storage's own map under the store's key (0), as
//! another firmware using this crate's map would have left them.

use embassy_futures::block_on;
use saw_core::scene::Config;
use saw_store::{Saved, SceneStore, StoreError, FORMAT, ITEM_BYTES};
use sequential_storage::cache::Cache;
use sequential_storage::map::{MapConfig, MapStorage};
use sequential_storage::mock_flash::{MockFlashBase, WriteCountCheck};

/// Two 2 KiB pages of 4-byte words.
type Flash = MockFlashBase<2, 4, 512>;
const RANGE: core::ops::Range<u32> = Flash::FULL_FLASH_RANGE;

/// A scene with every section and several texture kinds, from the test's own text (so the
/// layout pin below moves only with the encoding or the scene file's reading, not with the
/// repository's scene files or the built-in default).
const SCENE: &str = r#"
[[region]]
kind = "grating"
until_mm = 30
wavelength_mm = 0.2
render = "hybrid"

[[region]]
kind = "random"
f_b_hz = 150
spread_percent = 20
amplitude_percent = 80
amplitude_spread_percent = 20
seed = 2

[lines]
positions_mm = [10, 43]
pulse_ms = 10
envelope = "triangle"
amplitude_percent = 90
rearm_mm = 0.2
"#;

fn scene() -> Config {
    saw_core::scene_file::parse("foreign.rs", SCENE)
        .expect("the test's scene reads")
        .config
}

const SCENE_ID: u32 = 0x5A5A_0001;

/// A flash whose store holds `item` as its scene item, written by the map itself.
fn holding(item: &[u8]) -> Flash {
    let mut map = MapStorage::<u8, _, _>::new(
        Flash::new(WriteCountCheck::OnceOnly, None, true),
        MapConfig::try_new(RANGE).unwrap(),
        Cache::new_uncached(),
    );
    let mut buf = [0u8; ITEM_BYTES];
    block_on(map.store_item(&mut buf, &0u8, &item)).expect("the map stores the item");
    map.destroy().0
}

/// The item the store writes for `saved`, read back raw through the map.
fn item_written(saved: &Saved) -> Vec<u8> {
    let mut store =
        SceneStore::new(Flash::new(WriteCountCheck::OnceOnly, None, true), RANGE).unwrap();
    block_on(store.save(saved)).unwrap();
    let mut map = MapStorage::<u8, _, _>::new(
        store.into_flash().unwrap(),
        MapConfig::try_new(RANGE).unwrap(),
        Cache::new_uncached(),
    );
    let mut buf = [0u8; ITEM_BYTES];
    let item: Option<&[u8]> = block_on(map.fetch_item(&mut buf, &0u8)).unwrap();
    item.expect("the saved item").to_vec()
}

/// Loads from a store holding `item` (after a reboot: a fresh store over the flash); then a save
/// replaces it and loads back.
fn load_then_save(item: &[u8]) -> Result<Option<Saved>, StoreError> {
    let mut store = SceneStore::new(holding(item), RANGE).unwrap();
    let loaded = block_on(store.load());
    let next = Saved {
        scene_id: 7,
        config: scene(),
    };
    block_on(store.save(&next)).expect("a save over a foreign item works");
    let mut rebooted = SceneStore::new(store.into_flash().unwrap(), RANGE).unwrap();
    assert_eq!(
        block_on(rebooted.load()),
        Ok(Some(next)),
        "the save replaced it"
    );
    loaded
}

/// `[tag] ‖ postcard(scene_id, config)`: this firmware's body behind any tag.
fn tagged(tag: u8, config: &Config) -> Vec<u8> {
    let mut item = vec![tag];
    item.extend(postcard::to_allocvec(&(SCENE_ID, config)).unwrap());
    item
}

#[test]
fn this_firmwares_item_loads() {
    // The helper writes what the store reads: the checks below are not refusals of the helper.
    assert_eq!(
        load_then_save(&tagged(FORMAT, &scene())),
        Ok(Some(Saved {
            scene_id: SCENE_ID,
            config: scene()
        }))
    );
}

#[test]
fn an_item_of_another_format_is_reported_not_read_as_a_scene() {
    // A body this firmware would decode, behind another version's tag: refused by the tag.
    for tag in [0u8, FORMAT + 1, 0xFF] {
        assert_eq!(
            load_then_save(&tagged(tag, &scene())),
            Err(StoreError::OtherFormat { found: tag }),
            "tag {tag}"
        );
    }
    assert_eq!(
        StoreError::OtherFormat { found: 2 }.to_string(),
        "the saved scene has layout version 2, this firmware reads 1"
    );
}

#[test]
fn an_item_that_does_not_decode_is_reported() {
    let whole = tagged(FORMAT, &scene());
    let cases: [(&str, Vec<u8>); 5] = [
        ("empty", vec![]),
        ("a tag alone", vec![FORMAT]),
        ("cut one byte short", whole[..whole.len() - 1].to_vec()),
        ("0xFF bytes", {
            let mut v = vec![FORMAT];
            v.extend([0xFF; 40]);
            v
        }),
        // Bytes after the scene: not this firmware's item (it writes the scene and nothing else),
        // so a longer layout whose start happens to decode is not taken for a scene.
        ("a byte after the scene", {
            let mut v = whole.clone();
            v.push(0);
            v
        }),
    ];
    for (what, item) in cases {
        assert_eq!(
            load_then_save(&item),
            Err(StoreError::Undecodable),
            "{what}: {item:?}"
        );
    }
}

/// A scene saved by firmware from before `limits.max_level_percent` (commit 6e8654e7): format 1,
/// `SafetyLimits` without `max_level_permille`. It is reported as not decoding (the field read
/// in its place leaves the last one short), never loaded as another scene: such a board boots
/// its embedded or default scene once, logging "boot: the saved scene cannot be read (the saved
/// scene does not decode)", until the scene is saved again.
#[test]
fn a_scene_saved_before_the_level_cap_does_not_decode() {
    let c = scene();
    let mut old = vec![1u8];
    // postcard writes a struct as its fields in order: the old Config, field by field.
    old.extend(
        postcard::to_allocvec(&(
            SCENE_ID,
            &c.calibration,
            &c.scene,
            (c.limits.max_duty_permille, c.limits.max_on_time_us),
            c.stale_after_us,
        ))
        .unwrap(),
    );
    assert_eq!(load_then_save(&old), Err(StoreError::Undecodable));
}

/// Snapshot of format 1's item for the test's scene. If this fails, `Config`'s encoding (or the
/// scene file's reading of `SCENE`) changed. A scene saved by the firmware in the field is an
/// item of the old bytes: if a field was added, removed, reordered or retyped, bump
/// `saw_store::FORMAT` (such items are then reported as another format instead of being
/// decoded as this one) and take the new bytes here; if only a value the scene file gives
/// changed, take the new bytes.
#[test]
fn format_1_item_layout_snapshot() {
    assert_eq!(FORMAT, 1, "this snapshot is format 1's");
    let item = item_written(&Saved {
        scene_id: SCENE_ID,
        config: scene(),
    });
    let hex: String = item.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(hex, SNAPSHOT_FORMAT_1, "the item's bytes changed");
}

const SNAPSHOT_FORMAT_1: &str = "018180e8d2059e0ae1f50398ec038f0501b0ea010202c80190039875e807023204f09309c801a006c8019003026402904ef8cf02904e018407c80100f403d08603e8078827";
