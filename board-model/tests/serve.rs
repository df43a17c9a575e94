//! `saw` against the real firmware images: `board-model serve` runs each image on the board model
//! behind a pseudo-terminal and the `saw` binary drives it as it drives a Nucleo — hello, every
//! scene file pushed and read back, a refused scene that changes nothing, a save that must erase
//! a unit (the F446's 128 KiB sector) followed by a power cycle, and a stream.
//!
//! Ignored by a plain `cargo test`: they need the `saw` binary of the host workspace
//! (`cargo build -p saw`, either profile; `SAW_BIN` names another) and the images
//! (`$SAW_FIRMWARE_DIR/<board>.elf`, default `../firmware/target`). `scripts/board-model.sh` runs
//! them after `check`: `cargo test --release --test serve -- --ignored`.
//!
//! The model runs slower than a board (about 0.3–0.7× real time on this machine's 2 cores,
//! `board-model serve` prints it), and `saw`'s timeouts are wall-clock: every `saw` here gets
//! `--timeout 5000` (`TIMEOUT_MS`), so an answer 1 s of board time after its request still
//! arrives in time at 0.2× real time. Nothing here measures the host clock.

use saw_board_model::board::BoardKind;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// `saw --timeout` for every command here, ms: the model's speed, not the board's, sets it.
const TIMEOUT_MS: &str = "5000";

fn firmware(kind: BoardKind) -> PathBuf {
    let dir = std::env::var("SAW_FIRMWARE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| Path::new(env!("CARGO_MANIFEST_DIR")).join("../firmware/target"));
    let elf = dir.join(format!("{}.elf", kind.name()));
    assert!(
        elf.exists(),
        "{} is missing: run scripts/build-firmware.sh",
        elf.display()
    );
    elf
}

fn saw_bin() -> PathBuf {
    let bin = match std::env::var("SAW_BIN") {
        Ok(p) => PathBuf::from(p),
        Err(_) => {
            let target = std::env::var("CARGO_TARGET_DIR")
                .map(PathBuf::from)
                .unwrap_or_else(|_| Path::new(env!("CARGO_MANIFEST_DIR")).join("../target"));
            // Either profile: saw only moves bytes.
            let release = target.join("release/saw");
            if release.exists() {
                release
            } else {
                target.join("debug/saw")
            }
        }
    };
    assert!(
        bin.exists(),
        "{} is missing: cargo build --release -p saw (or set SAW_BIN)",
        bin.display()
    );
    bin
}

/// A scratch directory removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let p = std::env::temp_dir().join(format!("saw-serve-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        Self(p)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

extern "C" {
    fn kill(pid: i32, sig: i32) -> i32;
}
const SIGTERM: i32 = 15;

/// `board-model serve` in a child process, stopped (SIGTERM, as Ctrl-C) on drop.
struct Served {
    child: Option<Child>,
    port: PathBuf,
    log: PathBuf,
}

impl Served {
    fn start(kind: BoardKind, dir: &Path, flash: Option<&Path>) -> Self {
        let port = dir.join("tty");
        let log = dir.join("defmt.log");
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_board-model"));
        cmd.args(["serve", "--board", kind.name(), "--elf"])
            .arg(firmware(kind))
            .arg("--pty")
            .arg(&port)
            .arg("--log")
            .arg(&log)
            .stdout(Stdio::null());
        if let Some(f) = flash {
            cmd.arg("--flash").arg(f);
        }
        let child = cmd.spawn().unwrap();
        let give_up = Instant::now() + Duration::from_secs(60);
        while !port.exists() {
            assert!(Instant::now() < give_up, "board-model serve made no pty");
            std::thread::sleep(Duration::from_millis(20));
        }
        Self {
            child: Some(child),
            port,
            log,
        }
    }

    /// Pulls the plug as Ctrl-C does: serve writes the flash back and removes its link.
    fn stop(mut self) {
        self.stop_child();
    }

    fn stop_child(&mut self) {
        if let Some(mut c) = self.child.take() {
            unsafe {
                kill(c.id() as i32, SIGTERM);
            }
            let status = c.wait().unwrap();
            assert!(status.success(), "board-model serve ended with {status}");
            assert!(!self.port.exists(), "serve left its link behind");
        }
    }

    fn log_text(&self) -> String {
        std::fs::read_to_string(&self.log).unwrap_or_default()
    }
}

impl Drop for Served {
    fn drop(&mut self) {
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

fn saw(port: &Path, args: &[&str]) -> Run {
    let mut all = vec!["--timeout", TIMEOUT_MS];
    all.extend_from_slice(args);
    saw_as_is(port, &all)
}

/// `saw` with no `--timeout` of ours: its own default (1 000 ms per answer, a save at least
/// `saw::SAVE_TIMEOUT`).
fn saw_as_is(port: &Path, args: &[&str]) -> Run {
    let out = Command::new(saw_bin())
        .arg("--port")
        .arg(port)
        .args(args)
        .output()
        .unwrap();
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn saw_json(port: &Path, args: &[&str]) -> Value {
    let mut all = vec!["--json"];
    all.extend_from_slice(args);
    let r = saw(port, &all);
    serde_json::from_str(r.stdout.trim())
        .unwrap_or_else(|e| panic!("{e}: {} {}", r.stdout, r.stderr))
}

fn scenes() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        // 1D scenes only: the link carries no 2D scene (issue #36's `scenes/2d-*.toml`).
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            saw_core::scene_file::sensor_of(&p.display().to_string(), &text)
                == Ok(saw_core::scene_file::SensorKind::Rheostat)
        })
        .collect();
    v.sort();
    v
}

/// Hello names the board; every scene file in scenes/ is pushed and read back (or, where the
/// board's limits refuse it, refused with host-sim's sentence for that board); a refused scene
/// and a refused live edit change nothing.
fn hello_push_and_refuse(kind: BoardKind) {
    let dir = Scratch::new(&format!("push-{}", kind.name()));
    let s = Served::start(kind, &dir.0, None);
    let h = saw_json(&s.port, &["hello"]);
    assert_eq!(h["ok"], true, "{h}");
    assert_eq!(h["result"]["hello"]["board"], kind.name(), "{h}");
    assert_eq!(h["result"]["hello"]["sample_rate_hz"], 10_000, "{h}");
    let def = kind.def();
    let (timer, period_us) = (
        host_sim::sim::burst_timer(def),
        host_sim::sim::sample_period_us(def),
    );
    for path in scenes() {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(&path).unwrap();
        let doc = saw_core::scene_file::parse(&name, &text).unwrap();
        let host = saw_core::scene_file::load_for_board(&name, &text, timer, period_us);
        let r = saw(&s.port, &["push", &name]);
        match host {
            Ok(_) => {
                assert_eq!(r.code, 0, "{name}: {}", r.stderr);
                let want = format!("{:#010x}", saw_link::scene_id(&doc.config));
                let h = saw_json(&s.port, &["hello"]);
                assert_eq!(h["result"]["hello"]["scene_id"], want, "{name}: {h}");
                let src = h["result"]["hello"]["scene_source"].as_str().unwrap_or("");
                assert!(src == "link" || src == "default", "{name}: {h}");
                let g = saw_json(&s.port, &["get"]);
                // `get --json` speaks the scene file's keys: as TOML it reads back as the scene.
                let toml_text = toml::to_string(&g["result"]["scene"]).unwrap();
                let back = saw_core::scene_file::parse("get", &toml_text)
                    .unwrap()
                    .config;
                assert_eq!(back, doc.config, "{name}");
            }
            Err(e) => {
                // A scene file the board refuses exits 2, as the reader's refusals do.
                assert_eq!(r.code, 2, "{name}: {}", r.stdout);
                assert_eq!(r.stderr.trim(), format!("error: {e}"), "{name}");
            }
        }
    }
    // A scene the board refuses: host-sim's sentence for this board, nothing changed.
    let file = dir.0.join("fast.toml");
    let text = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n\
                [[region]]\nkind = \"constant\"\nf_b_hz = 3000\n";
    std::fs::write(&file, text).unwrap();
    let name = file.display().to_string();
    let host = saw_core::scene_file::load_for_board(&name, text, timer, period_us).unwrap_err();
    let before = saw_json(&s.port, &["hello"]);
    let r = saw(&s.port, &["push", &name]);
    assert_eq!(r.code, 2, "{}", r.stdout);
    assert_eq!(r.stderr.trim(), format!("error: {host}"));
    // Region 0: the last scene file pushed may have only one region (scenes/rf-off.toml).
    let r = saw(&s.port, &["set", "0", "kind=constant", "f_b_hz=9000"]);
    assert_eq!(r.code, 1, "{}", r.stdout);
    assert!(r.stderr.contains("f_b 9000 Hz is above"), "{}", r.stderr);
    let after = saw_json(&s.port, &["hello"]);
    assert_eq!(
        before["result"]["hello"]["scene_id"],
        after["result"]["hello"]["scene_id"]
    );
    s.stop();
}

/// A stream at every 10th sample (1 kHz): records arrive 1 000 µs of board time apart with
/// nothing dropped or lost, and region and position follow the finger.
fn stream(kind: BoardKind) {
    let dir = Scratch::new(&format!("stream-{}", kind.name()));
    let s = Served::start(kind, &dir.0, None);
    let csv = dir.0.join("s.csv");
    let r = saw_json(
        &s.port,
        &[
            "stream",
            "--csv",
            csv.to_str().unwrap(),
            "--seconds",
            "2",
            "--every",
            "10",
        ],
    );
    assert_eq!(r["ok"], true, "{r}");
    let res = &r["result"];
    assert_eq!(res["dropped"], 0, "{r}");
    assert_eq!(res["frames_lost"], 0, "{r}");
    assert_eq!(res["bad_frames"], 0, "{r}");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (time, pos, region, scene) = (
        col("time_us"),
        col("position_um"),
        col("region"),
        col("scene_id"),
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    // Every record carries the scene in force: the image's default scene.
    let want_id = format!("{:#010x}", saw_link::scene_id(&saw_core::default_config()));
    assert!(
        rows.iter().all(|r| r[scene] == want_id),
        "{:?}",
        rows.first()
    );
    // How many depends on the model's speed (2 s of wall time); the gaps and regions do not.
    assert!(rows.len() >= 2, "{} records: {r}", rows.len());
    let t: Vec<u64> = rows.iter().map(|r| r[time].parse().unwrap()).collect();
    assert!(
        t.windows(2).all(|w| w[1] - w[0] == 1_000),
        "a gap in the records"
    );
    // The finger moves at 60 mm/s between 1.5 and 61.5 mm: every record has a position there,
    // and the region the default scene has there (0.2 mm clear of a boundary: its 0.1 mm
    // hysteresis and the noise).
    let bounds = saw_core::default_config().scene.boundaries_um;
    for row in &rows {
        let um: f64 = row[pos].parse().unwrap();
        assert!((1_000.0..=62_000.0).contains(&um), "{row:?}");
        if bounds.iter().all(|&b| (um - b as f64).abs() > 200.0) {
            let want = bounds.iter().filter(|&&b| (b as f64) < um).count();
            assert_eq!(row[region], want.to_string(), "{row:?}");
        }
    }
    s.stop();
}

/// A save from a store filled to its first erase (the F446 must erase a 128 KiB sector, 1 s of
/// stalled CPU; the G474 a 2 KiB page): `saw save` answers Saved with the moved scene, the
/// flash file shows the unit erased, and after a power cycle the firmware boots into the scene
/// just saved and says so.
fn save_and_power_cycle(kind: BoardKind) {
    let dir = Scratch::new(&format!("save-{}", kind.name()));
    let def = kind.def();
    let scene = |i: usize| {
        saw_core::default_config()
            .with_boundary(0, 25_000 + (i as u32 % 50) * 100)
            .expect("a boundary between 25 and 30 mm is valid in the default scene")
    };
    let (image, last, _) =
        saw_board_model::store_image::before_an_erase(def, scene).expect("store image");
    let flash = dir.0.join("flash.bin");
    std::fs::write(&flash, &image).unwrap();
    let s = Served::start(kind, &dir.0, Some(&flash));
    let h = saw_json(&s.port, &["hello"]);
    assert_eq!(
        h["result"]["hello"]["scene_id"],
        format!("{:#010x}", last.scene_id),
        "{h}"
    );
    assert_eq!(h["result"]["hello"]["scene_source"], "saved", "{h}");
    let moved = saw_json(&s.port, &["boundary", "0", "30"]);
    let id = moved["result"]["applied"].clone();
    assert!(id.is_string(), "{moved}");
    // With saw's own timeouts, as a user types it. Board time never runs ahead of the wall
    // clock, so the F446's 1 s sector erase holds the answer back at least 1 s of wall time
    // (1.25 s measured): a save that waited only the default 1 s per answer fails here.
    let r = saw_as_is(&s.port, &["--json", "save"]);
    let r: Value = serde_json::from_str(r.stdout.trim())
        .unwrap_or_else(|e| panic!("{e}: {} {}", r.stdout, r.stderr));
    assert_eq!(r["ok"], true, "{r}");
    assert_eq!(r["result"]["saved"], id, "{r}");
    eprintln!(
        "{}: save answered after {} s of wall time",
        kind.name(),
        r["result"]["seconds"]
    );
    // The board still answers after the save.
    let h = saw_json(&s.port, &["hello"]);
    assert_eq!(h["ok"], true, "{h}");
    s.stop();
    let after = std::fs::read(&flash).unwrap();
    let erased = image
        .iter()
        .zip(&after)
        .filter(|(b, a)| **b != 0xFF && **a == 0xFF)
        .count();
    // Programming only clears bits: a byte back at 0xFF was erased.
    assert!(erased > 0, "the save erased no unit");
    let s = Served::start(kind, &dir.0, Some(&flash));
    let h = saw_json(&s.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_id"], id, "{h}");
    assert_eq!(h["result"]["hello"]["scene_source"], "saved", "{h}");
    let boot_line = format!(
        "boot: the scene saved in flash (id {})",
        id.as_str().unwrap().trim_start_matches("0x")
    );
    // The log file is written as the firmware logs; the hello above came after boot.
    let give_up = Instant::now() + Duration::from_secs(10);
    while !s.log_text().contains(&boot_line) {
        assert!(
            Instant::now() < give_up,
            "no `{boot_line}` in the log:\n{}",
            s.log_text()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    s.stop();
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn f446_hello_push_and_refuse() {
    hello_push_and_refuse(BoardKind::F446);
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn g474_hello_push_and_refuse() {
    hello_push_and_refuse(BoardKind::G474);
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn f446_stream() {
    stream(BoardKind::F446);
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn g474_stream() {
    stream(BoardKind::G474);
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn f446_save_erasing_a_sector_and_power_cycle() {
    save_and_power_cycle(BoardKind::F446);
}

#[test]
#[ignore = "needs the saw binary and the images; scripts/board-model.sh runs it"]
fn g474_save_erasing_a_page_and_power_cycle() {
    save_and_power_cycle(BoardKind::G474);
}
