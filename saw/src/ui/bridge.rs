//! The panel's end of the link: one thread owns the serial port (as `saw` does, with its lock),
//! keeps the telemetry stream running, carries out the page's edits one at a time, and
//! publishes what the board answers. When the link fails it says so (to the pages and on the
//! terminal) and reopens the port every `RETRY` until the board answers again.
//!
//! The port is held only while a page is open: a panel whose tab was closed (a forgotten `saw ui`)
//! lets go of the port after `ALONE`, and does not take it again until a page connects, so `saw`
//! or another tool can have it meanwhile.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use saw_core::gate::DriveMode;
use saw_link::client::Client;
use saw_link::msg::{Record, Record2d, Reply, Request};
use serde_json::{json, Value};
use tokio::sync::broadcast;

use super::{Snapshot, UiOptions};
use crate::{Done, Failure};

/// How often a lost link is tried again.
pub(super) const RETRY: Duration = Duration::from_millis(300);
/// How often records go to the pages: about a screen's frame rate.
const FRAME: Duration = Duration::from_millis(33);
/// How often the counters are read.
const COUNTERS_EVERY: Duration = Duration::from_secs(1);
/// No stream frame for this long while streaming: the board is asked who it is; no answer is a
/// lost link.
const SILENCE: Duration = Duration::from_secs(1);
/// No page open for this long: the port is let go. Long enough for a page's reload (its socket
/// closes and a new one opens) not to drop the link.
pub(super) const ALONE: Duration = Duration::from_secs(2);
/// Why a session ends when no page is open (not a lost link: nothing is shown for it).
const LET_GO: &str = "no page open";
/// The largest scene file the page may send, bytes.
const MAX_SCENE_BYTES: usize = 64 * 1024;

/// An edit from the page.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Move boundary `index` to `mm`.
    Boundary { index: u8, mm: f64 },
    /// Give region `index` the texture of these scene-file keys.
    Set { index: u8, keys: Vec<String> },
    /// Load a scene file's text.
    Push { name: String, text: String },
    /// Save the active scene to flash.
    Save,
    /// Standing or progressive drive.
    Drive(DriveMode),
    /// Counters from zero.
    ResetCounters,
    /// The board's scene as a scene file.
    Export,
    /// Move 2D window `index` whole: its lower-left bounding corner to (`x_mm`, `y_mm`).
    MoveWindow { index: u8, x_mm: f64, y_mm: f64 },
    /// Give rectangle window `index` the corners (x0, y0) – (x1, y1), mm.
    ResizeWindow { index: u8, rect: [f64; 4] },
}

/// Reads one command from the page: `{"id": N, "cmd": …}`. Every value is checked here; the
/// error names the field, the value and the rule.
pub fn parse_command(text: &str) -> Result<(u64, Command), (u64, String)> {
    let v: Value = serde_json::from_str(text).map_err(|e| (0, format!("not a command: {e}")))?;
    let id = v.get("id").and_then(Value::as_u64).unwrap_or(0);
    let fail = |s: String| (id, s);
    let cmd = v
        .get("cmd")
        .and_then(Value::as_str)
        .ok_or_else(|| fail("`cmd` missing".into()))?;
    let index = |name: &str| -> Result<u8, (u64, String)> {
        let x = v
            .get(name)
            .ok_or_else(|| fail(format!("`{name}` missing")))?;
        x.as_u64()
            .and_then(|i| u8::try_from(i).ok())
            .ok_or_else(|| {
                fail(format!(
                    "`{name}` = {x}: must be a whole number from 0 to 255"
                ))
            })
    };
    // Millimetres on the plate: finite, 0 to 1000.
    let plate_mm = |name: &str| -> Result<f64, (u64, String)> {
        let x = v
            .get(name)
            .ok_or_else(|| fail(format!("`{name}` missing")))?;
        x.as_f64()
            .filter(|m| m.is_finite() && (0.0..=1000.0).contains(m))
            .ok_or_else(|| {
                fail(format!(
                    "`{name}` = {x}: must be a number from 0 to 1000 mm"
                ))
            })
    };
    let c = match cmd {
        "move_window" => Command::MoveWindow {
            index: index("index")?,
            x_mm: plate_mm("x_mm")?,
            y_mm: plate_mm("y_mm")?,
        },
        "resize_window" => Command::ResizeWindow {
            index: index("index")?,
            rect: [
                plate_mm("x0_mm")?,
                plate_mm("y0_mm")?,
                plate_mm("x1_mm")?,
                plate_mm("y1_mm")?,
            ],
        },
        "boundary" => {
            let x = v.get("mm").ok_or_else(|| fail("`mm` missing".into()))?;
            let mm = x
                .as_f64()
                .filter(|m| m.is_finite() && (0.0..=1000.0).contains(m))
                .ok_or_else(|| fail(format!("`mm` = {x}: must be a number from 0 to 1000 mm")))?;
            Command::Boundary {
                index: index("index")?,
                mm,
            }
        }
        "set" => {
            let keys: Vec<String> = v
                .get("keys")
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(|k| k.as_str().map(str::to_owned))
                        .collect()
                })
                .unwrap_or_default();
            if keys.is_empty() {
                return Err(fail("`keys` = []: give at least kind=…".into()));
            }
            Command::Set {
                index: index("index")?,
                keys,
            }
        }
        "push" => {
            let name = v
                .get("name")
                .and_then(Value::as_str)
                .unwrap_or("scene.toml");
            let text = v
                .get("text")
                .and_then(Value::as_str)
                .ok_or_else(|| fail("`text` missing".into()))?;
            // TOML 1.0 allows no control character but tab, CR and LF anywhere in a file: other
            // input is refused by name and rule, and none of it is echoed back.
            if text
                .chars()
                .any(|c| c.is_control() && !matches!(c, '\t' | '\n' | '\r'))
            {
                return Err(fail(format!(
                    "{}: not a scene file (a scene file is TOML text: UTF-8 without control characters); nothing sent",
                    printable(name)
                )));
            }
            if text.len() > MAX_SCENE_BYTES {
                return Err(fail(format!(
                    "{name}: {} bytes; a scene file may have at most {MAX_SCENE_BYTES}",
                    text.len()
                )));
            }
            Command::Push {
                name: printable(name),
                text: text.into(),
            }
        }
        "save" => Command::Save,
        "drive" => match v.get("mode").and_then(Value::as_str) {
            Some("standing") => Command::Drive(DriveMode::Standing),
            Some("progressive") => Command::Drive(DriveMode::Progressive),
            other => {
                return Err(fail(format!(
                    "`mode` = {other:?}: must be \"standing\" or \"progressive\""
                )))
            }
        },
        "reset_counters" => Command::ResetCounters,
        "export" => Command::Export,
        other => {
            return Err(fail(format!(
                "`cmd` = \"{other}\": not a command of the panel"
            )))
        }
    };
    Ok((id, c))
}

/// A file name as messages show it: at most 200 characters, control characters dropped.
fn printable(name: &str) -> String {
    name.chars().filter(|c| !c.is_control()).take(200).collect()
}

struct Out {
    tx: broadcast::Sender<String>,
    snapshot: Arc<Mutex<Snapshot>>,
}

impl Out {
    fn send(&self, v: Value) {
        let _ = self.tx.send(v.to_string());
    }
    fn keep(&self, which: fn(&mut Snapshot) -> &mut Option<String>, v: Value) {
        let s = v.to_string();
        *which(&mut self.snapshot.lock().unwrap_or_else(|e| e.into_inner())) = Some(s.clone());
        let _ = self.tx.send(s);
    }
    fn lost(&self, why: &str) {
        self.keep(
            |s| &mut s.link,
            json!({"t": "link", "ok": false, "why": why}),
        );
    }
}

/// Starts the bridge thread. `pages` counts the open pages; `said` is what the terminal was
/// already told about the port (not said again).
pub(super) fn spawn(
    opts: UiOptions,
    tx: broadcast::Sender<String>,
    snapshot: Arc<Mutex<Snapshot>>,
    commands: Receiver<(u64, Command)>,
    stop: Arc<AtomicBool>,
    pages: Arc<AtomicUsize>,
    said: Option<String>,
) -> Option<std::thread::JoinHandle<()>> {
    let out = Out { tx, snapshot };
    std::thread::Builder::new()
        .name("saw-ui-link".into())
        .spawn(move || {
            let mut last_why = said.unwrap_or_default();
            let mut published = String::new();
            while !stop.load(Ordering::Relaxed) {
                if pages.load(Ordering::Relaxed) == 0 {
                    // Nobody to show the board to: the port is left to other programs.
                    std::thread::sleep(RETRY);
                    continue;
                }
                let why = match crate::port::open(&opts.port) {
                    Ok(port) => {
                        let mut client = Client::new(port, opts.timeout);
                        linked(&mut client, &opts, &out, &commands, &stop, &pages)
                    }
                    Err(e) => e,
                };
                if why == LET_GO {
                    eprintln!(
                        "saw ui: no page open for {} s: port {} let go (taken again when a page connects)",
                        ALONE.as_secs(),
                        opts.port.display()
                    );
                    // A page that connects next is told the link's state afresh.
                    out.snapshot.lock().unwrap_or_else(|e| e.into_inner()).link = None;
                    (last_why, published) = (String::new(), String::new());
                    continue;
                }
                if why != published {
                    out.lost(&why);
                    published = why.clone();
                }
                if why != last_why && why != "the panel stopped" {
                    eprintln!(
                        "saw ui: {why}; trying again every {} s while a page is open",
                        RETRY.as_secs_f64()
                    );
                }
                last_why = why;
                // Edits made while the link is down are refused, not queued for later.
                while let Ok((id, _)) = commands.try_recv() {
                    out.send(json!({"t": "answer", "id": id, "ok": false, "text": format!("not sent: the link is lost ({last_why})")}));
                }
                std::thread::sleep(RETRY);
            }
        })
        .ok()
}

fn record_json(r: &Record) -> Value {
    json!([
        r.time_us,
        r.position_um,
        r.velocity_um_s,
        r.region,
        r.burst_millihz as f64 / 1000.0,
        r.bursting,
        r.fault.map(|f| format!("{f:?}")),
        crate::scene_hex(r.scene_id),
        r.change
    ])
}

/// A 2D record as the page reads it (by name).
fn record_2d_json(r: &Record2d) -> Value {
    use saw_core::plane::Place;
    json!({
        "time_us": r.time_us,
        "x_um": r.position.map(|p| p.x_um),
        "y_um": r.position.map(|p| p.y_um),
        "vx_um_s": r.velocity_um_s.map(|v| v.0),
        "vy_um_s": r.velocity_um_s.map(|v| v.1),
        // A window's index, -1 for the background, null while nothing renders.
        "window": r.place.map(|p| match p { Place::Window(i) => i as i32, Place::Background => -1 }),
        "edge": r.edge,
        "f_b_hz": r.burst_millihz as f64 / 1000.0,
        "bursting": r.bursting,
        "lifted": r.lifted,
        "fault": r.fault.map(crate::record::fault_2d_name),
        "scene_id": crate::scene_hex(r.scene_id),
        "change": r.change,
    })
}

/// One session on an open port; returns why it ended.
fn linked<P: Read + Write>(
    client: &mut Client<P>,
    opts: &UiOptions,
    out: &Out,
    commands: &Receiver<(u64, Command)>,
    stop: &AtomicBool,
    pages: &AtomicUsize,
) -> String {
    let hello = match client.hello() {
        Ok(h) => h,
        Err(e) => return e.to_string(),
    };
    eprintln!(
        "saw ui: linked to {} ({}) on {}",
        hello.board,
        hello.firmware,
        opts.port.display()
    );
    out.keep(
        |s| &mut s.link,
        json!({"t": "link", "ok": true, "hello": hello}),
    );
    // A board with the touch overlay streams 2D records (issue #36).
    let plane = match crate::board_is_2d(client) {
        Ok(p) => p,
        Err(f) => return f.message,
    };
    if let Err(e) = publish_scene(client, out) {
        return e;
    }
    // Only records sampled from here on: none left in transit from an earlier stream.
    let sample_rate_hz = match client.start_stream(opts.every) {
        Ok(s) => s.sample_rate_hz,
        Err(e) => return e.to_string(),
    };
    out.keep(
        |s| &mut s.stream,
        json!({"t": "stream", "records_per_s": sample_rate_hz as f64 / opts.every as f64}),
    );
    let mut records: Vec<Value> = Vec::new();
    let mut dropped = 0u32;
    let (mut flushed, mut counted, mut heard) = (Instant::now(), Instant::now(), Instant::now());
    let mut alone: Option<Instant> = None;
    loop {
        if stop.load(Ordering::Relaxed) {
            let _ = client.request(&Request::Stream { every_samples: 0 });
            return "the panel stopped".into();
        }
        if pages.load(Ordering::Relaxed) > 0 {
            alone = None;
        } else if alone.get_or_insert_with(Instant::now).elapsed() >= ALONE {
            let _ = client.request(&Request::Stream { every_samples: 0 });
            return LET_GO.into();
        }
        while let Ok((id, cmd)) = commands.try_recv() {
            let result = execute(client, &cmd, opts.timeout);
            let link_failed = matches!(&result, Err(f) if f.code == 3);
            match result {
                Ok(done) => {
                    out.send(json!({"t": "answer", "id": id, "ok": true, "text": done.text, "file": done.json.get("scene_file")}))
                }
                Err(f) => {
                    out.send(json!({"t": "answer", "id": id, "ok": false, "text": f.message}))
                }
            }
            if link_failed {
                return "the board stopped answering".into();
            }
            // The strip redraws from the board's own account of its scene.
            if let Err(e) = publish_scene(client, out) {
                return e;
            }
        }
        let deadline = Instant::now() + Duration::from_millis(5);
        let next = if plane {
            client.next_stream_2d(deadline).map(|f| {
                f.map(|(_, s)| (s.dropped, s.records.iter().map(record_2d_json).collect()))
            })
        } else {
            client
                .next_stream(deadline)
                .map(|f| f.map(|(_, s)| (s.dropped, s.records.iter().map(record_json).collect())))
        };
        match next {
            Ok(Some((d, rs))) => {
                heard = Instant::now();
                dropped = d;
                records.extend::<Vec<Value>>(rs);
            }
            Ok(None) => {}
            Err(e) => return e.to_string(),
        }
        if flushed.elapsed() >= FRAME {
            flushed = Instant::now();
            if !records.is_empty() {
                out.send(json!({"t": "records", "records": std::mem::take(&mut records), "dropped": dropped}));
            }
        }
        if counted.elapsed() >= COUNTERS_EVERY {
            counted = Instant::now();
            match client.request(&Request::Counters { reset: false }) {
                Ok(Reply::Counters(c)) => {
                    out.keep(|s| &mut s.counters, json!({"t": "counters", "counters": c}))
                }
                Ok(Reply::Counters2d(c)) => out.keep(
                    |s| &mut s.counters,
                    json!({"t": "counters", "counters": c, "plane": true}),
                ),
                Ok(other) => {
                    return format!("the board answered the counters request with {other:?}")
                }
                Err(e) => return e.to_string(),
            }
        }
        if heard.elapsed() >= SILENCE {
            heard = Instant::now();
            if let Err(e) = client.hello() {
                return e.to_string();
            }
        }
    }
}

/// Runs one command from the page; `timeout` is the panel's wait per answer (a save waits at
/// least `SAVE_TIMEOUT`).
fn execute<P: Read + Write>(
    client: &mut Client<P>,
    cmd: &Command,
    timeout: Duration,
) -> Result<Done, Failure> {
    match cmd {
        Command::Boundary { index, mm } => crate::boundary(client, *index, *mm),
        Command::MoveWindow { index, x_mm, y_mm } => {
            crate::window(client, *index, Some((*x_mm, *y_mm)), None)
        }
        Command::ResizeWindow { index, rect } => crate::window(client, *index, None, Some(*rect)),
        Command::Set { index, keys } => crate::set(client, *index, keys),
        Command::Push { name, text } => crate::push_text(client, name, text),
        Command::Save => crate::save(client, timeout),
        Command::Drive(mode) => {
            let reply = client.request(&Request::SetDrive(*mode))?;
            crate::applied(reply, format!("drive {mode:?}"))
        }
        Command::Export => match client.request(&Request::GetScene)? {
            Reply::Scene {
                scene_id, config, ..
            } => {
                let title = format!(
                    "Scene {scene_id:#010x}, saved from the panel (saw ui): the board's own account of its scene."
                );
                Ok(Done {
                    text: format!("scene {scene_id:#010x} as a scene file"),
                    json: json!({"scene_file": saw_core::scene_file::to_scene_file(&config, &title)}),
                })
            }
            Reply::Scene2d {
                scene_id, scene, ..
            } => {
                let title = format!(
                    "Scene {scene_id:#010x}, saved from the panel (saw ui): the board's own account of its 2D scene."
                );
                Ok(Done {
                    text: format!("scene {scene_id:#010x} as a scene file"),
                    json: json!({"scene_file": saw_core::scene_file::to_scene_file_2d(&scene.config, scene.plate_um, &title)}),
                })
            }
            other => Err(crate::unexpected(other)),
        },
        Command::ResetCounters => match client.request(&Request::Counters { reset: true })? {
            Reply::Counters(_) | Reply::Counters2d(_) => Ok(Done {
                text: "counters from zero".into(),
                json: Value::Null,
            }),
            other => Err(crate::unexpected(other)),
        },
    }
}

/// Reads the board's scene and publishes it with each region's extent and label.
fn publish_scene<P: Read + Write>(client: &mut Client<P>, out: &Out) -> Result<(), String> {
    match client.request(&Request::GetScene) {
        Ok(Reply::Scene {
            scene_id,
            source,
            config,
        }) => {
            let length_mm = config.calibration.length_um as f64 / 1000.0;
            let regions: Vec<Value> = crate::regions_mm(&config)
                .map(|(from, to, t)| {
                    json!({"from_mm": from, "to_mm": to, "label": crate::texture_text(t)})
                })
                .collect();
            out.keep(
                |s| &mut s.scene,
                json!({
                    "t": "scene",
                    "scene_id": format!("{scene_id:#010x}"),
                    "source": crate::source_name(source),
                    "length_mm": length_mm,
                    "drive": format!("{:?}", config.scene.drive),
                    "regions": regions,
                    "lines": config.scene.lines.positions_um.iter().map(|&u| u as f64 / 1000.0).collect::<Vec<_>>(),
                }),
            );
            Ok(())
        }
        Ok(Reply::Scene2d {
            scene_id,
            source,
            scene,
        }) => {
            let sc = &scene.config.scene;
            let mm = |u: i32| u as f64 / 1000.0;
            let windows: Vec<Value> = sc
                .windows
                .iter()
                .enumerate()
                .map(|(i, w)| {
                    let v = &w.outline.vertices;
                    // An axis-aligned rectangle resizes by its corners; any other outline moves.
                    let rect = v.len() == 4
                        && (0..4).all(|k| {
                            let (a, b) = (v[k], v[(k + 1) % 4]);
                            (a.x_um == b.x_um) != (a.y_um == b.y_um)
                        });
                    json!({
                        "index": i,
                        "points": v.iter().map(|p| [mm(p.x_um), mm(p.y_um)]).collect::<Vec<_>>(),
                        "label": crate::plane_texture_text(&w.texture),
                        "rect": rect,
                        "edge": w.edge,
                    })
                })
                .collect();
            out.keep(
                |s| &mut s.scene,
                json!({
                    "t": "scene2d",
                    "scene_id": format!("{scene_id:#010x}"),
                    "source": crate::source_name(source),
                    "plate_mm": [scene.plate_um.0 as f64 / 1000.0, scene.plate_um.1 as f64 / 1000.0],
                    "band_mm": sc.band_um as f64 / 1000.0,
                    "drive": format!("{:?}", sc.drive),
                    "background": crate::plane_texture_text(&sc.background),
                    "windows": windows,
                    "edges": sc.free_edges.iter().map(|e| [mm(e.a.x_um), mm(e.a.y_um), mm(e.b.x_um), mm(e.b.y_um)]).collect::<Vec<_>>(),
                }),
            );
            Ok(())
        }
        Ok(other) => Err(format!(
            "the board answered the scene request with {other:?}"
        )),
        Err(e) => Err(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_are_checked_at_the_door() {
        assert_eq!(
            parse_command(r#"{"id":3,"cmd":"boundary","index":1,"mm":30.5}"#),
            Ok((3, Command::Boundary { index: 1, mm: 30.5 }))
        );
        for (text, says) in [
            (
                r#"{"id":4,"cmd":"boundary","index":1,"mm":-1}"#,
                "`mm` = -1",
            ),
            (
                r#"{"id":4,"cmd":"boundary","index":1,"mm":1e9}"#,
                "`mm` = 1000000000",
            ),
            (
                r#"{"id":4,"cmd":"boundary","index":300,"mm":3}"#,
                "`index` = 300",
            ),
            (r#"{"id":4,"cmd":"boundary","mm":3}"#, "`index` missing"),
            (r#"{"id":4,"cmd":"set","index":0,"keys":[]}"#, "`keys` = []"),
            (
                r#"{"id":4,"cmd":"drive","mode":"sideways"}"#,
                "`mode` = Some(\"sideways\")",
            ),
            (r#"{"id":4,"cmd":"launch"}"#, "`cmd` = \"launch\""),
            (
                r#"{"id":4,"cmd":"move_window","index":0,"x_mm":-0.5,"y_mm":3}"#,
                "`x_mm` = -0.5: must be a number from 0 to 1000 mm",
            ),
            (
                r#"{"id":4,"cmd":"move_window","index":0,"x_mm":1,"y_mm":"NaN"}"#,
                "`y_mm` = \"NaN\"",
            ),
            (
                r#"{"id":4,"cmd":"resize_window","index":0,"x0_mm":1,"y0_mm":1,"x1_mm":2}"#,
                "`y1_mm` missing",
            ),
        ] {
            let (id, why) = parse_command(text).unwrap_err();
            assert_eq!(id, 4, "{text}");
            assert!(why.contains(says), "{text}: {why}");
        }
        assert_eq!(
            parse_command(r#"{"id":7,"cmd":"move_window","index":2,"x_mm":36,"y_mm":2.5}"#),
            Ok((
                7,
                Command::MoveWindow {
                    index: 2,
                    x_mm: 36.0,
                    y_mm: 2.5
                }
            ))
        );
        assert!(parse_command("not json").is_err());
        let big = format!(
            r#"{{"id":1,"cmd":"push","name":"x.toml","text":"{}"}}"#,
            "a".repeat(MAX_SCENE_BYTES + 1)
        );
        assert!(parse_command(&big).unwrap_err().1.contains("at most 65536"));
    }

    #[test]
    fn a_file_that_is_not_text_is_refused_without_its_bytes() {
        // Bytes a binary file decodes to (NUL, ESC, DEL, a replacement character): refused by
        // name and rule, none of them in the sentence.
        let cmd = json!({"id": 5, "cmd": "push", "name": "photo\u{7}.png", "text": "PNG\u{0}\u{1b}[2J\u{7f}\u{fffd}kind = \"grating\""});
        let (id, why) = parse_command(&cmd.to_string()).unwrap_err();
        assert_eq!(id, 5);
        assert!(
            why.starts_with("photo.png: not a scene file") && why.contains("TOML text"),
            "{why}"
        );
        assert!(!why.contains("PNG") && !why.contains('\u{fffd}'), "{why}");
        assert!(!why.chars().any(char::is_control), "{why:?}");
        // Tabs and both line ends are TOML's own.
        let ok = json!({"id": 6, "cmd": "push", "name": "a.toml", "text": "[scene]\r\n\tdrive = \"standing\"\n"});
        assert!(parse_command(&ok.to_string()).is_ok());
    }
}
