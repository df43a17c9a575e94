//! Test helpers shared by the `saw` tests: the virtual board of `host-sim serve` in a thread.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use clap::Parser;
use host_sim::serve::{serve, ServeArgs, ServeStats};

/// A virtual board running in a thread, stopped on drop.
pub struct VirtualBoard {
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<ServeStats, String>>>,
    pub port: PathBuf,
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
            serve(&args, &s, |_| {
                let _ = tx.send(());
            })
        });
        rx.recv_timeout(Duration::from_secs(10))
            .expect("the virtual board did not start");
        Self {
            stop,
            handle: Some(handle),
            port,
            _dir: dir,
        }
    }

    /// Pulls the plug: the board stops; its directory (and the flash file in it) stays.
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
