//! 2D scenes end to end (issue #36): the `saw` binary against `host-sim serve` with the touch
//! overlay (`--scene scenes/2d-fig12.toml`) and against the 1D board: a 2D scene pushed and
//! read back as the same file, windows moved and resized live, the stream's x and y where the
//! virtual finger is, and each board refusing the other kind of scene with a sentence, nothing
//! changed, the link usable.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

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

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The F446's touch frame, µs: the period the virtual overlay board reads at (its schedule's,
/// 280 µs since one conversion is thrown away after each switch and a pressure phase sums 4).
fn frame_us() -> u32 {
    host_sim::sim2d::board_frame_period_us(&saw_boards::NUCLEO_F446RE).expect("a frame period")
}

/// The F446's burst timer.
fn timer() -> saw_core::burst::BurstTimer {
    let b = &saw_boards::NUCLEO_F446RE;
    saw_core::burst::BurstTimer {
        clock_hz: b.burst_timer_clk_hz,
        counter_bits: b.burst_timer_bits,
        max_burst_hz: b.max_burst_hz,
    }
}

/// `saw --json get`'s scene written as TOML, read back as a 2D scene file.
fn read_back(port: &Path) -> (String, saw_core::plane::Config2d, (u32, u32)) {
    let g = saw_json(port, &["get"]);
    assert_eq!(g["ok"], true, "{g}");
    let table: toml::Table = serde_json::from_value(g["result"]["scene"].clone()).unwrap();
    let text = toml::to_string(&table).unwrap();
    let config =
        saw_core::scene_file::load_2d_for_board("back.toml", &text, timer(), frame_us()).unwrap();
    let plate = saw_core::scene_file::plate_um_of("back.toml", &text).unwrap();
    (
        g["result"]["scene_id"].as_str().unwrap().to_string(),
        config,
        plate,
    )
}

fn file_config(name: &str) -> saw_core::plane::Config2d {
    let text = std::fs::read_to_string(scene(name)).unwrap();
    saw_core::scene_file::load_2d_for_board(name, &text, timer(), frame_us()).unwrap()
}

#[test]
fn a_2d_scene_is_pushed_read_back_edited_and_a_1d_one_refused() {
    let fig12 = scene("2d-fig12.toml");
    let vb = VirtualBoard::start(&["--scene", s(&fig12), "--rest-at-xy", "17,27"]);
    let h = saw_json(&vb.port, &["hello"]);
    assert_eq!(h["result"]["hello"]["sensor"]["kind"], "4-wire", "{h}");
    assert_eq!(
        h["result"]["hello"]["sensor"]["plate_mm"],
        serde_json::json!([95.0, 54.0])
    );
    let r = saw(&vb.port, &["push", s(&fig12)]);
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let (id, config, plate) = read_back(&vb.port);
    assert_eq!(config, file_config("2d-fig12.toml"));
    assert_eq!(plate, (95_000, 54_000));

    // A 1D scene on the overlay: refused with the board's sentence, exit 2, nothing changed.
    let r = saw(&vb.port, &["push", s(&scene("default.toml"))]);
    assert_eq!(r.code, 2, "{} {}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("this board reads the 4-wire touch overlay, 95 x 54 mm (2D scenes): a 1D scene (regions, boundaries; no [sensor] table) needs a board with the slide rheostat"),
        "{}",
        r.stderr
    );
    assert_eq!(r.stderr.trim().lines().count(), 1, "{}", r.stderr);
    let r = saw(&vb.port, &["boundary", "0", "30"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert_eq!(read_back(&vb.port).0, id);

    // Window 1 (35,5 – 60,49 mm) moved to (36, 2), then resized.
    let r = saw(&vb.port, &["window", "1", "--to", "36,2"]);
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let (_, moved, _) = read_back(&vb.port);
    let mut want = file_config("2d-fig12.toml");
    for v in want.scene.windows[1].outline.vertices.iter_mut() {
        v.x_um += 1_000;
        v.y_um -= 3_000;
    }
    assert_eq!(moved, want);
    // `get --toml` is a scene file of what runs: the moved window, kept and pushed again.
    let tuned = saw(&vb.port, &["get", "--toml"]);
    assert_eq!(tuned.code, 0, "{}", tuned.stderr);
    assert!(
        tuned
            .stdout
            .starts_with("# Read back with `saw get --toml`: scene 0x"),
        "{}",
        tuned.stdout
    );
    let dir = std::env::temp_dir().join(format!("saw-e2e2d-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tuned_file = dir.join("tuned.toml");
    std::fs::write(&tuned_file, &tuned.stdout).unwrap();
    assert_eq!(
        saw_core::scene_file::load_2d_for_board("tuned.toml", &tuned.stdout, timer(), frame_us())
            .unwrap(),
        want
    );
    let r = saw(&vb.port, &["push", s(&fig12)]);
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let r = saw(&vb.port, &["push", s(&tuned_file)]);
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    assert_eq!(read_back(&vb.port).1, want);
    let r = saw(&vb.port, &["window", "1", "--rect", "40,10,62.5,30"]);
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let (id, resized, _) = read_back(&vb.port);
    let mut xs: Vec<i32> = resized.scene.windows[1]
        .outline
        .vertices
        .iter()
        .map(|v| v.x_um)
        .collect();
    let mut ys: Vec<i32> = resized.scene.windows[1]
        .outline
        .vertices
        .iter()
        .map(|v| v.y_um)
        .collect();
    xs.sort();
    ys.sort();
    assert_eq!(
        (xs, ys),
        (
            vec![40_000, 40_000, 62_500, 62_500],
            vec![10_000, 10_000, 30_000, 30_000]
        )
    );

    // Refused edits: off the plate (the board's sentence, exit 1), NaN and a bad form at the
    // door (exit 2, one line naming the flag); the scene unchanged after each.
    let r = saw(&vb.port, &["window", "0", "--to", "80,5"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    assert!(
        r.stderr.contains(
            "window 0: the point (105 mm, 5 mm) is off the plate (0 to 95 mm, 0 to 54 mm)"
        ),
        "{}",
        r.stderr
    );
    for (args, says) in [
        (vec!["window", "0", "--to", "NaN,3"], "--to"),
        (vec!["window", "0", "--to", "3"], "X,Y"),
        (vec!["window", "0", "--rect", "1,2,3,inf"], "--rect"),
        (vec!["window", "0", "--to", "-1,3"], "0 to 1000"),
        // Neither flag: the sentence names both (clap's own error named only --to).
        (
            vec!["window", "0"],
            "give --to X,Y (move) or --rect X0,Y0,X1,Y1 (resize)",
        ),
    ] {
        let r = saw(&vb.port, &args);
        assert_eq!(r.code, 2, "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
        assert_eq!(r.stderr.trim().lines().count(), 1, "{args:?}: {}", r.stderr);
    }
    assert_eq!(read_back(&vb.port).0, id);

    // The stream carries x and y: the finger rests at (17, 27) mm, in window 0.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("t.csv");
    let r = saw(
        &vb.port,
        &["stream", "--csv", s(&csv), "--seconds", "1", "--every", "3"],
    );
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        header,
        saw::record::CSV_HEADER_2D.split(',').collect::<Vec<_>>()
    );
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert!(
        rows.len() > 500,
        "{} rows in 1 s at ~960 records/s",
        rows.len()
    );
    let down: Vec<&Vec<String>> = rows.iter().filter(|r| !r[col("x_um")].is_empty()).collect();
    assert!(
        down.len() > rows.len() - 40,
        "the finger is down (landing run excepted)"
    );
    for r in &down {
        let x: f64 = r[col("x_um")].parse().unwrap();
        let y: f64 = r[col("y_um")].parse().unwrap();
        assert!(
            (x - 17_000.0).abs() < 300.0 && (y - 27_000.0).abs() < 300.0,
            "{r:?}"
        );
        assert_eq!(r[col("lifted")], "0");
        assert_eq!(r[col("scene_id")], id);
    }
    let in_window_0 = down.iter().filter(|r| r[col("window")] == "0").count();
    assert!(
        in_window_0 > down.len() - 40,
        "{in_window_0} of {}",
        down.len()
    );

    // The 2D core's counters, one `name value` a line.
    let r = saw(&vb.port, &["counters"]);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let lines: Vec<&str> = r.stdout.trim().lines().collect();
    assert_eq!(lines.len(), 10, "{}", r.stdout);
    assert!(lines[0].starts_with("touch readings "), "{}", r.stdout);
    assert!(lines.iter().all(|l| !l.starts_with(' ')), "{}", r.stdout);
    let c = saw_json(&vb.port, &["counters"]);
    assert!(
        c["result"]["counters"]["core"]["readings"]
            .as_u64()
            .unwrap()
            > 2_000,
        "{c}"
    );
}

#[test]
fn the_stream_follows_the_finger_round_its_circle() {
    // The default 2D finger: round the circle of radius 0.4 × 54 mm about the plate's middle
    // (47.5, 27) mm at 60 mm/s (host-sim serve's trajectory_2d): every position recorded lies
    // on it within the noise (2 LSB: ~8 µm RMS per axis) and a frame's travel.
    let vb = VirtualBoard::start(&["--scene", s(&scene("2d-fig12.toml"))]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("c.csv");
    let r = saw(
        &vb.port,
        &["stream", "--csv", s(&csv), "--seconds", "2", "--every", "3"],
    );
    assert_eq!(r.code, 0, "{} {}", r.stdout, r.stderr);
    let text = std::fs::read_to_string(&csv).unwrap();
    let (mut n, mut xs, mut windows) = (0, Vec::new(), std::collections::BTreeSet::new());
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        if f[4].is_empty() {
            continue;
        }
        let (x, y): (f64, f64) = (f[4].parse().unwrap(), f[5].parse().unwrap());
        let r_mm = ((x - 47_500.0).hypot(y - 27_000.0)) / 1000.0;
        assert!(
            (r_mm - 21.6).abs() < 0.2,
            "{line}: {r_mm} mm from the centre"
        );
        xs.push(x);
        windows.insert(f[8].to_string());
        n += 1;
    }
    assert!(n > 1000, "{n} records");
    // Over 2 s (120 mm of a 136 mm circle) it crosses windows 0, 1 and 2 and the gaps.
    let (lo, hi) = xs
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(hi - lo > 30_000.0, "x from {lo} to {hi}");
    assert!(windows.len() >= 3, "{windows:?}");
}

#[test]
fn a_board_with_the_rheostat_refuses_a_2d_scene_with_a_sentence() {
    let vb = VirtualBoard::start(&[]);
    let before = saw_json(&vb.port, &["hello"]);
    assert_eq!(before["result"]["hello"]["sensor"]["kind"], "rheostat");
    let r = saw(&vb.port, &["push", s(&scene("2d-fig12.toml"))]);
    assert_eq!(r.code, 2, "{} {}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("this board reads the slide rheostat (1D scenes): a 2D scene ([sensor] kind = \"4-wire\") or a window edit needs a board with the 4-wire touch overlay"),
        "{}",
        r.stderr
    );
    let r = saw(&vb.port, &["window", "0", "--to", "5,5"]);
    assert_eq!(r.code, 1, "{}", r.stderr);
    let after = saw_json(&vb.port, &["hello"]);
    assert_eq!(
        after["result"]["hello"]["scene_id"],
        before["result"]["hello"]["scene_id"]
    );
    // Still usable: a 1D edit runs.
    assert_eq!(saw(&vb.port, &["boundary", "0", "30"]).code, 0);
}

/// The sentence a board with the overlay answers a 1D edit with (the session's
/// `Refused2d::WrongSensor`), as docs/link.md gives it.
const NOT_1D: &str = "this board reads the 4-wire touch overlay, 95 x 54 mm (2D scenes): a 1D scene (regions, boundaries; no [sensor] table) needs a board with the slide rheostat";

/// `saw session` on a 2D board: the 2D columns, `window` lines applied live (window 0 moved out
/// from under the resting finger and back: the records of each part say so), and `boundary` and
/// `set` lines answered with the board's sentence while the session goes on.
#[test]
fn a_session_on_a_2d_board_logs_its_columns_and_runs_window_lines() {
    use std::io::Write;
    let vb = VirtualBoard::start(&[
        "--scene",
        s(&scene("2d-fig12.toml")),
        "--rest-at-xy",
        "17,27",
    ]);
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("session.csv");
    let script = "wait 0.2\nwindow 0 --to 60,5\nwait 0.3\nboundary 0 30\nset 0 f_b_hz=30\nwindow 0 --to 5,5\nwait 0.3\n";
    let mut child = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args(["--json", "session", "--csv", s(&csv), "--every", "3"])
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
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{stdout} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 8, "{stdout}");
    let moved = lines[1]["result"]["applied"].as_str().unwrap().to_string();
    let back = lines[5]["result"]["applied"].as_str().unwrap().to_string();
    for i in [3, 4] {
        assert_eq!(lines[i]["ok"], false, "{}", lines[i]);
        assert_eq!(lines[i]["kind"], "refused", "{}", lines[i]);
        assert_eq!(
            lines[i]["error"],
            format!("refused, nothing changed: {NOT_1D}"),
            "{}",
            lines[i]
        );
    }
    assert_eq!(lines[7]["result"]["commands"], 7, "{}", lines[7]);
    assert_eq!(lines[7]["result"]["commands_failed"], 2, "{}", lines[7]);

    let text = std::fs::read_to_string(&csv).unwrap();
    let mut rows = text.lines();
    assert_eq!(rows.next(), Some(saw::record::CSV_HEADER_2D));
    let header: Vec<&str> = saw::record::CSV_HEADER_2D.split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    // Each scene's records: where the finger at (17, 27) mm is, window 0 or the background.
    let mut seen: Vec<(String, std::collections::BTreeSet<String>)> = Vec::new();
    for row in rows {
        let r: Vec<&str> = row.split(',').collect();
        let id = r[col("scene_id")].to_string();
        match seen.last_mut() {
            Some((last, windows)) if *last == id => {
                windows.insert(r[col("window")].to_string());
            }
            _ => seen.push((id, [r[col("window")].to_string()].into())),
        }
    }
    let ids: Vec<&str> = seen.iter().map(|(id, _)| id.as_str()).collect();
    assert_eq!(ids.len(), 3, "{seen:?}");
    assert_eq!(&ids[1..], [moved.as_str(), back.as_str()], "{seen:?}");
    let windows: Vec<Vec<&str>> = seen
        .iter()
        .map(|(_, w)| w.iter().map(String::as_str).collect())
        .collect();
    assert_eq!(windows, [vec!["0"], vec!["background"], vec!["0"]]);
}

/// `saw bench` on a 2D board times window 0's moves, puts the window back (the scene id as
/// before), and counts the 2D records of each stream rate (a bench reading 1D frames would
/// count none and call every rate lossless).
#[test]
fn bench_on_a_2d_board_moves_a_window_and_streams_2d_records() {
    let vb = VirtualBoard::start(&["--scene", s(&scene("2d-fig12.toml"))]);
    let before = saw_json(&vb.port, &["hello"])["result"]["hello"]["scene_id"].clone();
    let r = saw_json(&vb.port, &["bench", "--moves", "10", "--seconds", "0.5"]);
    assert_eq!(r["ok"], true, "{r}");
    let b = &r["result"];
    assert_eq!(b["edit"], "window", "{b}");
    assert_eq!(b["moves"], 10, "{b}");
    let rates = b["rates"].as_array().unwrap();
    assert_eq!(rates.len(), 6, "{b}");
    for rate in rates {
        let asked = rate["rate_hz"].as_f64().unwrap();
        let records = rate["records"].as_f64().unwrap();
        // At least a third of what 0.5 s at that rate gives (the line caps every frame at
        // ~2 600/s), so the 2D records were read.
        assert!(records >= asked * 0.5 / 3.0, "{rate}");
    }
    // Every third frame (960/s) fits the line: a lossless rate was found.
    assert!(b["lossless_rate_hz"].as_f64().unwrap() >= 960.0, "{b}");
    let after = saw_json(&vb.port, &["hello"])["result"]["hello"]["scene_id"].clone();
    assert_eq!(after, before);
}
