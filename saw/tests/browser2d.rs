//! The panel's 2D map in a real browser (issue #36), as `browser.rs` tests the fig. 11 strip:
//! headless Chromium over WebDriver against `host-sim serve --scene scenes/2d-fig12.toml`. The
//! finger is drawn where the virtual finger rests; dragging a window shows where it goes while
//! the button is held and moves the board's window exactly there; dragging a rectangle's corner
//! resizes it; a drag off the plate is refused with the board's sentence and changes nothing;
//! `saw get` reads the moved and resized windows back once the panel has let go of the port.
//! Screenshots go to target/ui-screens/ (and SAW_UI_SCREENSHOTS, as browser.rs).

mod common;

use std::process::Command;
use std::time::Duration;

use common::browser::{browser, js, until};
use common::{panel, VirtualBoard};
use fantoccini::actions::{InputSource, MouseActions, PointerAction, MOUSE_BUTTON_LEFT};
use fantoccini::Client;
use serde_json::{json, Value};

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

/// The page's pixel (CSS, in the window) of plate point (x, y) mm on the map.
async fn at(c: &Client, x: f64, y: f64) -> (i64, i64) {
    let v = js(
        c,
        &format!(
            "const m = document.getElementById('map'), r = m.getBoundingClientRect(); \
             const k = r.width / m.width, s = mapScale(); \
             return [r.left + (30 + {x} * s) * k, r.top + (m.height - 30 - {y} * s) * k];"
        ),
    )
    .await;
    (
        v[0].as_f64().unwrap().round() as i64,
        v[1].as_f64().unwrap().round() as i64,
    )
}

/// Presses at `from`, moves to `to` and (with `release`) lets go.
async fn drag(c: &Client, from: (i64, i64), to: (i64, i64), release: bool) {
    let mut a = MouseActions::new("mouse".into())
        .then(PointerAction::MoveTo {
            duration: None,
            x: from.0,
            y: from.1,
        })
        .then(PointerAction::Down {
            button: MOUSE_BUTTON_LEFT,
        })
        .then(PointerAction::MoveTo {
            duration: Some(Duration::from_millis(200)),
            x: to.0,
            y: to.1,
        });
    if release {
        a = a.then(PointerAction::Up {
            button: MOUSE_BUTTON_LEFT,
        });
    }
    c.perform_actions(a).await.unwrap();
}

async fn release(c: &Client) {
    let a = MouseActions::new("mouse".into()).then(PointerAction::Up {
        button: MOUSE_BUTTON_LEFT,
    });
    c.perform_actions(a).await.unwrap();
}

/// The numbers in the drag label: `window 1 to (40.12, 7.01) mm` → [1, 40.12, 7.01].
fn numbers(label: &str) -> Vec<f64> {
    label
        .split(|ch: char| !(ch.is_ascii_digit() || ch == '.'))
        .filter(|w| !w.is_empty())
        .map(|w| w.trim_end_matches('.').parse().unwrap())
        .collect()
}

/// Window `i`'s bounding box as the page has it from the board: [x0, y0, x1, y1] mm.
async fn bounds(c: &Client, i: usize) -> Vec<f64> {
    let v = js(
        c,
        &format!(
            "const p = window.sawState.plane.windows[{i}].points; \
             const xs = p.map(q => q[0]), ys = p.map(q => q[1]); \
             return [Math.min(...xs), Math.min(...ys), Math.max(...xs), Math.max(...ys)];"
        ),
    )
    .await;
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

async fn new_scene(c: &Client, before: &Value) {
    until(
        c,
        "the board's new scene",
        &format!("return document.body.dataset.sceneId !== {before}"),
        5,
    )
    .await;
}

#[tokio::test(flavor = "current_thread")]
async fn the_2d_map_in_a_real_browser() {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/2d-fig12.toml");
    // The finger rests at (17, 27) mm: inside window 0 (5,5 – 30,49).
    let vb = VirtualBoard::start(&["--scene", scene, "--rest-at-xy", "17,27"]);
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
        "the map shown and the finger drawn",
        "return document.body.dataset.mode === '2d' && document.getElementById('map').dataset.fingerXMm !== undefined",
        10,
    )
    .await;
    // The strip and the region editor are the 1D panel's: hidden on a 2D board.
    assert_eq!(
        js(
            &c,
            "return document.getElementById('strip-box').offsetParent === null"
        )
        .await,
        json!(true)
    );
    tokio::time::sleep(Duration::from_millis(500)).await;
    let f = js(&c, "const d = document.getElementById('map').dataset; return [Number(d.fingerXMm), Number(d.fingerYMm), d.window]").await;
    let (fx, fy) = (f[0].as_f64().unwrap(), f[1].as_f64().unwrap());
    assert!(
        (fx - 17.0).abs() < 0.3 && (fy - 27.0).abs() < 0.3,
        "the marker at ({fx}, {fy}) mm, the finger at (17, 27)"
    );
    assert_eq!(f[2], json!("0"), "the board says the finger is in window 0");
    screenshot(&c, "map").await;

    // Drag window 1 (35,5 – 60,49) by its middle 5 mm right and 2 mm up, the button held.
    let before = js(&c, "return document.body.dataset.sceneId").await;
    let from = at(&c, 47.5, 27.0).await;
    let to = at(&c, 52.5, 29.0).await;
    drag(&c, from, to, false).await;
    until(
        &c,
        "where the window goes, shown",
        "const l = document.getElementById('map-mm'); return !l.hidden && l.textContent.startsWith('window 1 to')",
        5,
    )
    .await;
    let label = js(&c, "return document.getElementById('map-mm').textContent").await;
    let shown = numbers(label.as_str().unwrap());
    // A CSS pixel is about 0.11 mm on this map; the pointer lands on a whole pixel.
    assert!(
        (shown[1] - 40.0).abs() < 0.25 && (shown[2] - 7.0).abs() < 0.25,
        "shown while dragging: {label}"
    );
    screenshot(&c, "map-dragging").await;
    release(&c).await;
    new_scene(&c, &before).await;
    let b = bounds(&c, 1).await;
    // The value shown is the value sent: the board has the window there (to its 1 µm), the
    // same size.
    assert!(
        (b[0] - shown[1]).abs() < 0.0011 && (b[1] - shown[2]).abs() < 0.0011,
        "window 1 at {b:?} after the drag, ({}, {}) shown",
        shown[1],
        shown[2]
    );
    assert!((b[2] - b[0] - 25.0).abs() < 0.0011 && (b[3] - b[1] - 44.0).abs() < 0.0011);
    assert_eq!(
        js(&c, "return document.getElementById('map-mm').hidden").await,
        json!(true)
    );
    let moved = (shown[1], shown[2]);

    // Resize window 0 by its upper-right corner (30, 49) to (25, 40).
    let before = js(&c, "return document.body.dataset.sceneId").await;
    let from = at(&c, 30.0, 49.0).await;
    let to = at(&c, 25.0, 40.0).await;
    drag(&c, from, to, true).await;
    new_scene(&c, &before).await;
    let b = bounds(&c, 0).await;
    assert_eq!((b[0], b[1]), (5.0, 5.0), "the opposite corner stays");
    assert!(
        (b[2] - 25.0).abs() < 0.25 && (b[3] - 40.0).abs() < 0.25,
        "window 0 resized to {b:?}"
    );
    let resized = b.clone();
    screenshot(&c, "map-resized").await;

    // Window 2 (65 – 90 mm) dragged 10 mm right: off the 95 mm plate, refused by the board with
    // its sentence, nothing changed.
    let before = js(&c, "return document.body.dataset.sceneId").await;
    let from = at(&c, 77.0, 27.0).await;
    let to = at(&c, 87.0, 27.0).await;
    drag(&c, from, to, true).await;
    until(
        &c,
        "the refusal shown",
        "return document.body.dataset.lastAnswer === 'refused'",
        5,
    )
    .await;
    let text = js(&c, "return document.getElementById('answer').textContent").await;
    let text = text.as_str().unwrap();
    assert!(
        text.starts_with("refused, nothing changed: window 2: the point (")
            && text.ends_with("is off the plate (0 to 95 mm, 0 to 54 mm)"),
        "{text}"
    );
    assert_eq!(js(&c, "return document.body.dataset.sceneId").await, before);
    let b = bounds(&c, 2).await;
    assert_eq!(b, vec![65.0, 5.0, 90.0, 49.0]);
    screenshot(&c, "map-refused").await;

    // Read back through `saw` once the panel has let go of the port.
    ui.stop();
    let out = Command::new(env!("CARGO_BIN_EXE_saw"))
        .arg("--port")
        .arg(&vb.port)
        .args(["--json", "get"])
        .output()
        .unwrap();
    let g: Value = serde_json::from_slice(&out.stdout).unwrap();
    let windows = g["result"]["scene"]["window"].as_array().unwrap();
    let pts = |i: usize| -> Vec<(f64, f64)> {
        windows[i]["polygon_mm"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| (p[0].as_f64().unwrap(), p[1].as_f64().unwrap()))
            .collect()
    };
    let min = |v: &[(f64, f64)]| {
        v.iter()
            .fold((f64::MAX, f64::MAX), |(a, b), &(x, y)| (a.min(x), b.min(y)))
    };
    let m1 = min(&pts(1));
    assert!(
        (m1.0 - moved.0).abs() < 0.0011 && (m1.1 - moved.1).abs() < 0.0011,
        "{m1:?}"
    );
    let p0 = pts(0);
    let max0 = p0
        .iter()
        .fold((f64::MIN, f64::MIN), |(a, b), &(x, y)| (a.max(x), b.max(y)));
    assert_eq!(max0, (resized[2], resized[3]));
}
