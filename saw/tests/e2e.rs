//! End to end through a real tty: the `saw` binary against the virtual board of
//! `host-sim serve` (the same core and link code as the firmware) on a pseudo-terminal.

mod common;

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use common::VirtualBoard;
use serde_json::Value;

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

fn saw(port: &Path, args: &[&str]) -> Run {
    let out = Command::new(env!("CARGO_BIN_EXE_saw"))
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
        .collect();
    v.sort();
    v
}

#[test]
fn every_scene_file_is_pushed_and_read_back() {
    let vb = VirtualBoard::start(&[]);
    for path in scenes() {
        let text = std::fs::read_to_string(&path).unwrap();
        let doc = saw_core::scene_file::parse(&path.display().to_string(), &text).unwrap();
        let want = saw_link::scene_id(&doc.config);
        let r = saw_json(&vb.port, &["push", path.to_str().unwrap()]);
        assert_eq!(r["ok"], true, "{}: {r}", path.display());
        assert_eq!(r["result"]["applied"], want, "{}", path.display());
        let h = saw_json(&vb.port, &["hello"]);
        assert_eq!(h["result"]["hello"]["scene_id"], want);
        assert_eq!(h["result"]["hello"]["scene_source"], "Link");
        let g = saw_json(&vb.port, &["get"]);
        let back: saw_core::scene::Config =
            serde_json::from_value(g["result"]["config"].clone()).unwrap();
        assert_eq!(back, doc.config, "{}", path.display());
    }
}

fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

/// Positions (mm) where the region changed from `a` to `b` or back, in a stream CSV, located
/// only between two records `max_gap_us` apart or less: across records the line dropped (the
/// stream's drop counter), the switch could be anywhere in the gap.
fn switches(rows: &[Vec<String>], a: &str, b: &str, max_gap_us: u64) -> Vec<f64> {
    let t = |r: &Vec<String>| r[0].parse::<u64>().unwrap_or(0);
    rows.windows(2)
        .filter(|w| t(&w[1]).wrapping_sub(t(&w[0])) <= max_gap_us)
        .filter(|w| (w[0][3] == a && w[1][3] == b) || (w[0][3] == b && w[1][3] == a))
        .filter_map(|w| w[1][1].parse::<f64>().ok())
        .map(|um| um / 1000.0)
        .collect()
}

/// Streams `seconds` at every fourth sample (2 500 records/s, within the line's 3 333); the
/// positions (mm) where region 0 and 1 swap.
fn switch_positions(port: &Path, seconds: &str) -> Vec<f64> {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    let args = [
        "stream",
        "--csv",
        csv.to_str().unwrap(),
        "--seconds",
        seconds,
        "--every",
        "4",
    ];
    let r = saw(port, &args);
    assert_eq!(r.code, 0, "{}", r.stderr);
    // Every fourth sample at 10 kHz: consecutive records are 400 µs apart (0.04 mm at 100 mm/s).
    let s = switches(&csv_rows(&csv), "0", "1", 400);
    assert!(!s.is_empty(), "no switch in {seconds} s");
    s
}

#[test]
fn a_boundary_moved_live_moves_the_switch() {
    // 60 mm of travel at 100 mm/s: each pass crosses the boundary once.
    let vb = VirtualBoard::start(&["--speed", "100"]);
    // The default boundary is at 18.963 mm; a switch lands within hysteresis (0.1 mm) plus one
    // record's travel (0.04 mm) past it.
    let s = switch_positions(&vb.port, "1.5");
    assert!(s.iter().all(|x| (x - 18.963).abs() < 0.15), "{s:?}");
    let r = saw(&vb.port, &["boundary", "0", "30"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.contains("boundary 0 at 30 mm: running"),
        "{}",
        r.stdout
    );
    let s = switch_positions(&vb.port, "1.5");
    assert!(s.iter().all(|x| (x - 30.0).abs() < 0.15), "{s:?}");
}

#[test]
fn ten_seconds_stream_without_a_drop_at_1_khz() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    let r = saw_json(
        &vb.port,
        &[
            "stream",
            "--csv",
            csv.to_str().unwrap(),
            "--seconds",
            "10",
            "--every",
            "10",
        ],
    );
    let res = &r["result"];
    assert_eq!(res["dropped"], 0, "{r}");
    assert_eq!(res["frames_lost"], 0, "{r}");
    assert_eq!(res["bad_frames"], 0, "{r}");
    let rows = csv_rows(&csv);
    // 1000 records/s for 10 s, give or take the frames in flight at the ends.
    assert!(
        (9_900..=10_100).contains(&rows.len()),
        "{} records",
        rows.len()
    );
    // Consecutive records are 10 samples (1 ms) apart: nothing lost in between.
    let t: Vec<u64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    assert!(
        t.windows(2).all(|w| w[1] - w[0] == 1_000),
        "a gap in the records"
    );
}

#[test]
fn a_stream_faster_than_the_line_drops_and_counts_and_never_stalls() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    // Every sample: 10 000 records/s of ~19 bytes is twice what 921 600 baud carries.
    let r = saw_json(
        &vb.port,
        &[
            "stream",
            "--csv",
            csv.to_str().unwrap(),
            "--seconds",
            "1",
            "--every",
            "1",
        ],
    );
    let dropped = r["result"]["dropped"].as_u64().unwrap();
    let records = r["result"]["records"].as_u64().unwrap();
    assert!(dropped > 2_000, "{r}");
    assert!(records > 3_000, "{r}");
    // The board still answers at once.
    let h = saw(&vb.port, &["--timeout", "200", "hello"]);
    assert_eq!(h.code, 0, "{}", h.stderr);
}

#[test]
fn a_refused_scene_reads_as_host_sim_reads_it_and_changes_nothing() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("fast.toml");
    let text = "[[region]]\nkind = \"constant\"\nuntil_mm = 20\nf_b_hz = 80\n\n\
                [[region]]\nkind = \"constant\"\nf_b_hz = 3000\n";
    std::fs::write(&file, text).unwrap();
    let board = saw_boards::NUCLEO_F446RE;
    let host = saw_core::scene_file::load_for_board(
        &file.display().to_string(),
        text,
        host_sim::sim::burst_timer(&board),
        host_sim::sim::sample_period_us(&board),
    )
    .unwrap_err();
    let before = saw_json(&vb.port, &["hello"]);
    let r = saw(&vb.port, &["push", file.to_str().unwrap()]);
    assert_eq!(r.code, 1);
    assert_eq!(r.stderr.trim(), format!("error: {host}"));
    let after = saw_json(&vb.port, &["hello"]);
    assert_eq!(
        before["result"]["hello"]["scene_id"],
        after["result"]["hello"]["scene_id"]
    );
    // A live edit refused by the board: its sentence, nothing changed.
    let r = saw(&vb.port, &["set", "1", "kind=constant", "f_b_hz=9000"]);
    assert_eq!(r.code, 1);
    assert!(
        r.stderr
            .contains("f_b 9000 Hz is above this board's limit of 2000 Hz"),
        "{}",
        r.stderr
    );
    // Refused at the door (scene-file range): exit 2, the field named.
    let r = saw(&vb.port, &["set", "1", "kind=constant", "f_b_hz=-3"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("f_b_hz"), "{}", r.stderr);
    let after2 = saw_json(&vb.port, &["hello"]);
    assert_eq!(
        before["result"]["hello"]["scene_id"],
        after2["result"]["hello"]["scene_id"]
    );
}

#[test]
fn a_second_client_is_told_the_port_is_busy() {
    let vb = VirtualBoard::start(&[]);
    let held = serialport::new(vb.port.to_string_lossy(), 921_600)
        .open_native()
        .unwrap();
    let r = saw(&vb.port, &["hello"]);
    assert_eq!(r.code, 3);
    assert!(r.stderr.contains("is busy"), "{}", r.stderr);
    drop(held);
    assert_eq!(saw(&vb.port, &["hello"]).code, 0);
}

fn encoded(version: u16, seq: u32, req: &saw_link::msg::Request) -> Vec<u8> {
    let mut out = [0u8; saw_link::frame::MAX_ENCODED];
    let n =
        saw_link::frame::encode(&saw_link::msg::Header { version, seq }, req, &mut out).unwrap();
    out[..n].to_vec()
}

#[test]
fn unplugged_mid_upload_and_noise_leave_the_scene_and_the_link_usable() {
    let vb = VirtualBoard::start(&[]);
    let before = saw_json(&vb.port, &["hello"])["result"]["hello"]["scene_id"].clone();
    let scene = std::fs::read_to_string(scenes()[0].clone()).unwrap();
    let cfg = saw_core::scene_file::parse("x", &scene).unwrap().config;
    let frame = encoded(1, 5, &saw_link::msg::Request::LoadScene(cfg));
    {
        // A client that dies half way through an upload.
        let mut p = serialport::new(vb.port.to_string_lossy(), 921_600)
            .open_native()
            .unwrap();
        p.write_all(&frame[..frame.len() / 2]).unwrap();
        p.flush().unwrap();
    }
    std::thread::sleep(Duration::from_millis(50));
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["ok"], true, "{h}");
    assert_eq!(h["result"]["hello"]["scene_id"], before);
    {
        // Junk, then a frame with one bit flipped.
        let mut p = serialport::new(vb.port.to_string_lossy(), 921_600)
            .open_native()
            .unwrap();
        p.write_all(&[0x13, 0x37, 0xff, 0x00, 0x42]).unwrap();
        let mut bad = frame.clone();
        bad[7] ^= 0x04;
        p.write_all(&[0]).unwrap();
        p.write_all(&bad).unwrap();
        p.flush().unwrap();
    }
    std::thread::sleep(Duration::from_millis(50));
    let c = saw_json(&vb.port, &["counters"]);
    assert!(
        c["result"]["counters"]["link"]["frames_bad"]
            .as_u64()
            .unwrap()
            >= 2,
        "{c}"
    );
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_id"], before);
}

#[test]
fn a_host_of_another_protocol_version_gets_a_typed_answer() {
    use std::io::Read;
    let vb = VirtualBoard::start(&[]);
    let mut p = serialport::new(vb.port.to_string_lossy(), 921_600)
        .timeout(Duration::from_millis(20))
        .open_native()
        .unwrap();
    p.write_all(&[0]).unwrap();
    p.write_all(&encoded(2, 41, &saw_link::msg::Request::Hello))
        .unwrap();
    let mut rx = saw_link::frame::Receiver::<{ saw_link::frame::MAX_ENCODED }>::default();
    let deadline = std::time::Instant::now() + Duration::from_secs(2);
    let mut byte = [0u8; 1];
    let reply = loop {
        assert!(std::time::Instant::now() < deadline, "no answer");
        if p.read(&mut byte).unwrap_or(0) == 0 {
            continue;
        }
        if let Some(Ok(n)) = rx.push(byte[0]) {
            break saw_link::frame::message::<saw_link::msg::Reply>(rx.payload(n)).unwrap();
        }
    };
    assert_eq!(reply.0.seq, 41);
    assert_eq!(
        reply.1,
        saw_link::msg::Reply::Error(saw_link::msg::LinkError::WrongVersion { ours: 1, theirs: 2 })
    );
}

#[test]
fn no_board_and_bad_values_are_one_line_each() {
    let r = saw(Path::new("/nonexistent/tty"), &["hello"]);
    assert_eq!(r.code, 3);
    assert!(r.stderr.contains("does not exist"), "{}", r.stderr);
    assert_eq!(r.stderr.trim().lines().count(), 1);
    for bad in ["nan", "inf", "-1", "1001"] {
        let r = saw(Path::new("/nonexistent/tty"), &["boundary", "0", bad]);
        assert_eq!(r.code, 2, "{bad}");
        assert!(r.stderr.contains("0 to 1000 mm"), "{bad}: {}", r.stderr);
    }
    // A pty with nothing behind it answering: no answer, said plainly.
    let dir = tempfile::tempdir().unwrap();
    let silent = dir.path().join("silent");
    let pty = nix::pty::openpty(None, None).unwrap();
    let name = nix::unistd::ttyname(&pty.slave).unwrap();
    std::os::unix::fs::symlink(name, &silent).unwrap();
    let r = saw(&silent, &["--timeout", "100", "hello"]);
    assert_eq!(r.code, 3);
    assert!(r.stderr.contains("no answer within 100 ms"), "{}", r.stderr);
}

#[test]
fn a_saved_scene_survives_a_power_cycle() {
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    let flash_arg = flash.to_str().unwrap().to_string();
    // No store: said plainly.
    {
        let vb = VirtualBoard::start(&[]);
        let r = saw(&vb.port, &["save"]);
        assert_eq!(r.code, 1);
        assert!(r.stderr.contains("no scene store"), "{}", r.stderr);
    }
    let vb = VirtualBoard::start_in(dir, &["--flash", &flash_arg]);
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_source"], "Default", "{h}");
    let grating = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/grating.toml");
    let pushed = saw_json(&vb.port, &["push", grating.to_str().unwrap()]);
    let id = pushed["result"]["applied"].clone();
    let s = saw_json(&vb.port, &["save"]);
    assert_eq!(s["result"]["saved"], id, "{s}");
    // An edit after the save is not saved.
    assert_eq!(saw(&vb.port, &["boundary", "0", "25"]).code, 0);
    let dir = vb.power_off();
    let vb = VirtualBoard::start_in(dir, &["--flash", &flash_arg]);
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_id"], id, "{h}");
    assert_eq!(h["result"]["hello"]["scene_source"], "Saved", "{h}");
}

/// docs/link.md: at 921 600 baud the line carries every third sample of a 10 kHz board without a
/// drop, and not every second one (the benchmark `saw bench` finds the same edge).
#[test]
fn the_line_carries_every_third_sample_and_not_every_second() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    let c = csv.to_str().unwrap();
    let third = saw_json(
        &vb.port,
        &["stream", "--csv", c, "--seconds", "2", "--every", "3"],
    );
    assert_eq!(third["result"]["dropped"], 0, "{third}");
    let second = saw_json(
        &vb.port,
        &["stream", "--csv", c, "--seconds", "2", "--every", "2"],
    );
    assert!(
        second["result"]["dropped"].as_u64().unwrap() > 500,
        "{second}"
    );
}

/// A save that must reclaim a 128 KiB sector answers only after the erase (1 s on the F446, up
/// to 2 s: `host-sim serve` takes the typical 1 s): `saw save` waits for it (`SAVE_TIMEOUT`)
/// instead of reporting no answer after its usual 1 s, says how long it took, and the board
/// boots into the scene after a power cycle.
#[test]
fn a_save_that_erases_a_sector_succeeds_and_survives_a_power_cycle() {
    let (image, last) = common::f446_store_before_an_erase();
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    std::fs::write(&flash, &image).unwrap();
    let flash_arg = flash.to_str().unwrap().to_string();
    let args = ["--board", "nucleo-f446re", "--flash", &flash_arg];
    let vb = VirtualBoard::start_in(dir, &args);
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_id"], last, "{h}");
    assert_eq!(h["result"]["hello"]["scene_source"], "Saved", "{h}");
    let moved = saw_json(&vb.port, &["boundary", "0", "30"]);
    let id = moved["result"]["applied"].clone();
    let s = saw_json(&vb.port, &["save"]);
    assert_eq!(s["ok"], true, "{s}");
    assert_eq!(s["result"]["saved"], id, "{s}");
    assert!(s["result"]["seconds"].is_f64(), "{s}");
    // The save erased a sector: bytes that held items are erased (0xFF) again.
    let after = std::fs::read(&flash).unwrap();
    let erased = image
        .iter()
        .zip(&after)
        .filter(|(b, a)| **b != 0xFF && **a == 0xFF)
        .count();
    assert!(erased > 0, "the save did not erase a sector");
    // The text says how long it took.
    assert_eq!(saw(&vb.port, &["boundary", "0", "31"]).code, 0);
    let r = saw(&vb.port, &["save"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    assert!(
        r.stdout.starts_with("saved scene 0x") && r.stdout.contains(" s: the board boots into it"),
        "{}",
        r.stdout
    );
    let id = saw_json(&vb.port, &["hello"])["result"]["hello"]["scene_id"].clone();
    let dir = vb.power_off();
    let vb = VirtualBoard::start_in(dir, &args);
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["scene_id"], id, "{h}");
    assert_eq!(h["result"]["hello"]["scene_source"], "Saved", "{h}");
}
