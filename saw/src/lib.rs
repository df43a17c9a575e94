//! `saw`: the command a user (or an experiment script) drives a display with over its serial
//! link. One subcommand per request; every value checked before anything is sent; `--json`
//! prints one JSON object per command for scripts. The link itself is `saw_link`.

pub mod port;
pub mod ui;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand, ValueEnum};
use saw_core::gate::DriveMode;
use saw_core::scene::Config;
use saw_core::texture::Texture;
use saw_link::client::{Client, ClientError};
use saw_link::msg::{Counters, Hello, Record, Reply, Request, SceneSource};
use serde_json::{json, Value};

/// `saw --port PORT <command>`.
#[derive(Parser, Debug)]
#[command(
    name = "saw",
    version,
    about = "Drive a SAW tactile display over its serial link (the Nucleo's ST-LINK virtual COM port, or `host-sim serve --pty PATH` / `board-model serve --pty PATH`).",
    after_help = "Exit codes: 0 done; 1 the board refused (the reason is printed); 2 a bad command line or scene file; 3 the link failed (no port, port busy, no answer, protocol mismatch)."
)]
pub struct Cli {
    /// The serial port: /dev/ttyACM0 for a Nucleo, or the path given to `host-sim serve --pty` or `board-model serve --pty`.
    #[arg(long, short, value_name = "PORT")]
    pub port: PathBuf,
    /// Print one JSON object instead of text (for scripts).
    #[arg(long, global = true)]
    pub json: bool,
    /// How long to wait for each answer, ms (10 to 60000). A save waits at least 4000 ms
    /// (`SAVE_TIMEOUT`): erasing a flash sector stalls the F446 for up to 2 s.
    #[arg(long, value_name = "MS", default_value_t = 1000, value_parser = clap::value_parser!(u64).range(10..=60_000))]
    pub timeout: u64,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The requests.
#[derive(Subcommand, Debug)]
pub enum Command {
    /// Who is there: board, firmware, protocol, the active scene's id and where it came from.
    Hello,
    /// Load a scene file: checked here as host-sim checks it, then compiled on the board;
    /// refused with the same sentence, located in the file, with nothing changed.
    Push {
        /// The scene file (TOML, as in scenes/).
        file: PathBuf,
    },
    /// Print the active scene (`--json`: the whole configuration).
    Get,
    /// Move boundary INDEX (where region INDEX ends) to MM, live.
    Boundary {
        /// Boundary index, 0 = the end of the first region.
        index: u8,
        /// New position, mm from the start end (0 to 1000; the scene's layout rules apply).
        #[arg(value_parser = mm, allow_hyphen_values = true)]
        mm: f64,
    },
    /// Give region INDEX a new texture, written as scene-file keys: `saw set 1 kind=grating
    /// wavelength_mm=1.5` (same keys, ranges and sentences as a `[[region]]` table).
    Set {
        /// Region index, left to right from 0.
        index: u8,
        /// `key=value` pairs of a `[[region]]` table (docs/scenes.md).
        #[arg(required = true, value_name = "KEY=VALUE")]
        keys: Vec<String>,
    },
    /// Standing (both IDTs) or progressive (one IDT) drive.
    Drive {
        /// The drive mode.
        mode: Drive,
    },
    /// The board's counters since boot or the last reset.
    Counters {
        /// Start counting from zero after this read.
        #[arg(long)]
        reset: bool,
    },
    /// Record the telemetry stream to a CSV file.
    Stream {
        /// Where to write the records (time_us, position_um, velocity_um_s, region, f_b_hz, bursting, fault).
        #[arg(long, value_name = "FILE")]
        csv: PathBuf,
        /// How long, s (0.1 to 86400).
        #[arg(long, value_name = "S", value_parser = seconds)]
        seconds: f64,
        /// One record every N samples (1 to 10000; 10 = 1 kHz on a 10 kHz board).
        #[arg(long, value_name = "N", default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=10_000))]
        every: u16,
    },
    /// Save the active scene to flash: the board boots into it from now on. A save that erases
    /// (an F446 sector: ~1 s, up to 2 s) holds the answer: this waits the longer of --timeout and
    /// 4 s, and prints how long the answer took (host time).
    Save,
    /// The fig. 11 panel: a local web page that shows the finger, the regions and the trace live
    /// and edits the scene (docs/ui.md). Open the address it prints in a browser.
    Ui {
        /// Where the page is served. Loopback only unless --allow-remote is given.
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:8800")]
        listen: std::net::SocketAddr,
        /// Allow a non-loopback --listen address (anyone who reaches it drives the display).
        #[arg(long)]
        allow_remote: bool,
        /// One record every N samples in the page's trace (1 to 10000; 10 = 1 kHz on a 10 kHz
        /// board).
        #[arg(long, value_name = "N", default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=10_000))]
        every: u16,
    },
    /// Measure the link: the round trip of boundary moves (the scene is restored after), and
    /// the fastest stream that arrives without a drop.
    Bench {
        /// Boundary moves to time (10 to 100000).
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(10..=100_000))]
        moves: u32,
        /// Seconds each stream rate is tried (0.5 to 60).
        #[arg(long, value_name = "S", default_value_t = 2.0, value_parser = bench_seconds)]
        seconds: f64,
    },
}

fn bench_seconds(s: &str) -> Result<f64, String> {
    finite_in(s, 0.5, 60.0, "s")
}

/// Drive modes as typed on the command line.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Drive {
    /// Both IDTs: a standing wave.
    Standing,
    /// One IDT: a progressive wave.
    Progressive,
}

fn finite_in(s: &str, lo: f64, hi: f64, unit: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("not a number; must be from {lo} to {hi} {unit}"))?;
    if !v.is_finite() || v < lo || v > hi {
        return Err(format!("must be a finite number from {lo} to {hi} {unit}"));
    }
    Ok(v)
}

fn mm(s: &str) -> Result<f64, String> {
    finite_in(s, 0.0, 1000.0, "mm")
}

fn seconds(s: &str) -> Result<f64, String> {
    finite_in(s, 0.1, 86_400.0, "s")
}

/// Why a command failed, with its exit code.
#[derive(Debug)]
pub struct Failure {
    /// 1 refused, 2 bad input, 3 link.
    pub code: u8,
    /// `refused`, `input` or `link`, for `--json`.
    pub kind: &'static str,
    /// One line for a person.
    pub message: String,
}

impl Failure {
    fn refused(message: String) -> Self {
        Self {
            code: 1,
            kind: "refused",
            message,
        }
    }
    fn input(message: String) -> Self {
        Self {
            code: 2,
            kind: "input",
            message,
        }
    }
    fn link(message: String) -> Self {
        Self {
            code: 3,
            kind: "link",
            message,
        }
    }
}

impl From<ClientError> for Failure {
    fn from(e: ClientError) -> Self {
        Failure::link(e.to_string())
    }
}

/// What a command printed: text for a person, JSON for a script.
#[derive(Debug)]
pub struct Done {
    /// Text output.
    pub text: String,
    /// JSON output.
    pub json: Value,
}

/// Runs one command.
pub fn run(cli: &Cli) -> Result<Done, Failure> {
    if let Command::Ui {
        listen,
        allow_remote,
        every,
    } = &cli.command
    {
        return ui_command(cli, *listen, *allow_remote, *every);
    }
    let port = port::open(&cli.port).map_err(Failure::link)?;
    let mut client = Client::new(port, Duration::from_millis(cli.timeout));
    // Every command starts with hello: a board speaking another protocol is named before
    // anything is sent that it would misread.
    let hello = client.hello()?;
    match &cli.command {
        Command::Hello => Ok(Done {
            text: hello_text(&hello),
            json: json!({ "hello": hello }),
        }),
        Command::Push { file } => push(&mut client, file),
        Command::Get => get(&mut client),
        Command::Boundary { index, mm } => boundary(&mut client, *index, *mm),
        Command::Set { index, keys } => set(&mut client, *index, keys),
        Command::Drive { mode } => {
            let drive = match mode {
                Drive::Standing => DriveMode::Standing,
                Drive::Progressive => DriveMode::Progressive,
            };
            let reply = client.request(&Request::SetDrive(drive))?;
            applied(reply, format!("drive {drive:?}"))
        }
        Command::Counters { reset } => {
            match client.request(&Request::Counters { reset: *reset })? {
                Reply::Counters(c) => Ok(Done {
                    text: counters_text(&c),
                    json: json!({ "counters": c }),
                }),
                other => Err(unexpected(other)),
            }
        }
        Command::Stream {
            csv,
            seconds,
            every,
        } => stream(&mut client, csv, *seconds, *every),
        Command::Bench { moves, seconds } => bench(&mut client, *moves, *seconds),
        Command::Save => save(&mut client, Duration::from_millis(cli.timeout)),
        Command::Ui { .. } => unreachable!("handled before the port is opened"),
    }
}

/// `saw ui`: serves the panel until interrupted.
fn ui_command(
    cli: &Cli,
    listen: std::net::SocketAddr,
    allow_remote: bool,
    every: u16,
) -> Result<Done, Failure> {
    if let Some(warning) = ui::check_listen(listen, allow_remote).map_err(Failure::input)? {
        eprintln!("{warning}");
    }
    let handle = ui::start(ui::UiOptions {
        port: cli.port.clone(),
        listen,
        allow_remote,
        timeout: Duration::from_millis(cli.timeout),
        every,
    })
    .map_err(Failure::input)?;
    eprintln!(
        "saw ui: http://{} (the panel for {}); Ctrl-C to stop",
        handle.addr,
        cli.port.display()
    );
    handle.wait();
    Ok(Done {
        text: "the panel stopped".into(),
        json: json!({ "stopped": true }),
    })
}

/// Moves boundary `index` to `mm`, live.
pub(crate) fn boundary<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    index: u8,
    mm: f64,
) -> Result<Done, Failure> {
    let at_um = (mm * 1000.0).round() as u32;
    let reply = client.request(&Request::MoveBoundary { index, at_um })?;
    applied(reply, format!("boundary {index} at {mm} mm"))
}

/// The least a save waits for its answer. A save may erase one unit of the store: on the F446 a
/// 128 KiB sector, 1 s typical and 2 s at most at ×32 parallelism (DS10693 §6.3.11, t_ERASE128KB),
/// during which the CPU is stalled and the link silent; the board model measures 1.11 s from
/// request to answer with a typical erase (docs/board-model.md). 4 s covers the worst erase with
/// the save's programming and item migration twice over. The G474's 2 KiB page (22 ms typical,
/// 40 ms at most: DS12288 §5.3.10) fits the usual timeout.
pub const SAVE_TIMEOUT: Duration = Duration::from_millis(4_000);

/// Saves the active scene, waiting up to the larger of `timeout` and `SAVE_TIMEOUT`; says how
/// long the board took.
pub(crate) fn save<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    timeout: Duration,
) -> Result<Done, Failure> {
    let asked = Instant::now();
    match client.request_within(&Request::Save, timeout.max(SAVE_TIMEOUT))? {
        Reply::Saved { scene_id } => {
            let seconds = asked.elapsed().as_secs_f64();
            Ok(Done {
                text: format!(
                    "saved scene {scene_id:#010x} in {seconds:.2} s: the board boots into it"
                ),
                json: json!({ "saved": scene_id, "seconds": seconds }),
            })
        }
        Reply::SaveFailed(e) => Err(Failure::refused(format!("save failed: {e}"))),
        other => Err(unexpected(other)),
    }
}

pub(crate) fn unexpected(r: Reply) -> Failure {
    Failure::link(format!(
        "the board answered with an unexpected reply: {r:?}"
    ))
}

pub(crate) fn source_name(s: SceneSource) -> &'static str {
    match s {
        SceneSource::Default => "the built-in default",
        SceneSource::BuildTime => "embedded at build time",
        SceneSource::Saved => "saved in flash",
        SceneSource::Link => "loaded over the link",
        _ => "unknown",
    }
}

fn hello_text(h: &Hello) -> String {
    format!(
        "{} running {} (protocol {}, {} samples/s); scene {:#010x}, {}",
        h.board,
        h.firmware,
        h.protocol,
        h.sample_rate_hz,
        h.scene_id,
        source_name(h.scene_source)
    )
}

pub(crate) fn applied(reply: Reply, what: String) -> Result<Done, Failure> {
    match reply {
        Reply::Applied { scene_id } => Ok(Done {
            text: format!("{what}: running, scene {scene_id:#010x}"),
            json: json!({ "applied": scene_id }),
        }),
        Reply::Refused(e) => Err(Failure::refused(format!("refused, nothing changed: {e}"))),
        other => Err(unexpected(other)),
    }
}

fn push<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    file: &PathBuf,
) -> Result<Done, Failure> {
    let name = file.display().to_string();
    let text = std::fs::read_to_string(file).map_err(|e| Failure::input(format!("{name}: {e}")))?;
    push_text(client, &name, &text)
}

/// Loads the scene file `text` (named `name` in messages): checked here, compiled on the board.
pub(crate) fn push_text<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    name: &str,
    text: &str,
) -> Result<Done, Failure> {
    let name = name.to_string();
    let doc =
        saw_core::scene_file::parse(&name, text).map_err(|e| Failure::input(e.to_string()))?;
    match client.request(&Request::LoadScene(doc.config.clone()))? {
        Reply::Applied { scene_id } => Ok(Done {
            text: format!("{name}: running, scene {scene_id:#010x}"),
            json: json!({ "applied": scene_id, "file": name }),
        }),
        // The board's refusal, located in the file: the sentence host-sim gives this file.
        Reply::Refused(e) => Err(Failure::refused(doc.locate(&e).to_string())),
        other => Err(unexpected(other)),
    }
}

fn get<P: std::io::Read + std::io::Write>(client: &mut Client<P>) -> Result<Done, Failure> {
    match client.request(&Request::GetScene)? {
        Reply::Scene {
            scene_id,
            source,
            config,
        } => Ok(Done {
            text: scene_text(scene_id, source, &config),
            json: json!({ "scene_id": scene_id, "source": source, "config": config }),
        }),
        other => Err(unexpected(other)),
    }
}

/// Each region's extent, mm from the start end, and its texture, left to right.
pub(crate) fn regions_mm(c: &Config) -> impl Iterator<Item = (f64, f64, &Texture)> {
    let ends = c
        .scene
        .boundaries_um
        .iter()
        .copied()
        .chain([c.calibration.length_um]);
    let starts = core::iter::once(0).chain(c.scene.boundaries_um.iter().copied());
    starts
        .zip(ends)
        .zip(c.scene.textures.iter())
        .map(|((from, to), t)| (from as f64 / 1000.0, to as f64 / 1000.0, t))
}

fn scene_text(scene_id: u32, source: SceneSource, c: &Config) -> String {
    let mut s = format!(
        "scene {scene_id:#010x}, {}; {} regions over {} mm, {:?} drive",
        source_name(source),
        c.scene.textures.len(),
        c.calibration.length_um as f64 / 1000.0,
        c.scene.drive
    );
    for (i, (from_mm, to_mm, t)) in regions_mm(c).enumerate() {
        s += &format!(
            "\n  region {i}: {from_mm} to {to_mm} mm, {}",
            texture_text(t)
        );
    }
    if !c.scene.lines.positions_um.is_empty() {
        let mm: Vec<String> = c
            .scene
            .lines
            .positions_um
            .iter()
            .map(|p| format!("{}", *p as f64 / 1000.0))
            .collect();
        s += &format!("\n  lines at {} mm", mm.join(", "));
    }
    s
}

pub(crate) fn texture_text(t: &Texture) -> String {
    match t {
        Texture::Off => "off".into(),
        Texture::Constant(c) => format!(
            "constant {} Hz, {} % duty",
            c.burst_millihz as f64 / 1000.0,
            c.duty_permille as f64 / 10.0
        ),
        Texture::Grating(g) => format!("grating λ {} mm", g.wavelength_um as f64 / 1000.0),
        Texture::Material(m) => format!("material Δμ {}", m.delta_mu),
        Texture::Random(r) => format!("random about {} Hz", r.center_millihz as f64 / 1000.0),
        other => other.kind().into(),
    }
}

/// `key=value` pairs as the lines of a `[[region]]` table: a value TOML reads as a number,
/// boolean, array or quoted string stays as written, anything else is quoted
/// (`kind=grating`).
pub fn region_toml(keys: &[String]) -> Result<String, String> {
    let mut out = String::from("[[region]]\n");
    for kv in keys {
        let Some((k, v)) = kv.split_once('=') else {
            return Err(format!("`{kv}` is not KEY=VALUE (e.g. f_b_hz=80)"));
        };
        let (k, v) = (k.trim(), v.trim());
        if k.is_empty() || !k.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!("`{k}` is not a scene-file key"));
        }
        let literal = format!("x = {v}");
        let value = if toml::from_str::<toml::Table>(&literal).is_ok() {
            v.to_string()
        } else {
            toml::Value::String(v.to_string()).to_string()
        };
        out += &format!("{k} = {value}\n");
    }
    Ok(out)
}

pub(crate) fn set<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    index: u8,
    keys: &[String],
) -> Result<Done, Failure> {
    let region = region_toml(keys).map_err(Failure::input)?;
    // The region is read against the board's substrate, so lengths are checked as in its scene.
    let Reply::Scene { config, .. } = client.request(&Request::GetScene)? else {
        return Err(Failure::link("the board did not send its scene".into()));
    };
    let cal = config.calibration;
    let text = format!(
        "[substrate]\nlength_mm = {}\ncode_at_start = {}\ncode_at_end = {}\nrail_margin_code = {}\n\n{region}",
        cal.length_um as f64 / 1000.0,
        cal.code_at_start,
        cal.code_at_end,
        cal.rail_margin_code
    );
    let doc = saw_core::scene_file::parse("set", &text).map_err(|e| {
        Failure::input(format!(
            "region {index}: `{}`: {}",
            e.field.trim_start_matches("region[0]."),
            e.message
        ))
    })?;
    let Some(texture) = doc.config.scene.textures.first().copied() else {
        return Err(Failure::input("no texture given (kind=…)".into()));
    };
    let reply = client.request(&Request::SetTexture {
        region: index,
        texture,
    })?;
    applied(reply, format!("region {index}: {}", texture_text(&texture)))
}

fn counters_text(c: &Counters) -> String {
    let k = &c.core;
    let l = &c.link;
    format!(
        "samples {}\nsensor faults {}\nregion switches {}\ngate actions {}\nf_b clamped {}\n\
         line pulses {} (skipped {})\nridge pulses {} (skipped {})\n\
         link frames {} (refused {})\nstream records {} (dropped {})",
        k.samples,
        k.faults,
        k.region_switches,
        k.gate_actions,
        k.clamped,
        k.line_pulses,
        k.lines_skipped,
        k.ridge_pulses,
        k.ridges_skipped,
        l.frames_ok,
        l.frames_bad,
        l.records_sent,
        l.records_dropped
    )
}

/// A CSV line of a record.
pub fn csv_line(r: &Record) -> String {
    let opt = |v: Option<i32>| v.map_or(String::new(), |v| v.to_string());
    format!(
        "{},{},{},{},{},{},{}",
        r.time_us,
        opt(r.position_um),
        opt(r.velocity_um_s),
        r.region.map_or(String::new(), |v| v.to_string()),
        r.burst_millihz as f64 / 1000.0,
        u8::from(r.bursting),
        r.fault.map_or(String::new(), |f| format!("{f:?}"))
    )
}

/// The CSV header.
pub const CSV_HEADER: &str = "time_us,position_um,velocity_um_s,region,f_b_hz,bursting,fault";

fn stream<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    csv: &PathBuf,
    seconds: f64,
    every: u16,
) -> Result<Done, Failure> {
    use std::io::Write;
    let file = std::fs::File::create(csv)
        .map_err(|e| Failure::input(format!("--csv {}: {e}", csv.display())))?;
    let mut w = std::io::BufWriter::new(file);
    let io = |e: std::io::Error| Failure::input(format!("--csv {}: {e}", csv.display()));
    writeln!(w, "{CSV_HEADER}").map_err(io)?;
    let dropped_before = match client.request(&Request::Counters { reset: false })? {
        Reply::Counters(c) => c.link.records_dropped,
        other => return Err(unexpected(other)),
    };
    let rate = match client.request(&Request::Stream {
        every_samples: every,
    })? {
        Reply::Streaming { sample_rate_hz, .. } => sample_rate_hz as f64 / every as f64,
        other => return Err(unexpected(other)),
    };
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut records, mut frames, mut frames_lost) = (0u64, 0u64, 0u64);
    let mut last_seq: Option<u32> = None;
    while let Some((h, s)) = client.next_stream(end)? {
        if let Some(prev) = last_seq {
            frames_lost += h.seq.wrapping_sub(prev).saturating_sub(1) as u64;
        }
        last_seq = Some(h.seq);
        frames += 1;
        for r in &s.records {
            writeln!(w, "{}", csv_line(r)).map_err(io)?;
            records += 1;
        }
    }
    let _ = client.request(&Request::Stream { every_samples: 0 })?;
    w.flush().map_err(io)?;
    let dropped = match client.request(&Request::Counters { reset: false })? {
        Reply::Counters(c) => c.link.records_dropped.wrapping_sub(dropped_before) as u64,
        other => return Err(unexpected(other)),
    };
    Ok(Done {
        text: format!(
            "{records} records in {seconds} s to {} ({rate:.0} records/s asked); {dropped} dropped by the board, {frames_lost} frames lost on the line, {} refused",
            csv.display(),
            client.bad_frames()
        ),
        json: json!({
            "records": records, "frames": frames, "dropped": dropped,
            "frames_lost": frames_lost, "bad_frames": client.bad_frames(),
            "rate_hz": rate, "csv": csv.display().to_string(),
        }),
    })
}

/// Round trips of boundary moves and the lossless stream rate.
fn bench<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    moves: u32,
    seconds: f64,
) -> Result<Done, Failure> {
    let Reply::Scene { config, .. } = client.request(&Request::GetScene)? else {
        return Err(Failure::link("the board did not send its scene".into()));
    };
    let Some(&at_um) = config.scene.boundaries_um.first() else {
        return Err(Failure::input(
            "the active scene has no boundary to move".into(),
        ));
    };
    let mut rtt_us: Vec<f64> = Vec::with_capacity(moves as usize);
    for i in 0..moves {
        // 0.1 mm either side of where it was: a real move each time, always a valid layout.
        let to = if i % 2 == 0 {
            at_um + 100
        } else {
            at_um.saturating_sub(100)
        };
        let t = Instant::now();
        match client.request(&Request::MoveBoundary {
            index: 0,
            at_um: to,
        })? {
            Reply::Applied { .. } => {}
            other => return Err(unexpected(other)),
        }
        rtt_us.push(t.elapsed().as_secs_f64() * 1e6);
    }
    match client.request(&Request::LoadScene(config))? {
        Reply::Applied { .. } => {}
        other => return Err(unexpected(other)),
    }
    rtt_us.sort_by(f64::total_cmp);
    let pick = |q: f64| rtt_us[((rtt_us.len() - 1) as f64 * q).round() as usize];
    let (median, p99, max) = (pick(0.5), pick(0.99), pick(1.0));

    let hello = client.hello()?;
    let mut rates = Vec::new();
    let mut lossless: Option<f64> = None;
    for every in [1u16, 2, 3, 4, 5, 10] {
        let before = counters(client)?.link.records_dropped;
        client.request(&Request::Stream {
            every_samples: every,
        })?;
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        let mut records = 0u64;
        while let Some((_, s)) = client.next_stream(end)? {
            records += s.records.len() as u64;
        }
        client.request(&Request::Stream { every_samples: 0 })?;
        // Frames still in flight after the stop are read and dropped here.
        while client
            .next_stream(Instant::now() + Duration::from_millis(50))?
            .is_some()
        {}
        let dropped = counters(client)?.link.records_dropped.wrapping_sub(before);
        let rate = hello.sample_rate_hz as f64 / every as f64;
        if dropped == 0 && lossless.is_none() {
            lossless = Some(rate);
        }
        rates.push(
            json!({ "every": every, "rate_hz": rate, "records": records, "dropped": dropped }),
        );
    }
    let text = format!(
        "boundary move round trip over {moves} moves: median {:.0} µs, 99th percentile {:.0} µs, max {:.0} µs\n\
         fastest stream without a drop over {seconds} s: {}",
        median,
        p99,
        max,
        lossless.map_or("none of the rates tried".into(), |r| format!("{r:.0} records/s"))
    );
    Ok(Done {
        text,
        json: json!({
            "moves": moves, "rtt_us": { "median": median, "p99": p99, "max": max },
            "lossless_rate_hz": lossless, "rates": rates,
        }),
    })
}

fn counters<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
) -> Result<Counters, Failure> {
    match client.request(&Request::Counters { reset: false })? {
        Reply::Counters(c) => Ok(c),
        other => Err(unexpected(other)),
    }
}
