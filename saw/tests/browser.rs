//! The panel in a real browser: Debian's headless Chromium driven over WebDriver (chromedriver),
//! against the virtual board. The page loads and links; the finger marker sits where the
//! virtual finger rests; dragging a boundary shows its position in mm while dragging and moves
//! the board's boundary to it (read back with `saw` once the panel has let go of the port); a
//! refused edit shows the board's sentence in view on a short window; a file of random bytes is
//! refused by name without its bytes; pulling the virtual board shows "link lost", the trace is
//! drawn against the board's time with a gap where records are missing, an edit is refused as
//! not sent, and the page comes back (the refusal gone) when the board returns; an open wiper is
//! named on the strip while it lasts, judged in the board's time. Frame times are measured in the
//! browser while the stream runs and printed (a benchmark figure, docs/ui.md; not asserted: they
//! depend on the machine's load). Screenshots go to target/ui-screens/ (and to the directory in
//! SAW_UI_SCREENSHOTS, e.g. docs/ui, to refresh the committed ones).

mod common;

use std::process::Command;
use std::time::{Duration, Instant};

use common::browser::{browser, js, until};
use common::{panel, VirtualBoard};
use fantoccini::actions::{InputSource, MouseActions, PointerAction, MOUSE_BUTTON_LEFT};
use fantoccini::Client;
use serde_json::{json, Value};

/// Records what the page draws: for each canvas, the `fillText`, `moveTo` and `lineTo` calls
/// since its last `clearRect` (the start of its frame), in `window.drawn[canvas id]`.
async fn record_drawing(c: &Client) {
    js(
        c,
        r#"
        const P = CanvasRenderingContext2D.prototype;
        window.drawn = {};
        const clear = P.clearRect;
        P.clearRect = function (...a) { window.drawn[this.canvas.id] = []; return clear.apply(this, a); };
        for (const m of ["fillText", "moveTo", "lineTo"]) {
          const f = P[m];
          P[m] = function (...a) {
            (window.drawn[this.canvas.id] ||= []).push([m, ...a]);
            return f.apply(this, a);
          };
        }
        return true;"#,
    )
    .await;
}

/// Whether element `id` lies wholly inside the browser's window.
async fn in_view(c: &Client, id: &str) -> bool {
    js(
        c,
        &format!(
            "const r = document.getElementById('{id}').getBoundingClientRect(); \
             return r.height > 0 && r.top >= 0 && r.bottom <= window.innerHeight"
        ),
    )
    .await
        == json!(true)
}

/// `n` bytes from a fixed xorshift sequence: a file no text editor wrote.
fn random_bytes(n: usize) -> Vec<u8> {
    let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 24) as u8
        })
        .collect()
}

async fn screenshot(c: &Client, name: &str) {
    let png = c.screenshot().await.unwrap();
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../target/ui-screens");
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(format!("{dir}/{name}.png"), &png).unwrap();
    if let Ok(d) = std::env::var("SAW_UI_SCREENSHOTS") {
        let d = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("..")
            .join(d);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::write(d.join(format!("{name}.png")), &png).unwrap();
    }
}

#[tokio::test(flavor = "current_thread")]
async fn the_panel_in_a_real_browser() {
    // The finger rests at 42.5 mm on the default scene.
    let vb = VirtualBoard::start(&["--rest-at", "42.5"]);
    let ui = panel(&vb);
    let (_driver, c) = browser("1300,1000").await;
    c.goto(&format!("http://127.0.0.1:{}/", ui.addr.port()))
        .await
        .unwrap();
    until(
        &c,
        "linked",
        "return document.body.dataset.link === 'ok'",
        10,
    )
    .await;
    until(
        &c,
        "finger drawn",
        "return document.getElementById('strip').dataset.fingerMm !== undefined",
        10,
    )
    .await;
    let finger: f64 = js(
        &c,
        "return Number(document.getElementById('strip').dataset.fingerMm)",
    )
    .await
    .as_f64()
    .unwrap();
    assert!(
        (finger - 42.5).abs() < 0.3,
        "the marker at {finger} mm, the finger at 42.5 mm"
    );
    // Let the trace fill, then measure frames over 2 s with the stream at 1 kHz. The times are a
    // benchmark figure (printed, and in docs/ui.md), not a check: on a machine busy with other
    // jobs they grow with the load.
    tokio::time::sleep(Duration::from_secs(2)).await;
    js(&c, "const S = window.sawState; S.frames = 0; S.frameMsSum = 0; S.frameMsMax = 0; S.drawMsMax = 0; S.recordsSeen = 0; return true").await;
    tokio::time::sleep(Duration::from_secs(2)).await;
    let perf = js(&c, "const S = window.sawState; return [S.frames, S.frameMsSum / S.frames, S.frameMsMax, S.drawMsMax, S.recordsSeen]").await;
    let (frames, mean, worst, draw, seen) = (
        perf[0].as_f64().unwrap(),
        perf[1].as_f64().unwrap(),
        perf[2].as_f64().unwrap(),
        perf[3].as_f64().unwrap(),
        perf[4].as_f64().unwrap(),
    );
    eprintln!("browser: {frames} frames in 2 s, mean {mean:.1} ms, worst {worst:.1} ms, drawing at most {draw:.2} ms; {seen} records");
    // The functional part: the page keeps drawing and takes in the stream.
    assert!(frames > 0.0, "no frame drawn in 2 s");
    assert!(seen > 1500.0, "{seen} records in 2 s at 1 kHz");
    screenshot(&c, "panel").await;

    // Drag boundary 0 from where the board has it to 30 mm.
    let xy = js(
        &c,
        r#"
        const s = document.getElementById('strip'), r = s.getBoundingClientRect();
        const k = r.width / s.width, sc = window.sawState.scene;
        const px = (mm) => r.left + (30 + mm / sc.length_mm * (s.width - 60)) * k;
        return [px(sc.regions[0].to_mm), px(30), r.top + 60 * k];"#,
    )
    .await;
    let (x0, x1, y) = (
        xy[0].as_f64().unwrap(),
        xy[1].as_f64().unwrap(),
        xy[2].as_f64().unwrap(),
    );
    let before = js(&c, "return document.body.dataset.sceneId").await;
    let press_and_move = MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x: x0.round() as i64,
            y: y.round() as i64,
        })
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        })
        .then(PointerAction::MoveTo {
            duration: Some(Duration::from_millis(200)),
            x: x1.round() as i64,
            y: y.round() as i64,
        });
    c.perform_actions(press_and_move).await.unwrap();
    // Still held: the boundary's position is shown, in mm, at the pointer.
    until(
        &c,
        "the dragged boundary's position shown",
        "const l = document.getElementById('drag-mm'); return !l.hidden && l.textContent.endsWith(' mm')",
        5,
    )
    .await;
    let shown = js(&c, "const l = document.getElementById('drag-mm'), r = l.getBoundingClientRect(); return [l.textContent, (r.left + r.right) / 2]").await;
    let shown_mm: f64 = shown[0]
        .as_str()
        .unwrap()
        .trim_end_matches(" mm")
        .parse()
        .unwrap_or_else(|e| panic!("{shown}: {e}"));
    // A CSS pixel is 0.055 mm on this strip; the pointer lands on a whole pixel.
    assert!(
        (shown_mm - 30.0).abs() < 0.1,
        "shown while dragging: {shown}"
    );
    assert!(
        (shown[1].as_f64().unwrap() - x1).abs() < 10.0,
        "the label at x = {shown}, the pointer at {x1}"
    );
    screenshot(&c, "dragging").await;
    let release = MouseActions::new("mouse".into()).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    });
    c.perform_actions(release).await.unwrap();
    until(
        &c,
        "the board's new scene",
        &format!("return document.body.dataset.sceneId !== {before}"),
        5,
    )
    .await;
    let to_mm = js(&c, "return window.sawState.scene.regions[0].to_mm")
        .await
        .as_f64()
        .unwrap();
    // The value shown is the value sent: the board has the boundary there (to its 1 µm).
    assert!(
        (to_mm - shown_mm).abs() < 0.0011,
        "boundary 0 at {to_mm} mm after the drag, {shown_mm} mm shown while dragging"
    );
    assert!(
        js(&c, "return document.getElementById('drag-mm').hidden").await == json!(true),
        "the position label outlived the drag"
    );
    screenshot(&c, "dragged").await;

    // Checked through `saw`: the panel lets go of the port, `saw get` reads the board's scene.
    ui.stop();
    let out = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args(["--json", "get"])
        .output()
        .unwrap();
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    let got: Value = serde_json::from_slice(&out.stdout).unwrap();
    // The board's scene as a scene file's keys: region 0 ends at boundary 0.
    let b0 = got["result"]["scene"]["region"][0]["until_mm"]
        .as_f64()
        .unwrap_or_else(|| panic!("no boundary 0 in {got}"));
    assert!((b0 - 30.0).abs() < 0.1, "the board's boundary 0 at {b0} mm");

    // A new panel on the same board; the page reloaded.
    let ui = panel(&vb);
    c.goto(&format!("http://127.0.0.1:{}/", ui.addr.port()))
        .await
        .unwrap();
    until(
        &c,
        "linked again",
        "return document.body.dataset.link === 'ok' && window.sawState.scene !== null",
        10,
    )
    .await;
    record_drawing(&c).await;

    // A refused edit on a short window (a laptop's, the page scrolled): the board's (the scene
    // file's) sentence in the page, and in view wherever the page is scrolled to.
    c.set_window_size(1300, 500).await.unwrap();
    c.find(fantoccini::Locator::Id("keys"))
        .await
        .unwrap()
        .send_keys("kind=grating wavelength_mm=-1")
        .await
        .unwrap();
    c.find(fantoccini::Locator::Id("apply"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    until(
        &c,
        "the refusal",
        "return document.getElementById('answer').className === 'refused'",
        5,
    )
    .await;
    let text = js(&c, "return document.getElementById('answer').textContent").await;
    assert!(text.as_str().unwrap().contains("wavelength_mm"), "{text}");
    assert!(
        in_view(&c, "answer").await,
        "the refusal below the window after Apply"
    );
    for scroll in ["0", "document.body.scrollHeight"] {
        js(&c, &format!("window.scrollTo(0, {scroll}); return true")).await;
        assert!(
            in_view(&c, "answer").await,
            "the refusal out of the window, scrolled to {scroll}"
        );
    }
    screenshot(&c, "refused").await;
    c.set_window_size(1300, 1000).await.unwrap();
    js(&c, "window.scrollTo(0, 0); return true").await;

    // A file of random bytes loaded as a scene: refused by its name and the rule, none of its
    // bytes shown, nothing sent (the board's scene unchanged).
    let dir = tempfile::tempdir().unwrap();
    let noise = dir.path().join("noise.bin");
    std::fs::write(&noise, random_bytes(4096)).unwrap();
    let scene_before = js(&c, "return document.body.dataset.sceneId").await;
    js(
        &c,
        "document.getElementById('answer').textContent = ''; return true",
    )
    .await;
    c.find(fantoccini::Locator::Id("file"))
        .await
        .unwrap()
        .send_keys(noise.to_str().unwrap())
        .await
        .unwrap();
    until(
        &c,
        "the file refused",
        "return document.getElementById('answer').textContent.includes('noise.bin')",
        5,
    )
    .await;
    let said = js(
        &c,
        "const a = document.getElementById('answer'); return [a.className, a.textContent]",
    )
    .await;
    let text = said[1].as_str().unwrap();
    assert_eq!(said[0], "refused", "{said}");
    assert!(text.contains("TOML text"), "the rule not named: {text}");
    assert!(
        text.chars().count() < 160
            && !text.contains('\u{fffd}')
            && !text.chars().any(char::is_control),
        "the file's bytes echoed: {text:?}"
    );
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        js(&c, "return document.body.dataset.sceneId").await,
        scene_before
    );

    // Unplugged, then back.
    let dir = vb.power_off();
    until(&c, "link lost shown", "return document.body.dataset.link === 'lost' && document.getElementById('status').textContent.includes('link lost')", 10).await;
    screenshot(&c, "link-lost").await;

    // The trace against the board's time, while no records come: 1 kHz records from 10 s to
    // 12 s of board time with none from 11 s to 11.5 s. The trace is 1200 px for 5 s, its right
    // edge the last record (12 s): a record at t s is drawn at x = 1200 (1 - (12 - t) / 5).
    js(
        &c,
        r#"
        // A record at 0 s first: the page starts its trace afresh (board time went back), and
        // the 10 s batch pushes it out of the 5 s window.
        onMessage({ t: "records", records: [[0, null, null, 0, 0, false, null]], dropped: 0 });
        const rs = [];
        for (let t = 10000000; t <= 12000000; t += 1000)
          if (t < 11000000 || t >= 11500000)
            rs.push([t, 20000 + (t - 10000000) / 100, 10000, 0, 100, true, null]);
        onMessage({ t: "stream", records_per_s: 1000 });
        onMessage({ t: "records", records: rs, dropped: 0 });
        return true"#,
    )
    .await;
    until(
        &c,
        "the injected records drawn",
        "return (window.drawn.trace || []).some((c) => c[0] === 'fillText' && c[1] === '10 s')",
        5,
    )
    .await;
    let drawn = js(&c, "return [window.drawn.trace, window.drawn.strip]").await;
    let calls = |canvas: usize, what: &str| -> Vec<Vec<Value>> {
        drawn[canvas]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_array().unwrap().clone())
            .filter(|c| c[0] == what)
            .collect()
    };
    let x_of = |t_s: f64| 1200.0 * (1.0 - (12.0 - t_s) / 5.0);
    // The position panel is the top third above the 20 px time axis: y < 93 px.
    let pen = |what: &str| -> Vec<f64> {
        calls(0, what)
            .iter()
            .filter(|c| c[2].as_f64().unwrap() < 93.0)
            .map(|c| c[1].as_f64().unwrap())
            .collect()
    };
    let (starts, lines) = (pen("moveTo"), pen("lineTo"));
    assert_eq!(
        starts.len(),
        2,
        "one gap, two runs: pen down at x = {starts:?}"
    );
    assert!(
        (starts[0] - x_of(10.0)).abs() < 0.5 && (starts[1] - x_of(11.5)).abs() < 0.5,
        "the runs start at x = {starts:?}, the records at 10 s and 11.5 s at {} and {}",
        x_of(10.0),
        x_of(11.5)
    );
    // No line is drawn across the gap (from 10.999 s to 11.5 s).
    assert!(
        !lines
            .iter()
            .any(|&x| x > x_of(10.999) + 0.5 && x < x_of(11.5) - 0.5),
        "a line across the gap: {lines:?}"
    );
    assert!((lines.last().unwrap() - 1200.0).abs() < 0.5, "{lines:?}");
    // The time axis in seconds of the board's time, ticks where those times are drawn; units on
    // every panel and on the strip.
    let texts: Vec<(String, f64)> = calls(0, "fillText")
        .iter()
        .map(|c| (c[1].as_str().unwrap().to_string(), c[2].as_f64().unwrap()))
        .collect();
    for t in [8.0, 9.0, 10.0, 11.0] {
        let label = format!("{t} s");
        let at = texts.iter().find(|(s, _)| *s == label);
        assert!(
            at.is_some_and(|(_, x)| (x - x_of(t)).abs() < 5.0),
            "the {label} tick at {at:?}, expected near x = {}: {texts:?}",
            x_of(t)
        );
    }
    for unit in ["board time, s", "position, mm", "velocity, mm/s", "f_b, Hz"] {
        assert!(
            texts.iter().any(|(s, _)| s.starts_with(unit)),
            "no `{unit}` on the trace: {texts:?}"
        );
    }
    assert!(
        calls(1, "fillText").iter().any(|c| c[1] == "mm"),
        "the strip's scale has no unit"
    );
    screenshot(&c, "trace-gap").await;
    // The injected trace ends where board time starts, so the board coming back (its time from
    // 0) continues it and nothing below sees the injected times.
    js(
        &c,
        r#"onMessage({ t: "records", records: [[0, 1000, 0, 0, 0, false, null]], dropped: 0 }); return true"#,
    )
    .await;

    // An edit while the link is down: refused as not sent.
    c.find(fantoccini::Locator::Id("save"))
        .await
        .unwrap()
        .click()
        .await
        .unwrap();
    until(
        &c,
        "the edit refused as not sent",
        "const a = document.getElementById('answer'); return a.className === 'refused' && a.textContent.startsWith('not sent')",
        5,
    )
    .await;

    // Back, now with the finger sliding (1.5 ↔ 61.5 mm at 60 mm/s): the marker follows it.
    // (An open wiper from 5 s to 8 s of the board's time: the panel names the fault.)
    const FAULT_FROM_US: f64 = 5e6;
    const FAULT_TO_US: f64 = 8e6;
    let _vb = VirtualBoard::start_in(
        dir,
        &[
            "--speed",
            "60",
            "--fault",
            "open",
            "--fault-at",
            "5",
            "--fault-for",
            "3",
        ],
    );
    until(
        &c,
        "reconnected",
        "return document.body.dataset.link === 'ok'",
        10,
    )
    .await;
    // The link back: the refusal for the down link is gone.
    until(
        &c,
        "the not-sent line cleared",
        "return !document.getElementById('answer').textContent.startsWith('not sent')",
        5,
    )
    .await;
    // Looked at from 1 s of the board's time (the finger well under way) for 1.2 s of it.
    let record_us = "return Number(document.getElementById('strip').dataset.recordUs || 0)";
    until(
        &c,
        "1 s of the board's time",
        &format!("{record_us} >= 1e6"),
        20,
    )
    .await;
    // The marker as drawn, with the board time of the record it shows: (mm, s).
    let mut seen: Vec<f64> = Vec::new();
    let mut at: Vec<f64> = Vec::new();
    let give_up = Instant::now() + Duration::from_secs(20);
    while at.len() < 2 || at[at.len() - 1] - at[0] < 1.2 {
        assert!(
            Instant::now() < give_up,
            "1.2 s of board time not seen in 20 s: {at:?}"
        );
        let v = js(
            &c,
            "const d = document.getElementById('strip').dataset; return [Number(d.fingerMm), Number(d.fingerUs)]",
        )
        .await;
        seen.push(v[0].as_f64().unwrap());
        at.push(v[1].as_f64().unwrap() / 1e6);
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // Watched before the fault (the finger's position is unknown while it lasts).
    assert!(
        at[at.len() - 1] * 1e6 < FAULT_FROM_US,
        "the finger watched until {} s of board time, into the fault's window",
        at[at.len() - 1]
    );
    let (lo, hi) = seen
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
    assert!(
        lo >= 1.0 && hi <= 62.0 && hi - lo > 20.0,
        "the marker over 1.2 s: {seen:?}"
    );
    // Between two looks, in the board's time, the marker moves as the finger does: at most
    // 60 mm/s, plus 0.5 mm of sensor noise and estimator lag. (Timed by the test's own clock,
    // a look that found an older batch would make the finger seem faster than it is.)
    for i in 1..seen.len() {
        let dt = at[i] - at[i - 1];
        assert!(
            dt >= 0.0 && (seen[i] - seen[i - 1]).abs() <= 60.0 * dt + 0.5,
            "the marker jumped: {seen:?} at board times {at:?} s"
        );
    }
    screenshot(&c, "moving").await;
    // The fault named exactly while the board's time is inside its window (5 ms of margin at
    // its edges: the core sees it a sample late, and sees it go a sample late), looked at until
    // the board's time is past it.
    const MARGIN_US: f64 = 5e3;
    let (mut inside, mut after, mut shot) = (0, 0, false);
    let give_up = Instant::now() + Duration::from_secs(30);
    loop {
        let v = js(
            &c,
            "const d = document.getElementById('strip').dataset; return [Number(d.recordUs), d.fault]",
        )
        .await;
        let (t_us, fault) = (v[0].as_f64().unwrap(), v[1].as_str().unwrap().to_string());
        if fault.is_empty() {
            assert!(
                !(FAULT_FROM_US + MARGIN_US..FAULT_TO_US).contains(&t_us),
                "no fault named at {t_us} µs of board time, inside its window"
            );
        } else {
            assert_eq!(fault, "RailLow");
            assert!(
                (FAULT_FROM_US..=FAULT_TO_US + MARGIN_US).contains(&t_us),
                "the fault named at {t_us} µs of board time, outside its window"
            );
        }
        if (FAULT_FROM_US + MARGIN_US..FAULT_TO_US).contains(&t_us) {
            inside += 1;
            // The screenshot from the window's middle: the position trace broken for 1.5 s.
            if !shot && t_us >= FAULT_FROM_US + 1.5e6 {
                screenshot(&c, "fault").await;
                shot = true;
            }
        } else if t_us > FAULT_TO_US + MARGIN_US {
            after += 1;
            if after >= 5 {
                break;
            }
        }
        assert!(
            Instant::now() < give_up,
            "the board's time reached only {t_us} µs in 30 s"
        );
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    // About 30 looks fall inside the 3 s window; a few are enough to have seen it.
    assert!(inside >= 3, "{inside} looks inside the fault's window");
    c.close().await.unwrap();
    ui.stop();
}
