//! `saw session`: one port, one stream, many changes. Commands come from stdin a line at a
//! time and run between stream frames; the records go to one CSV file, each carrying the scene
//! in force and the change count, so a trial sequence is one log that splits at the changes.

use std::io::{BufRead, Write};
use std::path::Path;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use clap::Parser;
use saw_link::client::Client;
use serde_json::json;

use crate::{execute, Command, Done, Failure, StreamRun};

/// One line of a session, parsed as the command line's commands are.
#[derive(Parser, Debug)]
#[command(name = "", no_binary_name = true, disable_help_flag = true)]
struct Line {
    #[command(subcommand)]
    command: Command,
}

/// What a line asks.
#[derive(Debug)]
enum Step {
    /// A request to the board.
    Run(Command),
    /// Hold the commands after this one for this long, s (the stream goes on).
    Wait(f64),
    /// A blank line or a comment.
    Nothing,
}

/// Longest `wait`, s.
const WAIT_MAX_S: f64 = 86_400.0;

fn parse(line: &str) -> Result<Step, String> {
    let line = line.trim();
    if line.is_empty() || line.starts_with('#') {
        return Ok(Step::Nothing);
    }
    let words = shlex::split(line).ok_or_else(|| format!("`{line}`: an unclosed quote"))?;
    if words[0] == "wait" {
        let [_, s] = words.as_slice() else {
            return Err("wait takes one value, seconds (0 to 86400): `wait 1.5`".into());
        };
        let v: f64 = s
            .parse()
            .map_err(|_| format!("wait {s}: not a number; must be from 0 to {WAIT_MAX_S} s"))?;
        if !v.is_finite() || !(0.0..=WAIT_MAX_S).contains(&v) {
            return Err(format!(
                "wait {s}: must be a finite number from 0 to {WAIT_MAX_S} s"
            ));
        }
        return Ok(Step::Wait(v));
    }
    let parsed =
        Line::try_parse_from(&words).map_err(|e| crate::one_line(&e.render().to_string()))?;
    match parsed.command {
        Command::Stream { .. }
        | Command::Session { .. }
        | Command::Ui { .. }
        | Command::Experiment { .. }
        | Command::Bench { .. }
        | Command::Ping { .. } => Err(format!(
            "`{}` does not run inside a session (it streams or holds the port itself); a session takes hello, push, get, boundary, set, window, drive, counters, save and wait",
            words[0]
        )),
        c => Ok(Step::Run(c)),
    }
}

/// Runs the session: streams to `csv` while stdin's commands run, until stdin ends (and its
/// waits are over) or `seconds` pass. Each command's answer is one line on stdout.
pub fn run<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    csv: &Path,
    seconds: Option<f64>,
    every: u16,
    json_out: bool,
    timeout: Duration,
) -> Result<Done, Failure> {
    let (tx, rx) = mpsc::channel::<String>();
    // stdin blocks; a thread reads it and the stream never waits for a line.
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let started = Instant::now();
    let end = seconds.map(|s| started + Duration::from_secs_f64(s));
    let mut stream = StreamRun::start(client, csv, every)?;
    let mut held_until = started;
    let mut stdin_open = true;
    let mut queued: std::collections::VecDeque<String> = Default::default();
    let (mut commands, mut failed) = (0u64, 0u64);
    loop {
        let now = Instant::now();
        if end.is_some_and(|e| now >= e) {
            break;
        }
        // Without --seconds the session lasts as long as its commands (stdin's end, then its
        // last wait); with it, exactly that long, whatever stdin does.
        if end.is_none() && !stdin_open && queued.is_empty() && now >= held_until {
            break;
        }
        // A few ms of stream between looks at stdin.
        let look =
            (now + Duration::from_millis(5)).min(end.unwrap_or(now + Duration::from_millis(5)));
        stream.rec.drain_until(client, look)?;
        loop {
            match rx.try_recv() {
                Ok(line) => queued.push_back(line),
                Err(mpsc::TryRecvError::Empty) => break,
                Err(mpsc::TryRecvError::Disconnected) => {
                    stdin_open = false;
                    break;
                }
            }
        }
        while Instant::now() >= held_until {
            let Some(line) = queued.pop_front() else {
                break;
            };
            let answer = match parse(&line) {
                Ok(Step::Nothing) => continue,
                Ok(Step::Wait(s)) => {
                    held_until = Instant::now() + Duration::from_secs_f64(s);
                    Ok(Done {
                        text: format!("waiting {s} s"),
                        json: json!({ "waiting_s": s }),
                    })
                }
                Ok(Step::Run(c)) => execute(client, &c, timeout, None),
                Err(message) => Err(Failure::input(message)),
            };
            commands += 1;
            let out = match answer {
                Ok(done) if json_out => {
                    json!({ "ok": true, "command": line, "result": done.json }).to_string()
                }
                Ok(done) => done.text,
                Err(f) => {
                    failed += 1;
                    // A link that stopped answering ends the session; a refusal does not.
                    if f.code == 3 {
                        return Err(f);
                    }
                    if json_out {
                        json!({ "ok": false, "command": line, "kind": f.kind, "error": f.message })
                            .to_string()
                    } else {
                        format!("error: {}", f.message)
                    }
                }
            };
            let mut so = std::io::stdout().lock();
            let _ = writeln!(so, "{out}");
            let _ = so.flush();
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let mut done = stream.finish(client, format!("in {seconds:.1} s"))?;
    done.text = format!(
        "{commands} command{} ({failed} failed); {}",
        if commands == 1 { "" } else { "s" },
        done.text
    );
    done.json["commands"] = json!(commands);
    done.json["commands_failed"] = json!(failed);
    Ok(done)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_parse_as_the_command_line_parses_commands() {
        assert!(matches!(parse("  "), Ok(Step::Nothing)));
        assert!(matches!(parse("# trial 3"), Ok(Step::Nothing)));
        assert!(matches!(parse("wait 1.5"), Ok(Step::Wait(s)) if s == 1.5));
        assert!(matches!(
            parse("set 0 f_b_hz=80"),
            Ok(Step::Run(Command::Set { index: 0, .. }))
        ));
        assert!(matches!(
            parse("push 'scenes/a b.toml'"),
            Ok(Step::Run(Command::Push { file })) if file.to_str() == Some("scenes/a b.toml")
        ));
        for (line, says) in [
            (
                "wait -1",
                "wait -1: must be a finite number from 0 to 86400 s",
            ),
            ("wait nan", "wait nan: must be a finite number"),
            ("wait", "wait takes one value"),
            (
                "stream --csv x --seconds 1",
                "`stream` does not run inside a session",
            ),
            ("boundary 0 -3", "must be a finite number from 0 to 1000 mm"),
            ("fly", "unrecognized subcommand 'fly'"),
        ] {
            let e = parse(line).unwrap_err();
            assert!(e.contains(says), "{line}: {e}");
            assert!(!e.contains('\n'), "{line}: one line: {e}");
        }
    }
}
