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
        // 1D scenes here; the 2D ones (`scenes/2d-*.toml`) go to a 2D board in e2e2d.rs.
        .filter(|p| {
            let text = std::fs::read_to_string(p).unwrap();
            saw_core::scene_file::sensor_of(&p.display().to_string(), &text)
                == Ok(saw_core::scene_file::SensorKind::Rheostat)
        })
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
        let want = format!("{want:#010x}");
        let r = saw_json(&vb.port, &["push", path.to_str().unwrap()]);
        assert_eq!(r["ok"], true, "{}: {r}", path.display());
        assert_eq!(r["result"]["applied"], want, "{}", path.display());
        let h = saw_json(&vb.port, &["hello"]);
        assert_eq!(h["result"]["hello"]["scene_id"], want);
        // The scene file that pushed it is the source only while it is not the boot scene.
        let src = h["result"]["hello"]["scene_source"]
            .as_str()
            .unwrap()
            .to_string();
        assert!(src == "link" || src == "default", "{h}");
        let g = saw_json(&vb.port, &["get"]);
        assert_eq!(g["result"]["scene_id"], want);
        // `get --json` speaks the scene file's keys: written as TOML it reads back as the scene.
        let toml_text = toml::to_string(&g["result"]["scene"]).unwrap();
        let back = saw_core::scene_file::parse("get", &toml_text)
            .unwrap_or_else(|e| panic!("{e}\n{toml_text}"))
            .config;
        assert_eq!(back, doc.config, "{}", path.display());
    }
}

/// A stream's CSV: rows of named columns.
struct Csv {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Csv {
    fn read(path: &Path) -> Self {
        let text = std::fs::read_to_string(path).unwrap();
        let mut lines = text.lines();
        let header = lines
            .next()
            .unwrap()
            .split(',')
            .map(str::to_string)
            .collect();
        let rows = lines
            .map(|l| l.split(',').map(str::to_string).collect())
            .collect();
        Csv { header, rows }
    }
    fn col(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name} in {:?}", self.header))
    }
    /// Column `name` of every row.
    fn values(&self, name: &str) -> Vec<String> {
        let c = self.col(name);
        self.rows.iter().map(|r| r[c].clone()).collect()
    }
    fn numbers(&self, name: &str) -> Vec<u64> {
        self.values(name)
            .iter()
            .map(|v| v.parse().unwrap())
            .collect()
    }
}

/// Positions (mm) where the region changed from `a` to `b` or back, in a stream CSV, located
/// only between two records `max_gap_us` apart or less: across records the line dropped (the
/// stream's drop counter), the switch could be anywhere in the gap.
fn switches(csv: &Csv, a: &str, b: &str, max_gap_us: u64) -> Vec<f64> {
    let (t, region, pos) = (
        csv.col("time_us"),
        csv.col("region"),
        csv.col("position_um"),
    );
    let time = |r: &Vec<String>| r[t].parse::<u64>().unwrap_or(0);
    csv.rows
        .windows(2)
        .filter(|w| time(&w[1]).wrapping_sub(time(&w[0])) <= max_gap_us)
        .filter(|w| {
            (w[0][region] == a && w[1][region] == b) || (w[0][region] == b && w[1][region] == a)
        })
        .filter_map(|w| w[1][pos].parse::<f64>().ok())
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
    let s = switches(&Csv::read(&csv), "0", "1", 400);
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
    let csv = Csv::read(&csv);
    // 1000 records/s for 10 s, give or take the frames in flight at the ends.
    assert!(
        (9_900..=10_100).contains(&csv.rows.len()),
        "{} records",
        csv.rows.len()
    );
    // The host times are the board times moved by the offset found before the stream (its
    // pings are back to back: no drift is fitted over a millisecond of them).
    let host = csv.numbers("host_time_us");
    let board = csv.numbers("time_us");
    assert!(
        host.iter()
            .zip(&board)
            .all(|(h, b)| (h - b).abs_diff(host[0] - board[0]) <= 1),
        "host_time_us drifts from time_us"
    );
    // Consecutive records are 10 samples (1 ms) apart: nothing lost in between.
    let t = csv.numbers("time_us");
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
    // A scene file refused, by the board here: exit 2 as for the reader's refusals.
    assert_eq!(r.code, 2);
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
    let frame = encoded(
        saw_link::msg::PROTOCOL_VERSION,
        5,
        &saw_link::msg::Request::LoadScene(cfg),
    );
    {
        // A client that dies half way through an upload.
        let mut p = serialport::new(vb.port.to_string_lossy(), 921_600)
            .open_native()
            .unwrap();
        p.write_all(&frame[..frame.len() / 2]).unwrap();
        p.flush().unwrap();
    }
    // No wait: the board reads the pty's bytes in order, so the next request comes after them.
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["ok"], true, "{h}");
    assert_eq!(h["result"]["hello"]["scene_id"], before);
    // Counted from here: the half frame above was closed by hello's leading zero (one bad frame).
    let c = saw_json(&vb.port, &["counters", "--reset"]);
    assert_eq!(c["result"]["counters"]["link"]["frames_bad"], 1, "{c}");
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
    // Three bad frames: `13 37 ff` (broken COBS or CRC), `42` (too short), and the frame
    // with the flipped bit (CRC).
    let c = saw_json(&vb.port, &["counters"]);
    assert_eq!(c["result"]["counters"]["link"]["frames_bad"], 3, "{c}");
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
    let theirs = saw_link::msg::PROTOCOL_VERSION + 1;
    p.write_all(&encoded(theirs, 41, &saw_link::msg::Request::Hello))
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
        saw_link::msg::Reply::Error(saw_link::msg::LinkError::WrongVersion {
            ours: saw_link::msg::PROTOCOL_VERSION,
            theirs
        })
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
    assert_eq!(h["result"]["hello"]["scene_source"], "default", "{h}");
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
    assert_eq!(h["result"]["hello"]["scene_source"], "saved", "{h}");
}

/// docs/link.md: at 921 600 baud the line carries every fourth sample of a 10 kHz board (2 500
/// records/s, about 72 % of what the line carries at ~26.5 bytes a record) without a drop, and
/// not every second one (5 000 records/s, ~1.4 × the line). Both at a margin from the edge
/// (every third, 96 %), so the load of the machine running the test does not decide it.
#[test]
fn the_line_carries_every_fourth_sample_and_not_every_second() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    let c = csv.to_str().unwrap();
    let fourth = saw_json(
        &vb.port,
        &["stream", "--csv", c, "--seconds", "2", "--every", "4"],
    );
    assert_eq!(fourth["result"]["dropped"], 0, "{fourth}");
    let second = saw_json(
        &vb.port,
        &["stream", "--csv", c, "--seconds", "2", "--every", "2"],
    );
    // 10 000 records in 2 s against the ~7 000 the line carries.
    assert!(
        second["result"]["dropped"].as_u64().unwrap() > 2_000,
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
    assert_eq!(
        h["result"]["hello"]["scene_id"],
        format!("{last:#010x}"),
        "{h}"
    );
    assert_eq!(h["result"]["hello"]["scene_source"], "saved", "{h}");
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
    assert_eq!(h["result"]["hello"]["scene_source"], "saved", "{h}");
}

/// The records' size on the wire, which the line-rate test's margins rest on: 8 records of a
/// moving finger with 64-bit time, scene id and change count frame to ~212 bytes.
#[test]
fn a_stream_frame_of_eight_records_is_about_212_bytes() {
    use saw_link::msg::{Header, Record, Reply, Stream};
    let r = Record {
        time_us: 12_345_678,
        scene_id: 0x9abc_def0,
        change: 3,
        position_um: Some(41_234),
        velocity_um_s: Some(-59_876),
        region: Some(2),
        burst_millihz: 80_000,
        bursting: true,
        fault: None,
    };
    let frame = Reply::Stream(Stream {
        dropped: 0,
        records: core::iter::repeat_n(r, 8).collect(),
    });
    let mut out = [0u8; saw_link::frame::MAX_ENCODED];
    let n = saw_link::frame::encode(
        &Header {
            version: 2,
            seq: 300,
        },
        &frame,
        &mut out,
    )
    .unwrap();
    assert!((200..=220).contains(&n), "{n} bytes");
}

/// The stale-record race: a script that sets a scene and then streams, trial after
/// trial, each `saw` a new process. Every record of every trial carries the scene that trial
/// set and the change count it made; none is from the trial before.
#[test]
fn twenty_trials_of_set_then_stream_record_only_their_own_scene() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let mut seen_changes = std::collections::BTreeSet::new();
    for trial in 0..20u32 {
        // A stream left running, as by a script killed mid-trial or a forgotten panel: every
        // sample, so the board's queue and the line are full of records from before the trial.
        {
            let mut p = serialport::new(vb.port.to_string_lossy(), 921_600)
                .open_native()
                .unwrap();
            let stream = saw_link::msg::Request::Stream { every_samples: 1 };
            p.write_all(&encoded(saw_link::msg::PROTOCOL_VERSION, 7, &stream))
                .unwrap();
            p.flush().unwrap();
        }
        let set = saw_json(
            &vb.port,
            &["set", "0", &format!("f_b_hz={}", 20 + 5 * trial)],
        );
        assert_eq!(set["ok"], true, "{set}");
        let id = set["result"]["applied"].as_str().unwrap().to_string();
        let csv = dir.path().join(format!("trial{trial}.csv"));
        // The board's clock as the stream is asked for: no record may be older.
        let asked_us = vb.clock.board_us(std::time::Instant::now());
        let r = saw_json(
            &vb.port,
            &[
                "stream",
                "--csv",
                csv.to_str().unwrap(),
                "--seconds",
                "0.3",
                "--every",
                "10",
            ],
        );
        assert_eq!(r["ok"], true, "{r}");
        let csv = Csv::read(&csv);
        assert!(
            csv.rows.len() > 200,
            "trial {trial}: {} records",
            csv.rows.len()
        );
        let t = csv.numbers("time_us");
        let stale = t.iter().filter(|&&t| t < asked_us).count();
        assert_eq!(
            stale, 0,
            "trial {trial}: {stale} records from before the stream was asked for"
        );
        let ids = csv.values("scene_id");
        let wrong = ids.iter().filter(|v| **v != id).count();
        assert_eq!(
            wrong, 0,
            "trial {trial}: {wrong} records of another scene than {id}"
        );
        let changes: std::collections::BTreeSet<u64> = csv.numbers("change").into_iter().collect();
        assert_eq!(changes.len(), 1, "trial {trial}: {changes:?}");
        // Each trial's change is new: no record is from an earlier trial's scene.
        assert!(
            seen_changes.insert(*changes.first().unwrap()),
            "trial {trial}"
        );
        // The records follow each other at the decimation: no seam of old records.
        assert!(
            t.windows(2).all(|w| w[1] - w[0] == 1_000),
            "trial {trial}: a gap"
        );
    }
}

/// `saw session`: one stream, the scene changed from stdin between waits; the log splits at
/// the change count, each part carrying the scene its command applied, in order.
#[test]
fn a_session_is_one_log_that_splits_at_each_change() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("session.csv");
    let script = "set 0 f_b_hz=30\nwait 0.2\nset 0 f_b_hz=45\nwait 0.2\n# a comment\nset 0 f_b_hz=60\nwait 0.2\nset 0 f_b_hz=75\nwait 0.2\nset 0 f_b_hz=90\nwait 0.2\nset 0 f_b_hz=-5\n";
    let mut child = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args(["--json", "session", "--csv", csv.to_str().unwrap()])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(script.as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // One answer per command (the comment is none), then the summary.
    assert_eq!(lines.len(), 12, "{lines:?}");
    let ids: Vec<String> = [0, 2, 4, 6, 8]
        .iter()
        .map(|&i| lines[i]["result"]["applied"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(lines[10]["ok"], false, "{}", lines[10]);
    assert!(
        lines[10]["error"].as_str().unwrap().contains("f_b_hz"),
        "{}",
        lines[10]
    );
    assert_eq!(lines[11]["result"]["commands"], 11, "{}", lines[11]);
    let csv = Csv::read(&csv);
    let (scene, change) = (csv.values("scene_id"), csv.numbers("change"));
    // Split at the change count: the boot scene's part, then one part per accepted set.
    let mut parts: Vec<(u64, String, usize)> = Vec::new();
    for (c, id) in change.iter().zip(&scene) {
        match parts.last_mut() {
            Some((pc, pid, n)) if pc == c => {
                assert_eq!(pid, id, "one scene within a change");
                *n += 1;
            }
            _ => parts.push((*c, id.clone(), 1)),
        }
    }
    let applied: Vec<&String> = parts.iter().map(|p| &p.1).skip(parts.len() - 5).collect();
    assert_eq!(applied, ids.iter().collect::<Vec<_>>(), "{parts:?}");
    // The five changes are consecutive counts, each lasting about its wait (0.2 s = 200
    // records at 1 kHz; the last part runs until stdin's end and the stop).
    let last5 = &parts[parts.len() - 5..];
    assert!(last5.windows(2).all(|w| w[1].0 == w[0].0 + 1), "{parts:?}");
    for p in &last5[..4] {
        assert!((150..=300).contains(&p.2), "{parts:?}");
    }
    // Time goes forward through the changes, and a change's first record is its first sample
    // (sent whatever the decimation), so the count restarts there: it comes at most 1 ms after
    // the record before it, the record after it exactly 1 ms later, and over the changes at
    // least one comes off the 1 ms schedule (each of the five lands on it by chance 1 time in
    // 10: all five, 1 run in 100 000).
    let t = csv.numbers("time_us");
    assert!(t.windows(2).all(|w| w[1] > w[0]), "time goes forward");
    let mut off_schedule = 0;
    for i in 1..change.len() - 1 {
        if change[i] != change[i - 1] {
            let before = t[i] - t[i - 1];
            assert!(
                before <= 1_000,
                "change at record {i}: {before} µs after the one before"
            );
            assert_eq!(t[i + 1] - t[i], 1_000, "the count restarts at the change");
            off_schedule += usize::from(before < 1_000);
        }
    }
    assert!(
        off_schedule > 0,
        "no change's first sample was forced into the stream"
    );
}

/// The clock alignment against the virtual board's own clock (which runs 200 ppm fast here):
/// the board's boot on the host's clock within the error `saw ping` states, and the drift
/// within what that error allows over the span.
#[test]
fn ping_aligns_the_board_clock_within_the_error_it_states() {
    let vb = VirtualBoard::start(&["--clock-ppm", "200"]);
    let r = saw_json(&vb.port, &["ping", "--count", "20", "--over", "2"]);
    assert_eq!(r["ok"], true, "{r}");
    let clock = &r["result"]["clock"];
    let error_us = clock["error_us"].as_f64().unwrap();
    let span_us = clock["span_us"].as_f64().unwrap();
    // The truth: the board booted at `vb.clock.start`, on this machine's Unix clock, read
    // between two monotonic readings (the tightest of a few, so a preempted thread does not
    // move it).
    let boot_unix_us = (0..5)
        .map(|_| {
            let before = std::time::Instant::now();
            let unix_us = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_micros() as f64;
            let after = std::time::Instant::now();
            let mid = before + (after - before) / 2;
            (
                after - before,
                unix_us - (mid - vb.clock.start).as_micros() as f64,
            )
        })
        .min_by_key(|(gap, _)| *gap)
        .unwrap()
        .1;
    let boot = clock["board_boot_host_us"].as_f64().unwrap();
    // Reading the two clocks here and in `saw` adds a few µs each; 50 µs of slack for it.
    assert!(
        (boot - boot_unix_us).abs() <= error_us * (1.0 + 2.0 * 2e-4) + 50.0,
        "boot at {boot} µs, truly {boot_unix_us} µs: off by {} µs, stated ±{error_us} µs",
        boot - boot_unix_us
    );
    // The board runs 200 ppm fast (1.0002 board µs a host µs): +200 ppm, within the error
    // it states (both ends' error over the span).
    let want_ppm = 200.0;
    let drift = clock["drift_ppm"].as_f64().unwrap();
    let allowed_ppm = clock["drift_error_ppm"].as_f64().unwrap();
    // The stated rule (both ends' error over the span), to rounding: the code may multiply
    // in another order, so the last bit can differ.
    let rule_ppm = 2.0 * error_us / span_us * 1e6;
    assert!(
        (allowed_ppm - rule_ppm).abs() <= 1e-9 * rule_ppm,
        "drift error {allowed_ppm} ppm, the rule gives {rule_ppm} ppm: {clock}"
    );
    assert!(
        span_us >= 0.5e6,
        "the fitted pings a third of the 2 s apart at least: {clock}"
    );
    assert!(
        (drift - want_ppm).abs() <= allowed_ppm,
        "drift {drift} ppm, truly {want_ppm} ppm (±{allowed_ppm})"
    );
    println!(
        "ping: error ±{error_us} µs, drift {drift:.1} ppm (true {want_ppm:.1}) over {span_us} µs"
    );
}

/// A command line's mistakes: with --json the answer is JSON on stdout like every other; a
/// negative value reaches its range sentence; one line each.
#[test]
fn command_line_errors_are_one_line_and_json_when_asked() {
    let port = Path::new("/nonexistent/tty");
    for (args, says) in [
        (
            vec!["stream", "--csv", "x.csv", "--seconds", "-1"],
            "--seconds",
        ),
        (
            vec![
                "stream",
                "--csv",
                "x.csv",
                "--seconds",
                "1",
                "--every",
                "-1",
            ],
            "--every",
        ),
        (vec!["--timeout", "-5", "hello"], "--timeout"),
        (vec!["bench", "--moves", "-1"], "--moves"),
        (vec!["ping", "--over", "-1"], "--over"),
        (vec!["boundary", "-1", "5"], "-1"),
        (vec!["set", "-2", "f_b_hz=5"], "-2"),
        (vec!["fly"], "fly"),
    ] {
        let r = saw(port, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert_eq!(r.stderr.trim().lines().count(), 1, "{args:?}: {}", r.stderr);
        assert!(
            !r.stderr.contains("unexpected argument '-"),
            "{args:?}: {}",
            r.stderr
        );
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
        let mut with_json = vec!["--json"];
        with_json.extend(&args);
        let r = saw(port, &with_json);
        assert_eq!(r.code, 2, "{args:?}");
        let v: Value = serde_json::from_str(r.stdout.trim())
            .unwrap_or_else(|e| panic!("{args:?}: {e}: stdout {:?}", r.stdout));
        assert_eq!(v["ok"], false);
        assert_eq!(v["kind"], "input");
        assert!(v["error"].as_str().unwrap().contains(says), "{v}");
    }
    // The range sentences themselves, for negative numbers.
    for (args, says) in [
        (
            vec!["stream", "--csv", "x.csv", "--seconds", "-1"],
            "from 0.1 to 86400 s",
        ),
        (
            vec!["--timeout", "-5", "hello"],
            "must be a whole number from 10 to 60000 ms",
        ),
        (
            vec!["boundary", "-1", "5"],
            "must be a whole number from 0 to 255",
        ),
        (
            vec!["ping", "--count", "1"],
            "must be a whole number from 2 to 1000 round trips",
        ),
    ] {
        let r = saw(port, &args);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    }
    // A missing argument is named on the one line.
    let r = saw(port, &["stream", "--seconds", "1"]);
    assert!(
        r.stderr.contains("not provided: --csv <FILE>"),
        "{}",
        r.stderr
    );
    assert_eq!(r.stderr.trim().lines().count(), 1, "{}", r.stderr);
    // --help is not an error.
    let r = saw(port, &["--help"]);
    assert_eq!(r.code, 0);
    assert!(r.stdout.contains("session"), "{}", r.stdout);
}

/// `set` changes what it names: a duty set earlier survives a later f_b change; a value is
/// range-checked without `kind`; a new kind starts from its own defaults.
#[test]
fn set_keeps_the_values_it_does_not_name() {
    let vb = VirtualBoard::start(&[]);
    let r = saw(&vb.port, &["set", "0", "duty_percent=25"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let r = saw(&vb.port, &["set", "0", "f_b_hz=55"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let g = saw_json(&vb.port, &["get"]);
    let region = &g["result"]["scene"]["region"][0];
    assert_eq!(region["f_b_hz"], 55, "{g}");
    assert_eq!(region["duty_percent"], 25, "{g}");
    // Checked at the door without `kind`: the key, the value's rule.
    let r = saw(&vb.port, &["set", "0", "f_b_hz=-5"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("region 0: `f_b_hz`"), "{}", r.stderr);
    assert!(!r.stderr.contains("kind"), "{}", r.stderr);
    // Past the last region: said with the count.
    let r = saw(&vb.port, &["set", "9", "f_b_hz=50"]);
    assert_eq!(r.code, 2, "{}", r.stderr);
    assert!(r.stderr.contains("has 3 regions (0 to 2)"), "{}", r.stderr);
    // A new kind: its own keys, the old kind's values gone.
    let r = saw(&vb.port, &["set", "0", "kind=grating", "wavelength_mm=2"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let g = saw_json(&vb.port, &["get"]);
    let region = &g["result"]["scene"]["region"][0];
    assert_eq!(region["kind"], "grating", "{g}");
    assert!(region.get("f_b_hz").is_none(), "{g}");
    // A grating's duty is its own default (40 %), not the 25 % the constant had.
    assert_eq!(region["duty_percent"], 40, "{g}");
    // The text says it in words.
    let r = saw(&vb.port, &["get"]);
    assert!(r.stdout.contains("3 regions over"), "{}", r.stdout);
    assert!(r.stdout.contains("standing drive"), "{}", r.stdout);
    let r = saw(&vb.port, &["drive", "progressive"]);
    assert!(
        r.stdout.starts_with("progressive drive: running"),
        "{}",
        r.stdout
    );
}

/// `saw --json ui`: its stdout is JSON like every other command's (where it listens), the
/// terminal lines stay on stderr.
#[test]
fn the_panel_under_json_says_where_it_listens_in_json() {
    use std::io::BufRead;
    let vb = VirtualBoard::start(&[]);
    let mut child = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args(["--json", "ui", "--listen", "127.0.0.1:0"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut first = String::new();
    std::io::BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let _ = child.kill();
    let _ = child.wait();
    let v: Value = serde_json::from_str(first.trim()).unwrap_or_else(|e| panic!("{e}: {first:?}"));
    assert_eq!(v["ok"], true, "{v}");
    let at = v["result"]["listening"].as_str().unwrap();
    assert!(
        at.starts_with("http://127.0.0.1:") && !at.ends_with(":0"),
        "{v}"
    );
}

/// `saw session --seconds S` records S seconds whatever stdin does (here: nothing, at once).
#[test]
fn a_session_with_seconds_lasts_them_with_no_commands() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("quiet.csv");
    let out = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args([
            "--json",
            "session",
            "--csv",
            csv.to_str().unwrap(),
            "--seconds",
            "0.5",
        ])
        .stdin(std::process::Stdio::null())
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let t = Csv::read(&csv).numbers("time_us");
    let span_us = t.last().unwrap() - t.first().unwrap();
    // Half a second of 1 kHz records, give or take the stream's start and stop.
    assert!((400_000..=600_000).contains(&span_us), "{span_us} µs");
}
