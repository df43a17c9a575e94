//! The virtual board's boot when the store holds nothing usable: a store whose load returns no
//! scene (nothing saved, another format, an item that does not decode: `saw-store`'s
//! `tests/foreign.rs` checks that its load reports those and returns none), a saved scene the
//! controller refuses, and a flash file of stray bytes. The board boots the scene it was started
//! with (the embedded one, `SceneSource::BuildTime`, or the built-in default), and says so; only
//! a readable scene the controller takes boots as `Saved`.

use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::Arc;

use host_sim::serve::board::{Persist, VirtualBoard};
use host_sim::serve::flash;
use host_sim::sim::{burst_timer, sample_period_us, SimParams};
use host_sim::trajectory::Trajectory;
use rand::{RngCore, SeedableRng};
use saw_boards::{BoardDef, NUCLEO_F446RE, NUCLEO_G474RE};
use saw_core::scene::Config;
use saw_core::Controller;
use saw_link::msg::{SceneSource, StoreFault};

/// A store that answers `load` with `scene` and counts the loads.
struct Stub {
    scene: Option<(u32, Config)>,
    loads: Arc<AtomicU32>,
}

impl Persist for Stub {
    fn load(&mut self) -> Option<(u32, Config)> {
        self.loads.fetch_add(1, Ordering::SeqCst);
        self.scene.clone()
    }
    fn save(&mut self, _: u32, _: &Config) -> Result<(), StoreFault> {
        Ok(())
    }
}

fn scene_file(board: &BoardDef, name: &str) -> Config {
    let path = format!("{}/../scenes/{name}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap();
    saw_core::scene_file::load_for_board(&path, &text, burst_timer(board), sample_period_us(board))
        .unwrap()
}

/// Boots `board` started with `fallback` (from `source`) over `store`: the scene it runs and
/// where that came from.
fn boot(
    board: &'static BoardDef,
    fallback: &Config,
    source: SceneSource,
    store: Option<Box<dyn Persist + Send>>,
) -> (Config, SceneSource) {
    let params = SimParams::new(board, Trajectory::Rest { at_um: 20_000.0 }, 0.01)
        .with_config(fallback.clone());
    let ctrl = Controller::new(burst_timer(board), sample_period_us(board)).unwrap();
    let b = VirtualBoard::boot(&params, ctrl, source, store).unwrap();
    (b.config, b.source)
}

fn stub(scene: Option<(u32, Config)>) -> (Box<dyn Persist + Send>, Arc<AtomicU32>) {
    let loads = Arc::new(AtomicU32::new(0));
    (
        Box::new(Stub {
            scene,
            loads: loads.clone(),
        }),
        loads,
    )
}

#[test]
fn a_store_with_nothing_usable_boots_the_scene_started_with() {
    let b = &NUCLEO_F446RE;
    // The embedded scene (as `--scene`) and the built-in default: each is what runs.
    for (fallback, source) in [
        (scene_file(b, "grating.toml"), SceneSource::BuildTime),
        (saw_core::default_config(), SceneSource::Default),
    ] {
        let (store, loads) = stub(None);
        let (config, booted) = boot(b, &fallback, source, Some(store));
        assert_eq!(loads.load(Ordering::SeqCst), 1, "the store was asked once");
        assert_eq!(booted, source);
        assert_eq!(config, fallback, "{source:?}: not the scene started with");
    }
    // No store at all: the same.
    let fallback = scene_file(b, "random.toml");
    assert_eq!(
        boot(b, &fallback, SceneSource::BuildTime, None),
        (fallback, SceneSource::BuildTime)
    );
}

/// The contrast the checks above rely on: a readable saved scene the controller takes boots,
/// and is reported as saved.
#[test]
fn a_readable_saved_scene_boots_as_saved() {
    let b = &NUCLEO_F446RE;
    let saved = scene_file(b, "lines.toml");
    let (store, _) = stub(Some((0x1234, saved.clone())));
    let fallback = scene_file(b, "grating.toml");
    assert_ne!(saved, fallback);
    assert_eq!(
        boot(b, &fallback, SceneSource::BuildTime, Some(store)),
        (saved, SceneSource::Saved)
    );
}

#[test]
fn a_saved_scene_the_controller_refuses_boots_the_scene_started_with() {
    let b = &NUCLEO_F446RE;
    let mut refused = scene_file(b, "lines.toml");
    // A region past the travel's end: decoded, but the controller refuses it.
    refused.scene.boundaries_um.clear();
    let _ = refused
        .scene
        .boundaries_um
        .push(refused.calibration.length_um + 1_000);
    let _ = refused
        .scene
        .textures
        .push(saw_core::texture::Texture::constant_hz(50));
    let mut probe = Controller::new(burst_timer(b), sample_period_us(b)).unwrap();
    assert!(probe.load(&refused).is_err(), "the scene is refused");
    let (store, _) = stub(Some((0x1234, refused)));
    let fallback = scene_file(b, "grating.toml");
    assert_eq!(
        boot(b, &fallback, SceneSource::BuildTime, Some(store)),
        (fallback, SceneSource::BuildTime)
    );
}

/// The store over a flash file (`host-sim serve --flash`) that holds stray bytes: whatever the
/// store makes of them (nothing stored, bookkeeping it cannot read), no scene comes out of
/// them, and the board boots the scene it was started with.
#[test]
fn a_flash_file_of_stray_bytes_boots_the_scene_started_with() {
    let dir = std::env::temp_dir().join(format!("saw-boot-fallback-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for board in [&NUCLEO_F446RE, &NUCLEO_G474RE] {
        let fallback = scene_file(board, "grating.toml");
        for (what, seed) in [("random", 1u64), ("random", 2), ("zeros", 0)] {
            let path = dir.join(format!("{}-{what}-{seed}.bin", board.name));
            let mut bytes = vec![0u8; board.store.bytes as usize];
            if what == "random" {
                rand_chacha::ChaCha8Rng::seed_from_u64(seed).fill_bytes(&mut bytes);
            }
            std::fs::write(&path, &bytes).unwrap();
            let store = flash::open(&path, board).unwrap();
            assert_eq!(
                boot(board, &fallback, SceneSource::BuildTime, Some(store)),
                (fallback.clone(), SceneSource::BuildTime),
                "{} {what} {seed}",
                board.name
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}
