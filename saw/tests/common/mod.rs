//! Test helpers shared by the `saw` tests: the virtual board of `host-sim serve` in a thread.

pub mod browser;

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use clap::Parser;
use host_sim::serve::{serve_with_clock, BoardClock, ServeArgs, ServeStats};

/// A virtual board running in a thread, stopped on drop.
pub struct VirtualBoard {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<ServeStats, String>>>,
    pub port: PathBuf,
    /// The board's own clock (boot instant, rate).
    #[allow(dead_code)]
    pub clock: BoardClock,
    _dir: tempfile::TempDir,
}

impl VirtualBoard {
    pub fn start(extra: &[&str]) -> Self {
        let dir = tempfile::tempdir().unwrap();
        Self::start_in(dir, extra)
    }

    pub fn start_in(dir: tempfile::TempDir, extra: &[&str]) -> Self {
        let port = dir.path().join("tty");
        let mut argv = vec![
            "serve".to_string(),
            "--pty".into(),
            port.display().to_string(),
        ];
        argv.extend(extra.iter().map(|s| s.to_string()));
        let args = ServeArgs::try_parse_from(argv).unwrap();
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, rx) = std::sync::mpsc::channel();
        let s = stop.clone();
        let handle = std::thread::spawn(move || {
            serve_with_clock(&args, &s, |_, clock| {
                let _ = tx.send(clock);
            })
        });
        let clock = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("the virtual board did not start");
        Self {
            stop,
            handle: Some(handle),
            port,
            clock,
            _dir: dir,
        }
    }

    /// Pulls the plug: the board stops; its directory (and the flash file in it) stays.
    #[allow(dead_code)] // not every test file pulls the plug
    pub fn power_off(mut self) -> tempfile::TempDir {
        self.stop.store(true, Ordering::Relaxed);
        let _ = self.handle.take().unwrap().join().unwrap();
        let dir = tempfile::tempdir().unwrap();
        std::mem::replace(&mut self._dir, dir)
    }
}

impl Drop for VirtualBoard {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// The web panel on `vb`'s port, served on any free local port.
// Each test file compiles this module on its own; the link tests do not use the panel.
#[allow(dead_code)]
pub fn panel(vb: &VirtualBoard) -> saw::ui::UiHandle {
    saw::ui::start(saw::ui::UiOptions {
        port: vb.port.clone(),
        listen: "127.0.0.1:0".parse().unwrap(),
        allow_remote: false,
        timeout: Duration::from_millis(1000),
        every: 10,
    })
    .unwrap()
}

/// The F446's store (sectors 6–7: two 128 KiB units written a word at a time) after as many
/// saves as fit before the next must erase a sector, built with the firmware's own `saw-store`
/// over sequential-storage's mock NOR flash: its bytes (a `--flash` file) and the last scene
/// saved.
// The e2e and panel tests use it; the browser test does not.
#[allow(dead_code)]
pub fn f446_store_before_an_erase() -> (Vec<u8>, u32) {
    use sequential_storage::mock_flash::MockFlashBase;
    type Flash = MockFlashBase<2, 4, 0x8000>;
    let layout = saw_boards::NUCLEO_F446RE.store;
    assert_eq!((layout.bytes, layout.erase_bytes), (2 * 0x2_0000, 0x2_0000));
    let mut flash = Flash::default();
    let start = flash.stats_snapshot();
    let mut last = None;
    for i in 0..100_000u32 {
        let before = flash.as_bytes().to_vec();
        let config = saw_core::default_config()
            .with_boundary(0, 25_000 + (i % 50) * 100)
            .unwrap();
        let saved = saw_store::Saved {
            scene_id: saw_link::scene_id(&config),
            config,
        };
        let mut store = saw_store::SceneStore::new(flash, Flash::FULL_FLASH_RANGE).unwrap();
        embassy_futures::block_on(store.save(&saved)).unwrap();
        flash = store.into_flash().unwrap();
        if start.compare_to(flash.stats_snapshot()).erases > 0 {
            return (before, last.expect("the first save erased"));
        }
        last = Some(saved.scene_id);
    }
    panic!("no erase after 100 000 saves");
}
