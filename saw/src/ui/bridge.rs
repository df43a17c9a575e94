//! The panel's end of the link: one thread owns the serial port (as `saw` does, with its lock),
//! keeps the telemetry stream running, carries out the page's edits one at a time, and
//! publishes what the board answers. When the link fails it says so and reopens the port every
//! `RETRY` until the board answers again.

use std::io::{Read, Write};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Receiver;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use saw_core::gate::DriveMode;
use saw_link::client::Client;
use saw_link::msg::{Record, Reply, Request};
use serde_json::{json, Value};
use tokio::sync::broadcast;

use super::{Snapshot, UiOptions};
use crate::{Done, Failure};

/// How often a lost link is tried again.
const RETRY: Duration = Duration::from_millis(300);
/// How often records go to the pages: about a screen's frame rate.
const FRAME: Duration = Duration::from_millis(33);
/// How often the counters are read.
const COUNTERS_EVERY: Duration = Duration::from_secs(1);
/// No stream frame for this long while streaming: the board is asked who it is; no answer is a
/// lost link.
const SILENCE: Duration = Duration::from_secs(1);
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
    let c = match cmd {
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
            if text.len() > MAX_SCENE_BYTES {
                return Err(fail(format!(
                    "{name}: {} bytes; a scene file may have at most {MAX_SCENE_BYTES}",
                    text.len()
                )));
            }
            Command::Push {
                name: name.chars().take(200).collect(),
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

/// Starts the bridge thread.
pub(super) fn spawn(
    opts: UiOptions,
    tx: broadcast::Sender<String>,
    snapshot: Arc<Mutex<Snapshot>>,
    commands: Receiver<(u64, Command)>,
    stop: Arc<AtomicBool>,
) -> Option<std::thread::JoinHandle<()>> {
    let out = Out { tx, snapshot };
    std::thread::Builder::new()
        .name("saw-ui-link".into())
        .spawn(move || {
            let mut last_why = String::new();
            while !stop.load(Ordering::Relaxed) {
                let why = match crate::port::open(&opts.port) {
                    Ok(port) => {
                        let mut client = Client::new(port, opts.timeout);
                        linked(&mut client, &opts, &out, &commands, &stop)
                    }
                    Err(e) => e,
                };
                if why != last_why {
                    out.lost(&why);
                    last_why = why;
                }
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
        r.fault.map(|f| format!("{f:?}"))
    ])
}

/// One session on an open port; returns why it ended.
fn linked<P: Read + Write>(
    client: &mut Client<P>,
    opts: &UiOptions,
    out: &Out,
    commands: &Receiver<(u64, Command)>,
    stop: &AtomicBool,
) -> String {
    let hello = match client.hello() {
        Ok(h) => h,
        Err(e) => return e.to_string(),
    };
    out.keep(
        |s| &mut s.link,
        json!({"t": "link", "ok": true, "hello": hello}),
    );
    if let Err(e) = publish_scene(client, out) {
        return e;
    }
    let streaming = client.request(&Request::Stream {
        every_samples: opts.every,
    });
    let sample_rate_hz = match streaming {
        Ok(Reply::Streaming { sample_rate_hz, .. }) => sample_rate_hz,
        Ok(other) => return format!("the board answered the stream request with {other:?}"),
        Err(e) => return e.to_string(),
    };
    out.keep(
        |s| &mut s.stream,
        json!({"t": "stream", "records_per_s": sample_rate_hz as f64 / opts.every as f64}),
    );
    let mut records: Vec<Value> = Vec::new();
    let mut dropped = 0u32;
    let (mut flushed, mut counted, mut heard) = (Instant::now(), Instant::now(), Instant::now());
    loop {
        if stop.load(Ordering::Relaxed) {
            let _ = client.request(&Request::Stream { every_samples: 0 });
            return "the panel stopped".into();
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
        match client.next_stream(Instant::now() + Duration::from_millis(5)) {
            Ok(Some((_, s))) => {
                heard = Instant::now();
                dropped = s.dropped;
                records.extend(s.records.iter().map(record_json));
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
            other => Err(crate::unexpected(other)),
        },
        Command::ResetCounters => match client.request(&Request::Counters { reset: true })? {
            Reply::Counters(_) => Ok(Done {
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
        ] {
            let (id, why) = parse_command(text).unwrap_err();
            assert_eq!(id, 4, "{text}");
            assert!(why.contains(says), "{text}: {why}");
        }
        assert!(parse_command("not json").is_err());
        let big = format!(
            r#"{{"id":1,"cmd":"push","name":"x.toml","text":"{}"}}"#,
            "a".repeat(MAX_SCENE_BYTES + 1)
        );
        assert!(parse_command(&big).unwrap_err().1.contains("at most 65536"));
    }
}
