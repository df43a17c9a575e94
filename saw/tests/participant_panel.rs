//! The participant's panel of `saw experiment run --panel` against the virtual board
//! (`host-sim serve --pty`): in headless Chromium, a participant clicks the response buttons of
//! every trial and the session's CSV holds each click; over plain HTTP, a panel listening off
//! loopback refuses every request and WebSocket upgrade without the run's token or with another
//! site's Origin, refuses an answer out of range with a sentence (nothing recorded), and a
//! non-loopback address without --allow-remote is refused at the door.
//!
//! The browser test skips (with a line saying so) where chromedriver is not installed
//! (scripts/setup.sh installs chromium and chromium-driver).

// The shared helpers; this file does not use them all.
#[allow(dead_code)]
mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, Read, Write};
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use common::browser::{browser, js, until};
use common::VirtualBoard;
use fantoccini::{Client, Locator};
use serde_json::Value;

/// Two inline-region stimuli compared both ways (Ura's variant): two trials, quick.
fn protocol(dir: &Path, explore_s: f64) -> std::path::PathBuf {
    let p = dir.join("tiny.toml");
    std::fs::write(
        &p,
        format!(
            r#"[experiment]
name = "Two surfaces"
seed = 11
instructions = "Explore each surface, then say which was rougher."

[timing]
explore_s = {explore_s}
pause_s = 0.05

[[stimulus]]
name = "20 Hz"
region = {{ kind = "constant", f_b_hz = 20, duty_percent = 40 }}

[[stimulus]]
name = "200 Hz"
region = {{ kind = "constant", f_b_hz = 200, duty_percent = 40 }}

[[block]]
name = "virtual"
design = "paired"
variant = "ura"
stimuli = ["20 Hz", "200 Hz"]
"#
        ),
    )
    .unwrap();
    p
}

/// A `saw --json experiment run … --panel` in its own process group, killed on drop.
struct Session {
    child: Child,
    lines: Receiver<String>,
    /// The panel's first JSON line: `result.panel`.
    panel: Value,
    stderr: std::path::PathBuf,
}

impl Session {
    fn start(vb: &VirtualBoard, dir: &Path, protocol: &Path, panel: &[&str]) -> Session {
        let stderr = dir.join("saw.stderr");
        let mut child = Command::new(env!("CARGO_BIN_EXE_saw"))
            .process_group(0)
            .arg("--json")
            .arg("--port")
            .arg(&vb.port)
            .args(["experiment", "run"])
            .arg(protocol)
            .args(["--subject", "p1", "--out"])
            .arg(dir.join("out"))
            .args(panel)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(std::fs::File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for l in std::io::BufReader::new(out).lines() {
                let Ok(l) = l else { return };
                if tx.send(l).is_err() {
                    return;
                }
            }
        });
        let first = lines
            .recv_timeout(Duration::from_secs(20))
            .unwrap_or_else(|_| {
                panic!(
                    "no JSON line from saw: {}",
                    std::fs::read_to_string(&stderr).unwrap_or_default()
                )
            });
        let v: Value = serde_json::from_str(&first).unwrap_or_else(|e| panic!("{e}: {first}"));
        assert_eq!(v["ok"], true, "{v}");
        let panel = v["result"]["panel"].clone();
        assert!(
            panel["participant"]
                .as_str()
                .is_some_and(|u| u.contains("/participant?token=")),
            "{v}"
        );
        Session {
            child,
            lines,
            panel,
            stderr,
        }
    }

    fn port(&self) -> u16 {
        let at = self.panel["listening"].as_str().unwrap();
        at.rsplit(':').next().unwrap().parse().unwrap()
    }

    fn token(&self) -> String {
        let u = self.panel["participant"].as_str().unwrap();
        u.rsplit("token=").next().unwrap().to_string()
    }

    /// Waits for the command to end: its last JSON line (the session's answer).
    fn finish(&mut self) -> Value {
        let end = Instant::now() + Duration::from_secs(30);
        let mut last = None;
        loop {
            match self.lines.recv_timeout(Duration::from_millis(100)) {
                Ok(l) => last = Some(l),
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
                Err(_) if Instant::now() > end => panic!("saw did not end within 30 s"),
                Err(_) => {}
            }
        }
        let status = self.child.wait().unwrap();
        let err = std::fs::read_to_string(&self.stderr).unwrap_or_default();
        assert!(status.success(), "saw: {status}: {err}");
        let last = last.expect("no answer line");
        serde_json::from_str(&last).unwrap_or_else(|e| panic!("{e}: {last}"))
    }
}

impl Drop for Session {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The session CSV's rows: trial number → response.
fn responses(csv: &Path) -> BTreeMap<u32, i32> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut rows = text.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (t, r) = (col("trial"), col("response"));
    rows.map(|l| {
        let f: Vec<&str> = l.split(',').collect();
        (f[t].parse().unwrap(), f[r].parse().unwrap())
    })
    .collect()
}

// --- the browser ---------------------------------------------------------------------------

/// Clicks the element `css` finds, as a person would (WebDriver's click: it must be shown and
/// enabled). The page re-renders on every state it is sent, so the element found can be
/// replaced before the click lands (a stale reference): found again and retried, for up to 5 s.
async fn click(c: &Client, css: &str) {
    let end = std::time::Instant::now() + std::time::Duration::from_secs(5);
    loop {
        let tried = match c.find(Locator::Css(css)).await {
            Ok(e) => e.click().await.map(|_| ()),
            Err(e) => Err(e),
        };
        match tried {
            Ok(()) => return,
            Err(e) if std::time::Instant::now() < end => {
                let _ = e;
                tokio::time::sleep(std::time::Duration::from_millis(50)).await;
            }
            Err(e) => panic!("clicking {css}: {e}"),
        }
    }
}

async fn screenshot(c: &Client, name: &str) {
    let png = c.screenshot().await.unwrap();
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../target/ui-screens");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(format!("{dir}/{name}.png"), &png).unwrap();
    if let Ok(d) = std::env::var("SAW_UI_SCREENSHOTS") {
        let d = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(d);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join(format!("{name}.png")), &png).unwrap();
    }
}

/// The grade clicked for trial `n`: a different one for each trial, so that a response logged
/// for the wrong trial shows.
fn grade_for(n: u32) -> i32 {
    [2, -1, 1, -2, 0][n as usize % 5]
}

#[tokio::test(flavor = "current_thread")]
async fn a_participant_answers_every_trial_with_the_panel_buttons() {
    if Command::new("chromedriver")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_err()
    {
        eprintln!("skipped: chromedriver is not installed (scripts/setup.sh installs chromium and chromium-driver)");
        return;
    }
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    let proto = protocol(dir.path(), 0.2);
    let mut s = Session::start(&vb, dir.path(), &proto, &["--panel", "127.0.0.1:0"]);
    let (_driver, c) = browser("1024,768").await;
    c.goto(s.panel["participant"].as_str().unwrap())
        .await
        .unwrap();
    until(
        &c,
        "the instructions",
        "return document.body.dataset.phase === 'instructions' && !document.getElementById('p-continue').hidden",
        15,
    )
    .await;
    screenshot(&c, "participant-instructions").await;
    click(&c, "#p-continue").await;

    let mut clicked = BTreeMap::new();
    loop {
        until(
            &c,
            "a question open or the session over",
            "const p = window.panel.state && window.panel.state.phase; return p === 'question' || p === 'over'",
            20,
        )
        .await;
        let state = js(&c, "return window.panel.state").await;
        if state["phase"] == "over" {
            break;
        }
        let trial = state["question"]["trial"].as_u64().unwrap() as u32;
        assert!(!clicked.contains_key(&trial), "trial {trial} asked twice");
        let grade = grade_for(trial);
        if trial == 0 {
            screenshot(&c, "participant-question").await;
        }
        click(&c, &format!("#p-buttons button[data-value='{grade}']")).await;
        clicked.insert(trial, grade);
        until(
            &c,
            "the answer taken",
            &format!(
                "const s = window.panel.state; return s.phase !== 'question' || s.question.trial !== {trial}"
            ),
            10,
        )
        .await;
        if trial == 0 {
            // The experimenter's view, in a second tab: progress and the response just given.
            let here = c.window().await.unwrap();
            let tab = c.new_window(true).await.unwrap();
            c.switch_to_window(tab.handle).await.unwrap();
            c.goto(s.panel["experimenter"].as_str().unwrap())
                .await
                .unwrap();
            until(
                &c,
                "the experimenter's view with the first response",
                "const s = window.panel.state; return !!s && s.history.length === 1",
                10,
            )
            .await;
            let e = js(&c, "return [document.getElementById('e-progress').textContent, document.getElementById('e-history').textContent]").await;
            assert!(
                e[0].as_str().unwrap().ends_with(" of 2"),
                "progress: {}",
                e[0]
            );
            assert!(
                e[1].as_str().unwrap().contains(&format!("{grade} (")),
                "history: {}",
                e[1]
            );
            screenshot(&c, "experimenter").await;
            c.close_window().await.unwrap();
            c.switch_to_window(here).await.unwrap();
        }
    }
    let renders = js(&c, "return window.panel.renders").await;
    let renders = renders.as_array().unwrap();
    // While a surface is explored the question's buttons are shown closed; once the question
    // is open, all of them answer.
    let exploring: Vec<&Value> = renders
        .iter()
        .filter(|r| r["phase"] == "explore" && r["buttons"].as_u64() > Some(0))
        .collect();
    assert!(
        !exploring.is_empty(),
        "no exploration rendered with its question: {renders:?}"
    );
    for r in &exploring {
        assert_eq!(
            r["disabled"], r["buttons"],
            "a button open while exploring: {r}"
        );
    }
    for r in renders.iter().filter(|r| r["phase"] == "question") {
        assert_eq!(r["buttons"], 5, "{r}");
        assert_eq!(r["disabled"], 0, "a button closed while asking: {r}");
    }
    let text = js(&c, "return document.getElementById('p-text').textContent").await;
    assert_eq!(text, "The session is over. Thank you!");

    let done = s.finish();
    assert_eq!(done["result"]["trials"], 2, "{done}");
    let logged = responses(&dir.path().join("out/p1.csv"));
    assert_eq!(logged, clicked, "the CSV's responses against the clicks");
    assert_eq!(logged.len(), 2);
}

// --- plain HTTP ----------------------------------------------------------------------------

/// One HTTP/1.1 request: the status and the body.
fn http(
    port: u16,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &str,
) -> (u16, String) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut req =
        format!("{method} {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\n");
    for (k, v) in headers {
        req += &format!("{k}: {v}\r\n");
    }
    if !body.is_empty() {
        req += &format!(
            "Content-Type: application/json\r\nContent-Length: {}\r\n",
            body.len()
        );
    }
    req += "\r\n";
    req += body;
    s.write_all(req.as_bytes()).unwrap();
    let mut got = Vec::new();
    let _ = s.read_to_end(&mut got);
    let got = String::from_utf8_lossy(&got).to_string();
    let status = got
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("not an HTTP answer: {got:?}"));
    let body = got.split_once("\r\n\r\n").map_or("", |b| b.1).to_string();
    (status, body)
}

/// A WebSocket upgrade: the status of the answer (101: upgraded).
fn upgrade(port: u16, path: &str, origin: Option<&str>) -> u16 {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let mut req = format!(
        "GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
    );
    if let Some(o) = origin {
        req += &format!("Origin: {o}\r\n");
    }
    req += "\r\n";
    s.write_all(req.as_bytes()).unwrap();
    let mut got = Vec::new();
    let mut b = [0u8; 1];
    while !got.ends_with(b"\r\n\r\n") {
        match s.read(&mut b) {
            Ok(1) => got.push(b[0]),
            _ => break,
        }
    }
    let got = String::from_utf8_lossy(&got).to_string();
    got.split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or_else(|| panic!("not an HTTP answer: {got:?}"))
}

/// The participant's view over its WebSocket: the next state `pred` accepts.
fn next_state(
    ws: &mut tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    what: &str,
    pred: impl Fn(&Value) -> bool,
) -> Value {
    let end = Instant::now() + Duration::from_secs(20);
    while Instant::now() < end {
        match ws.read() {
            Ok(tungstenite::Message::Text(t)) => {
                let v: Value = serde_json::from_str(&t).unwrap();
                if pred(&v) {
                    return v;
                }
            }
            Ok(_) => {}
            Err(e) => panic!("{what}: the socket ended: {e}"),
        }
    }
    panic!("{what}: not within 20 s");
}

#[test]
fn a_remote_panel_refuses_whatever_lacks_the_token_or_comes_from_another_site() {
    let vb = VirtualBoard::start(&[]);
    let dir = tempfile::tempdir().unwrap();
    // Long enough explorations that an answer sent during one lands in it.
    let proto = protocol(dir.path(), 1.0);
    let mut s = Session::start(
        &vb,
        dir.path(),
        &proto,
        &["--panel", "0.0.0.0:0", "--allow-remote"],
    );
    let (port, token) = (s.port(), s.token());
    assert_eq!(token.len(), 32, "128 bits as hex: {token}");
    assert!(token.bytes().all(|b| b.is_ascii_hexdigit()), "{token}");
    let wrong: String = token
        .chars()
        .map(|c| if c == '0' { '1' } else { '0' })
        .collect();
    let with = |path: &str| format!("{path}?token={token}");
    let with_wrong = |path: &str| format!("{path}?token={wrong}");

    // Pages: nothing without the token (not even a 404), nothing with another.
    for path in ["/participant", "/experimenter", "/", "/nothing-here"] {
        let (code, body) = http(port, "GET", path, &[], "");
        assert_eq!(code, 403, "GET {path} without the token: {body}");
        assert!(
            body.starts_with("refused: this panel needs the run's token") && !body.contains('<'),
            "GET {path}: {body}"
        );
        let (code, body) = http(port, "GET", &with_wrong(path), &[], "");
        assert_eq!(code, 403, "GET {path} with a wrong token: {body}");
    }
    let (code, page) = http(port, "GET", &with("/participant"), &[], "");
    assert_eq!(code, 200);
    assert!(page.contains("<main id=\"participant\""), "{page}");
    let (code, _) = http(port, "GET", &with("/experimenter"), &[], "");
    assert_eq!(code, 200);
    // The cookie a tokened request sets stands for the token (a reload without the query).
    let cookie = format!("saw-panel-{port}={token}");
    let (code, _) = http(port, "GET", "/participant", &[("Cookie", &cookie)], "");
    assert_eq!(code, 200, "with the cookie");
    let bad_cookie = format!("saw-panel-{port}={wrong}");
    let (code, _) = http(port, "GET", "/participant", &[("Cookie", &bad_cookie)], "");
    assert_eq!(code, 403, "with a wrong cookie");

    // WebSocket upgrades: the token, and the page's own Origin when one is sent.
    let own = format!("http://127.0.0.1:{port}");
    assert_eq!(upgrade(port, "/ws/participant", None), 403, "no token");
    assert_eq!(
        upgrade(port, "/ws/participant", Some(&own)),
        403,
        "no token, own origin"
    );
    assert_eq!(
        upgrade(port, &with_wrong("/ws/participant"), Some(&own)),
        403,
        "wrong token"
    );
    assert_eq!(
        upgrade(port, &with("/ws/participant"), Some("http://evil.example")),
        403,
        "a foreign Origin"
    );
    assert_eq!(
        upgrade(port, &with("/ws/experimenter"), Some("http://evil.example")),
        403,
        "a foreign Origin"
    );
    assert_eq!(
        upgrade(port, &with("/ws/participant"), Some(&own)),
        101,
        "the page's own"
    );

    // Answers: the token and the Origin again, then the trial's values.
    let (mut ws, _) =
        tungstenite::connect(format!("ws://127.0.0.1:{port}{}", with("/ws/participant"))).unwrap();
    let first = next_state(&mut ws, "the instructions", |v| {
        v["phase"] == "instructions"
    });
    let seq = first["seq"].to_string();
    let go = format!(r#"{{"seq": {seq}}}"#);
    let (code, body) = http(port, "POST", "/continue", &[], &go);
    assert_eq!(code, 403, "continue without the token: {body}");
    let (code, body) = http(
        port,
        "POST",
        &with("/continue"),
        &[("Origin", "http://evil.example")],
        &go,
    );
    assert_eq!(code, 403, "continue from another site: {body}");
    assert!(body.contains("Origin `http://evil.example`"), "{body}");
    let (code, body) = http(port, "POST", &with("/continue"), &[("Origin", &own)], &go);
    assert_eq!((code, body.as_str()), (200, "continued"));

    let exploring = next_state(&mut ws, "the first exploration", |v| {
        v["phase"] == "explore"
    });
    assert_eq!(exploring["text"], "Explore the first surface now.");
    assert_eq!(exploring["question"]["open"], false, "{exploring}");
    // The participant's view names no stimulus.
    assert!(!exploring.to_string().contains("Hz"), "{exploring}");
    let (code, body) = http(
        port,
        "POST",
        &with("/respond"),
        &[],
        r#"{"trial": 0, "value": 1}"#,
    );
    assert_eq!(code, 409, "an answer while exploring: {body}");
    assert!(body.contains("no question is open now"), "{body}");

    let mut given = BTreeMap::new();
    for _ in 0..2 {
        // A question not answered yet (a page's coming or going sends the state again).
        let q = next_state(&mut ws, "a question", |v| {
            v["phase"] == "question"
                && !given.contains_key(&(v["question"]["trial"].as_u64().unwrap() as u32))
        });
        let trial = q["question"]["trial"].as_u64().unwrap() as u32;
        let answer = |value: i32| format!(r#"{{"trial": {trial}, "value": {value}}}"#);
        let (code, body) = http(port, "POST", "/respond", &[], &answer(1));
        assert_eq!(code, 403, "an answer without the token: {body}");
        let (code, body) = http(
            port,
            "POST",
            &with("/respond"),
            &[("Origin", "http://evil.example")],
            &answer(1),
        );
        assert_eq!(code, 403, "an answer from another site: {body}");
        let (code, body) = http(port, "POST", &with("/respond"), &[], &answer(3));
        assert_eq!(code, 400, "{body}");
        assert_eq!(
            body,
            format!("value 3: not an answer to trial {trial}; it is one of -2, -1, 0, 1, 2; nothing recorded")
        );
        let grade = grade_for(trial + 1);
        let (code, body) = http(
            port,
            "POST",
            &with("/respond"),
            &[("Origin", &own)],
            &answer(grade),
        );
        assert_eq!(code, 200, "{body}");
        let (code, body) = http(port, "POST", &with("/respond"), &[], &answer(0));
        assert_eq!(code, 409, "a second answer: {body}");
        given.insert(trial, grade);
    }
    let done = s.finish();
    assert_eq!(done["result"]["trials"], 2, "{done}");
    assert_eq!(responses(&dir.path().join("out/p1.csv")), given);
}

#[test]
fn a_panel_off_loopback_needs_allow_remote() {
    let dir = tempfile::tempdir().unwrap();
    let proto = protocol(dir.path(), 0.2);
    let out = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(dir.path().join("no-such-port"))
        .args(["experiment", "run"])
        .arg(&proto)
        .args(["--subject", "p1", "--out"])
        .arg(dir.path().join("out"))
        .args(["--panel", "0.0.0.0:0"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--panel 0.0.0.0:0: not a loopback address; the participant's panel listens on loopback (127.0.0.1) unless --allow-remote is given"),
        "{err}"
    );
    assert!(!dir.path().join("out").exists(), "a session began");
}
