//! `saw ui` against the virtual board: the page is served from the binary with nothing from
//! elsewhere, foreign Host and Origin headers are refused, a non-loopback address needs its flag,
//! and the WebSocket carries the board's own scene and telemetry, edits with the board's
//! answers, and a lost link that comes back by itself. A missing or busy port is said on the
//! terminal, and the port is held only while a page is open.

mod common;

use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use common::{panel, VirtualBoard};
use saw::ui::UiHandle;
use serde_json::{json, Value};
use tungstenite::client::IntoClientRequest;
use tungstenite::Message;

/// A raw HTTP/1.1 GET with the given extra headers: (status, body).
fn get(ui: &UiHandle, path: &str, headers: &[(&str, &str)]) -> (u16, String) {
    let mut s = TcpStream::connect(ui.addr).unwrap();
    let host = format!("127.0.0.1:{}", ui.addr.port());
    let mut req = format!("GET {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        req += &format!("Host: {host}\r\n");
    }
    for (k, v) in headers {
        req += &format!("{k}: {v}\r\n");
    }
    req += "\r\n";
    s.write_all(req.as_bytes()).unwrap();
    let mut out = String::new();
    s.read_to_string(&mut out).unwrap();
    let status = out[9..12].parse().unwrap();
    let body = out.split_once("\r\n\r\n").map_or("", |b| b.1).to_string();
    (status, body)
}

type Socket = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>;

fn socket(ui: &UiHandle) -> Socket {
    let mut req = format!("ws://127.0.0.1:{}/ws", ui.addr.port())
        .into_client_request()
        .unwrap();
    req.headers_mut().insert(
        "Origin",
        format!("http://127.0.0.1:{}", ui.addr.port())
            .parse()
            .unwrap(),
    );
    let (ws, _) = tungstenite::connect(req).unwrap();
    if let tungstenite::stream::MaybeTlsStream::Plain(s) = ws.get_ref() {
        s.set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
    }
    ws
}

/// The next message of type `t` within `secs` (others are skipped).
fn next(ws: &mut Socket, t: &str, secs: f64) -> Option<Value> {
    let end = Instant::now() + Duration::from_secs_f64(secs);
    while Instant::now() < end {
        match ws.read() {
            Ok(Message::Text(text)) => {
                let v: Value = serde_json::from_str(&text).unwrap();
                if v["t"] == t {
                    return Some(v);
                }
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("websocket: {e}"),
        }
    }
    None
}

/// A record's field: records are arrays in `saw stream --csv`'s column order, or objects keyed by
/// those names.
fn field<'a>(rec: &'a Value, name: &str, column: usize) -> &'a Value {
    if rec.is_array() {
        &rec[column]
    } else {
        &rec[name]
    }
}

fn command(ws: &mut Socket, cmd: Value) -> Value {
    ws.send(Message::Text(cmd.to_string().into())).unwrap();
    next(ws, "answer", 5.0).expect("no answer")
}

#[test]
fn the_page_comes_from_the_binary_and_names_nothing_elsewhere() {
    let vb = VirtualBoard::start(&[]);
    let ui = panel(&vb);
    let (status, body) = get(&ui, "/", &[]);
    assert_eq!(status, 200);
    assert!(body.contains("<canvas id=\"strip\""), "{body}");
    // Nothing fetched at run time: no script, style, image or font from another address.
    for needle in [
        "src=\"http",
        "href=\"http",
        "url(http",
        "import(\"http",
        "//cdn",
    ] {
        assert!(!body.contains(needle), "the page names {needle}");
    }
}

#[test]
fn foreign_host_and_origin_are_refused() {
    let vb = VirtualBoard::start(&[]);
    let ui = panel(&vb);
    let port = ui.addr.port();
    // DNS rebinding: a name that resolves here but is not this panel's.
    let (status, body) = get(&ui, "/", &[("Host", &format!("attacker.example:{port}"))]);
    assert_eq!(status, 403, "{body}");
    assert!(body.contains("Host `attacker.example"), "{body}");
    // A page elsewhere opening the control socket or fetching the page.
    for path in ["/", "/ws"] {
        let (status, body) = get(&ui, path, &[("Origin", "http://attacker.example")]);
        assert_eq!(status, 403, "{path}: {body}");
        assert!(body.contains("Origin `http://attacker.example`"), "{body}");
    }
    // Same host, other port: another local server is another site.
    let (status, _) = get(
        &ui,
        "/",
        &[("Origin", &format!("http://127.0.0.1:{}", port + 1))],
    );
    assert_eq!(status, 403);
    // Its own page, under either local name.
    assert_eq!(
        get(&ui, "/", &[("Origin", &format!("http://127.0.0.1:{port}"))]).0,
        200
    );
    assert_eq!(
        get(&ui, "/", &[("Host", &format!("localhost:{port}"))]).0,
        200
    );
}

#[test]
fn a_non_loopback_address_needs_its_flag() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_saw"))
        .args(["--port", "/nonexistent", "ui", "--listen", "0.0.0.0:0"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--listen 0.0.0.0:0") && err.contains("--allow-remote"),
        "{err}"
    );
    let warned = saw::ui::check_listen("0.0.0.0:0".parse().unwrap(), true).unwrap();
    assert!(warned.is_some_and(|w| w.starts_with("warning:")));
    assert_eq!(
        saw::ui::check_listen("127.0.0.1:0".parse().unwrap(), false),
        Ok(None)
    );
}

#[test]
fn the_socket_carries_the_board_edits_and_their_refusals() {
    let vb = VirtualBoard::start(&["--speed", "100"]);
    let ui = panel(&vb);
    let mut ws = socket(&ui);
    let link = next(&mut ws, "link", 5.0).expect("link state");
    assert_eq!(link["ok"], true, "{link}");
    assert_eq!(link["hello"]["board"], "nucleo-f446re");
    let scene = next(&mut ws, "scene", 5.0).expect("scene");
    assert_eq!(scene["regions"].as_array().unwrap().len(), 3, "{scene}");
    // The finger: records at 1 kHz, positions on the substrate and moving.
    let mut positions = Vec::new();
    while positions.len() < 500 {
        let r = next(&mut ws, "records", 2.0).expect("records");
        positions.extend(
            r["records"]
                .as_array()
                .unwrap()
                .iter()
                .filter_map(|r| field(r, "position_um", 1).as_f64()),
        );
    }
    let (lo, hi) = positions
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &p| (a.min(p), b.max(p)));
    assert!(
        lo >= 0.0 && hi <= 63_000.0 && hi - lo > 10_000.0,
        "{lo}..{hi} µm"
    );
    // A boundary moved: answered, and the scene redrawn from the board's answer.
    let a = command(
        &mut ws,
        json!({"id": 7, "cmd": "boundary", "index": 0, "mm": 30.0}),
    );
    assert_eq!(
        (a["id"].as_u64(), a["ok"].as_bool()),
        (Some(7), Some(true)),
        "{a}"
    );
    let scene = next(&mut ws, "scene", 5.0).expect("scene after the move");
    assert_eq!(scene["regions"][0]["to_mm"], 30.0, "{scene}");
    // A refused edit: the scene file's sentence, nothing changed.
    let a = command(
        &mut ws,
        json!({"id": 8, "cmd": "set", "index": 1, "keys": ["kind=grating", "wavelength_mm=-1"]}),
    );
    assert_eq!(a["ok"], false, "{a}");
    assert!(a["text"].as_str().unwrap().contains("wavelength_mm"), "{a}");
    let scene = next(&mut ws, "scene", 5.0).unwrap();
    assert_eq!(scene["regions"][0]["to_mm"], 30.0);
    // A bad command from the page is refused at the door.
    let a = command(
        &mut ws,
        json!({"id": 9, "cmd": "boundary", "index": 0, "mm": "far"}),
    );
    assert!(
        a["text"].as_str().unwrap().contains("`mm` = \"far\""),
        "{a}"
    );
    // The board's scene saved as a scene file: it reads back as the scene the board runs.
    let a = command(&mut ws, json!({"id": 11, "cmd": "export"}));
    assert_eq!(a["ok"], true, "{a}");
    let file = a["file"]
        .as_str()
        .unwrap_or_else(|| panic!("no scene file: {a}"));
    let doc = saw_core::scene_file::parse("exported", file).unwrap();
    assert_eq!(doc.config.scene.boundaries_um[0], 30_000, "{file}");
    let scene = next(&mut ws, "scene", 5.0).unwrap();
    assert_eq!(
        doc.config.scene.textures.len(),
        scene["regions"].as_array().unwrap().len()
    );
    // A scene file loaded through the page.
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../scenes/grating.toml"
    ))
    .unwrap();
    let a = command(
        &mut ws,
        json!({"id": 10, "cmd": "push", "name": "grating.toml", "text": text}),
    );
    assert_eq!(a["ok"], true, "{a}");
}

#[test]
fn a_lost_link_is_shown_and_comes_back() {
    let vb = VirtualBoard::start(&[]);
    let ui = panel(&vb);
    let mut ws = socket(&ui);
    assert_eq!(next(&mut ws, "link", 5.0).unwrap()["ok"], true);
    // Unplugged.
    let dir = vb.power_off();
    let lost = next(&mut ws, "link", 5.0).expect("no link-lost message");
    assert_eq!(lost["ok"], false, "{lost}");
    assert!(!lost["why"].as_str().unwrap().is_empty());
    // An edit while the link is down is refused, not queued.
    let a = command(&mut ws, json!({"id": 3, "cmd": "save"}));
    assert_eq!(a["ok"], false);
    assert!(a["text"].as_str().unwrap().contains("link is lost"), "{a}");
    // Plugged in again at the same port: the panel finds it by itself.
    let _vb = VirtualBoard::start_in(dir, &[]);
    let back = next(&mut ws, "link", 10.0).expect("no reconnect");
    assert_eq!(back["ok"], true, "{back}");
    assert!(next(&mut ws, "records", 5.0).is_some());
}

#[test]
fn a_sensor_fault_reaches_the_page_while_it_lasts() {
    // The wiper open from 1.5 s to 1.8 s of the board's time: late enough for the panel to be
    // streaming by then on a busy machine. Everything below is judged in the board's time (the
    // records' `time_us`); the host's clock only bounds the wait.
    const FROM_US: u64 = 1_500_000;
    const TO_US: u64 = 1_800_000;
    // The core names the fault from the first sample that sees it to the first that does not:
    // at 10 kHz a sample or two past either edge; 5 ms of margin.
    const MARGIN_US: u64 = 5_000;
    let vb = VirtualBoard::start(&["--fault", "open", "--fault-at", "1.5", "--fault-for", "0.3"]);
    let ui = panel(&vb);
    let mut ws = socket(&ui);
    let (mut inside, mut after, mut board_us) = (0, 0, 0u64);
    let give_up = Instant::now() + Duration::from_secs(30);
    while board_us < TO_US + 300_000 {
        assert!(
            Instant::now() < give_up,
            "the board's time reached only {board_us} µs in 30 s"
        );
        let Some(r) = next(&mut ws, "records", 1.0) else {
            continue;
        };
        for rec in r["records"].as_array().unwrap() {
            let t_us = field(rec, "time_us", 0).as_u64().unwrap();
            board_us = board_us.max(t_us);
            match field(rec, "fault", 6).as_str() {
                Some(f) => {
                    assert_eq!(f, "RailLow", "{rec}");
                    assert!(
                        (FROM_US..=TO_US + MARGIN_US).contains(&t_us),
                        "a fault named outside its window: {rec}"
                    );
                }
                None => assert!(
                    !(FROM_US + MARGIN_US..TO_US).contains(&t_us),
                    "no fault named inside its window: {rec}"
                ),
            }
            if (FROM_US + MARGIN_US..TO_US).contains(&t_us) {
                inside += 1;
            } else if t_us > TO_US + MARGIN_US {
                after += 1;
            }
        }
    }
    // The window and the time after it were seen (295 records each at 1 kHz; a page that
    // lags misses batches, so a third of them is enough).
    assert!(inside > 100, "{inside} records inside the fault's window");
    assert!(after > 100, "{after} records after the fault");
}

/// `saw ui` started as a user starts it, its terminal read line by line.
struct SawUi {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
}

impl SawUi {
    fn start(port: &std::path::Path) -> Self {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_saw"))
            .arg("--port")
            .arg(port)
            .args(["ui", "--listen", "127.0.0.1:0"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = std::io::BufReader::new(child.stderr.take().unwrap());
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in stderr.lines().map_while(Result::ok) {
                let _ = tx.send(line);
            }
        });
        Self { child, lines }
    }

    /// The first line that contains every one of `words`, within 10 s; every line read is kept
    /// for the failure message.
    fn said(&self, words: &[&str]) -> String {
        let end = Instant::now() + Duration::from_secs(10);
        let mut seen = Vec::new();
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(line) if words.iter().all(|w| line.contains(w)) => return line,
                Ok(line) => seen.push(line),
                Err(_) => break,
            }
        }
        panic!("saw ui never said {words:?} on its terminal; it said: {seen:#?}");
    }
}

impl Drop for SawUi {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn a_missing_or_busy_port_is_said_on_the_terminal() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-board");
    let ui = SawUi::start(&missing);
    let line = ui.said(&["saw ui:", "does not exist"]);
    assert!(line.contains(&missing.display().to_string()), "{line}");
    drop(ui);

    let vb = VirtualBoard::start(&[]);
    let held = saw::port::open(&vb.port).unwrap();
    let ui = SawUi::start(&vb.port);
    let line = ui.said(&["saw ui:", "busy"]);
    assert!(line.contains(&vb.port.display().to_string()), "{line}");
    // Freed with no page open: the panel does not take it (`saw` may use it meanwhile).
    drop(held);
    std::thread::sleep(Duration::from_millis(1200));
    assert!(
        saw::port::open(&vb.port).is_ok(),
        "a panel with no page took the port when it freed"
    );
}

/// Waits (up to 10 s) until the port can be opened, i.e. nothing holds it.
fn until_free(port: &std::path::Path, what: &str) {
    let end = Instant::now() + Duration::from_secs(10);
    loop {
        match saw::port::open(port) {
            Ok(_) => return,
            Err(e) if Instant::now() > end => panic!("{what}: {e}"),
            Err(_) => std::thread::sleep(Duration::from_millis(100)),
        }
    }
}

#[test]
fn the_port_is_held_only_while_a_page_is_open() {
    let vb = VirtualBoard::start(&[]);
    let ui = panel(&vb);
    // No page yet: over four of the panel's retries the port stays free.
    std::thread::sleep(Duration::from_millis(1200));
    assert!(
        saw::port::open(&vb.port).is_ok(),
        "the panel took the port with no page open"
    );
    let mut ws = socket(&ui);
    let link = next(&mut ws, "link", 5.0).expect("no link message");
    assert_eq!(link["ok"], true, "{link}");
    assert!(
        saw::port::open(&vb.port).is_err(),
        "a page is open: the panel holds the port"
    );
    // The tab closed: the panel lets go of the port.
    drop(ws);
    until_free(
        &vb.port,
        "the panel held the port 10 s after its page closed",
    );
    // A page again: the link comes back, with its telemetry.
    let mut ws = socket(&ui);
    let link = next(&mut ws, "link", 5.0).expect("no link message");
    assert_eq!(link["ok"], true, "{link}");
    assert!(next(&mut ws, "records", 5.0).is_some());
}

/// The panel's save from a store at its first erase: the virtual F446 erases a 128 KiB sector
/// for 1 s before it answers (as the board does), longer than the panel's 1 s wait per answer;
/// the save still succeeds (`saw::SAVE_TIMEOUT`) and says how long it took.
#[test]
fn the_panels_save_waits_for_a_sector_erase() {
    let (image, _) = common::f446_store_before_an_erase();
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    std::fs::write(&flash, &image).unwrap();
    let flash_arg = flash.to_str().unwrap().to_string();
    let vb = VirtualBoard::start_in(dir, &["--board", "nucleo-f446re", "--flash", &flash_arg]);
    let ui = panel(&vb);
    let mut ws = socket(&ui);
    assert_eq!(next(&mut ws, "link", 5.0).unwrap()["ok"], true);
    let a = command(&mut ws, json!({"id": 7, "cmd": "save"}));
    assert_eq!(a["ok"], true, "{a}");
    let text = a["text"].as_str().unwrap();
    assert!(
        text.starts_with("saved scene 0x") && text.contains(" s: the board boots into it"),
        "{a}"
    );
    // The save erased a sector (a byte back at 0xFF), and the link stayed up through it.
    let after = std::fs::read(&flash).unwrap();
    assert!(image
        .iter()
        .zip(&after)
        .any(|(b, a)| *b != 0xFF && *a == 0xFF));
    assert!(next(&mut ws, "records", 5.0).is_some());
}

/// The panel's save on the real F446 image: `board-model serve` (`SAW_BOARD_MODEL_BIN`) runs
/// `SAW_F446_ELF` with its store filled to the first erase, so the save erases a 128 KiB sector
/// (1.11 s of board time; the model never runs ahead of the wall clock). The panel waits its
/// usual 1 s per answer and `SAVE_TIMEOUT` for the save. Ignored without those variables;
/// `scripts/board-model.sh` runs it.
#[test]
#[ignore = "needs SAW_BOARD_MODEL_BIN and SAW_F446_ELF; scripts/board-model.sh runs it"]
fn the_panels_save_on_the_f446_image_waits_for_its_sector_erase() {
    let (Ok(bin), Ok(elf)) = (
        std::env::var("SAW_BOARD_MODEL_BIN"),
        std::env::var("SAW_F446_ELF"),
    ) else {
        panic!("set SAW_BOARD_MODEL_BIN and SAW_F446_ELF");
    };
    let (image, _) = common::f446_store_before_an_erase();
    let dir = tempfile::tempdir().unwrap();
    let flash = dir.path().join("flash.bin");
    std::fs::write(&flash, &image).unwrap();
    let port = dir.path().join("tty");
    let mut served = std::process::Command::new(bin)
        .args(["serve", "--board", "nucleo-f446re", "--elf", &elf, "--pty"])
        .arg(&port)
        .arg("--flash")
        .arg(&flash)
        .arg("--log")
        .arg(dir.path().join("defmt.log"))
        .spawn()
        .unwrap();
    let give_up = Instant::now() + Duration::from_secs(60);
    while !port.exists() && Instant::now() < give_up {
        std::thread::sleep(Duration::from_millis(20));
    }
    let result = std::panic::catch_unwind(|| {
        let ui = saw::ui::start(saw::ui::UiOptions {
            port: port.clone(),
            listen: "127.0.0.1:0".parse().unwrap(),
            allow_remote: false,
            timeout: Duration::from_millis(1000),
            every: 10,
        })
        .unwrap();
        let mut ws = socket(&ui);
        let link = next(&mut ws, "link", 10.0).expect("no link message");
        assert_eq!(link["ok"], true, "{link}");
        assert_eq!(link["hello"]["board"], "nucleo-f446re", "{link}");
        ws.send(Message::Text(
            json!({"id": 9, "cmd": "save"}).to_string().into(),
        ))
        .unwrap();
        let a = next(&mut ws, "answer", 10.0).expect("no answer");
        assert_eq!(a["ok"], true, "{a}");
        let text = a["text"].as_str().unwrap();
        assert!(text.starts_with("saved scene 0x"), "{a}");
        eprintln!("panel on the F446 image: {text}");
    });
    let _ = served.kill();
    let _ = served.wait();
    if let Err(p) = result {
        std::panic::resume_unwind(p);
    }
}
