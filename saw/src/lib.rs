//! `saw`: the command a user (or an experiment script) drives a display with over its serial
//! link. One subcommand per request; every value checked before anything is sent; `--json`
//! prints one JSON object per command for scripts. The link itself is `saw_link`.

pub mod experiment;
mod experiment_analyze;
pub mod port;
pub mod record;
pub mod session;
#[cfg(feature = "ui")]
pub mod ui;

use std::path::PathBuf;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand, ValueEnum};
use saw_core::gate::DriveMode;
use saw_core::scene::Config;
use saw_core::texture::Texture;
use saw_link::client::{Client, ClientError};
use saw_link::msg::{Counters, Hello, Reply, Request, SceneSource};
use serde_json::{json, Value};

/// What the command line asked for.
#[derive(Debug)]
pub enum Parsed {
    /// A command to run.
    Run(Cli),
    /// `--help` or `--version`: print this, exit 0.
    Print(String),
    /// Not a valid command line: one line saying why (`json`: `--json` was given, so the
    /// answer goes to stdout as JSON like every other answer).
    Refused {
        /// `--json` was on the command line.
        json: bool,
        /// The flag or argument, the value and the rule, on one line.
        message: String,
    },
}

/// Parses a command line without exiting: errors come back as one line (clap's first line,
/// and its tip if it has one), so `--json` can answer in JSON even when the command line is
/// wrong.
pub fn parse_args<I, T>(args: I) -> Parsed
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let args: Vec<std::ffi::OsString> = args.into_iter().map(Into::into).collect();
    let json = args
        .iter()
        .skip(1)
        .take_while(|a| *a != "--")
        .any(|a| a == "--json");
    match Cli::try_parse_from(&args) {
        Ok(cli) => Parsed::Run(cli),
        Err(e) => {
            use clap::error::ErrorKind;
            match e.kind() {
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    Parsed::Print(e.render().to_string())
                }
                _ => Parsed::Refused {
                    json,
                    message: one_line(&e.render().to_string()),
                },
            }
        }
    }
}

/// Clap's error as one line: its first line without `error: `, and its tip.
pub(crate) fn one_line(rendered: &str) -> String {
    let all: Vec<&str> = rendered.lines().collect();
    let first = all
        .first()
        .map_or("the command line was not understood", |l| l.trim())
        .trim_start_matches("error: ");
    // A first line ending in ':' introduces an indented list (the missing arguments): kept.
    let list: Vec<&str> = if first.ends_with(':') {
        all.iter()
            .skip(1)
            .take_while(|l| l.starts_with("  "))
            .map(|l| l.trim())
            .collect()
    } else {
        Vec::new()
    };
    let first = if list.is_empty() {
        first.to_string()
    } else {
        format!("{} {}", first, list.join(", "))
    };
    let tip = all.iter().find_map(|l| l.trim().strip_prefix("tip: "));
    let help = "`saw --help` lists the commands, `saw COMMAND --help` their values";
    match tip {
        Some(t) => format!("{first} ({t}); {help}"),
        None => format!("{first}; {help}"),
    }
}

/// A whole number from `lo` to `hi` (`unit` in the sentence), negatives included in the check.
fn whole_in<T: TryFrom<i128>>(s: &str, lo: i128, hi: i128, unit: &str) -> Result<T, String> {
    let sentence = || format!("must be a whole number from {lo} to {hi}{unit}");
    let v: i128 = s
        .trim()
        .parse()
        .map_err(|_| format!("not a whole number; {}", sentence()))?;
    if v < lo || v > hi {
        return Err(sentence());
    }
    T::try_from(v).map_err(|_| sentence())
}

fn timeout_ms(s: &str) -> Result<u64, String> {
    whole_in(s, 10, 60_000, " ms")
}
fn every_n(s: &str) -> Result<u16, String> {
    whole_in(s, 1, 10_000, " samples")
}
fn index_u8(s: &str) -> Result<u8, String> {
    whole_in(s, 0, 255, "")
}
fn moves_n(s: &str) -> Result<u32, String> {
    whole_in(s, 10, 100_000, " moves")
}
fn count_n(s: &str) -> Result<u32, String> {
    whole_in(s, 2, 1_000, " round trips")
}

/// `saw --port PORT <command>`.
#[derive(Parser, Debug)]
#[command(
    name = "saw",
    version,
    about = "Drive a SAW tactile display over its serial link (the Nucleo's ST-LINK virtual COM port, or `host-sim serve --pty PATH` / `board-model serve --pty PATH`).",
    after_help = "Exit codes: 0 done; 1 the board refused a live edit (set, boundary, drive; the reason is printed); 2 a bad command line or scene file (a file the reader or the board refuses, located in the file); 3 the link failed (no port, port busy, no answer, protocol mismatch)."
)]
pub struct Cli {
    /// The serial port: /dev/ttyACM0 for a Nucleo, or the path given to `host-sim serve --pty` or `board-model serve --pty`.
    /// Every command but `experiment analyze` and `experiment check` needs it.
    #[arg(long, short, value_name = "PORT", global = true)]
    pub port: Option<PathBuf>,
    /// Print one JSON object instead of text (for scripts).
    #[arg(long, global = true)]
    pub json: bool,
    /// How long to wait for each answer, ms (10 to 60000). A save waits at least 4000 ms
    /// (`SAVE_TIMEOUT`): erasing a flash sector stalls the F446 for up to 2 s.
    #[arg(long, value_name = "MS", default_value_t = 1000, allow_negative_numbers = true, value_parser = timeout_ms)]
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
    /// Print the active scene (`--json`: the whole configuration; `--toml`: as a scene file).
    Get {
        /// Print the scene as a scene file (TOML, docs/scenes.md), to keep what was tuned live
        /// and push it again: `saw get --toml > tuned.toml`.
        #[arg(long)]
        toml: bool,
    },
    /// Move boundary INDEX (where region INDEX ends) to MM, live.
    Boundary {
        /// Boundary index, 0 = the end of the first region (0 to 255).
        #[arg(allow_negative_numbers = true, value_parser = index_u8)]
        index: u8,
        /// New position, mm from the start end (0 to 1000; the scene's layout rules apply).
        #[arg(value_parser = mm, allow_hyphen_values = true)]
        mm: f64,
    },
    /// Change region INDEX's texture, written as scene-file keys: `saw set 1 f_b_hz=80` keeps
    /// the region's kind and every value not named; `saw set 1 kind=grating wavelength_mm=1.5`
    /// gives it a new kind (its keys not named take their defaults). Same keys, ranges and
    /// sentences as a `[[region]]` table (docs/scenes.md).
    Set {
        /// Region index, left to right from 0 (0 to 255).
        #[arg(allow_negative_numbers = true, value_parser = index_u8)]
        index: u8,
        /// `key=value` pairs of a `[[region]]` table (docs/scenes.md).
        #[arg(required = true, value_name = "KEY=VALUE")]
        keys: Vec<String>,
    },
    /// Move or resize 2D window INDEX live (a board with the touch overlay): `--to X,Y` puts
    /// its outline's lower-left bounding corner at X,Y mm (any outline); `--rect X0,Y0,X1,Y1`
    /// gives a rectangle window new corners (a polygon only moves). Coordinates 0 to 1000 mm;
    /// the board refuses what leaves the scene's plate.
    Window {
        /// Window index, topmost first from 0 (0 to 255).
        #[arg(allow_negative_numbers = true, value_parser = index_u8)]
        index: u8,
        /// New lower-left bounding corner, mm: X,Y (each 0 to 1000).
        #[arg(long, value_name = "X,Y", allow_hyphen_values = true, value_parser = xy_mm, conflicts_with = "rect")]
        to: Option<(f64, f64)>,
        /// New corners of a rectangle, mm: X0,Y0,X1,Y1 (each 0 to 1000; lower left, upper right).
        #[arg(long, value_name = "X0,Y0,X1,Y1", allow_hyphen_values = true, value_parser = rect_mm)]
        rect: Option<[f64; 4]>,
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
    /// Record the telemetry stream to a CSV file (columns: docs/link.md). Only records
    /// sampled after the stream started are written: none left in transit from before.
    Stream {
        /// Where to write the records.
        #[arg(long, value_name = "FILE")]
        csv: PathBuf,
        /// How long, s (0.1 to 86400).
        #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = seconds)]
        seconds: f64,
        /// One record every N samples (1 to 10000; 10 = 1 kHz on a 10 kHz board).
        #[arg(long, value_name = "N", default_value_t = 10, allow_negative_numbers = true, value_parser = every_n)]
        every: u16,
    },
    /// One stream, many changes: streams to a CSV file while reading commands from stdin, one
    /// per line (`set 0 f_b_hz=80`, `push scenes/grating.toml`, `boundary 0 20`, `drive
    /// standing`, `wait 1.5`, `hello`, `get`, `counters`), until stdin ends or --seconds pass.
    /// Each command's answer is one line on stdout; every record carries the scene in force and
    /// the change count, so the log splits into trials at the changes.
    Session {
        /// Where to write the records.
        #[arg(long, value_name = "FILE")]
        csv: PathBuf,
        /// Record exactly this long, s (0.1 to 86400), whatever stdin does; without it the session
        /// ends when stdin ends and its last `wait` is over.
        #[arg(long, value_name = "S", allow_negative_numbers = true, value_parser = seconds)]
        seconds: Option<f64>,
        /// One record every N samples (1 to 10000; 10 = 1 kHz on a 10 kHz board).
        #[arg(long, value_name = "N", default_value_t = 10, allow_negative_numbers = true, value_parser = every_n)]
        every: u16,
    },
    /// Align the board's clock with this host's: round trips of a ping, the board's boot on the
    /// host's clock, the drift between the two clocks and how good the fit is.
    Ping {
        /// Round trips (2 to 1000), taken over --over seconds.
        #[arg(long, default_value_t = 20, allow_negative_numbers = true, value_parser = count_n)]
        count: u32,
        /// Seconds the round trips span (0 to 3600; a longer span measures the drift better).
        #[arg(long, value_name = "S", default_value_t = 1.0, allow_negative_numbers = true, value_parser = over_seconds)]
        over: f64,
    },
    /// Save the active scene to flash: the board boots into it from now on. A save that erases
    /// (an F446 sector: ~1 s, up to 2 s) holds the answer: this waits the longer of --timeout and
    /// 4 s, and prints how long the answer took (host time).
    Save,
    /// Experiments with people: run a protocol (paired comparisons, constant stimuli,
    /// staircases) with a participant, check a protocol, analyse sessions (docs/experiment.md).
    Experiment {
        /// What to do.
        #[command(subcommand)]
        command: experiment::ExperimentCommand,
    },
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
        #[arg(long, value_name = "N", default_value_t = 10, allow_negative_numbers = true, value_parser = every_n)]
        every: u16,
    },
    /// Measure the link: the round trip of boundary moves (window 0's moves on a board with the
    /// touch overlay; the scene is restored after), and the fastest stream that arrives without
    /// a drop.
    Bench {
        /// Boundary (or window) moves to time (10 to 100000).
        #[arg(long, default_value_t = 200, allow_negative_numbers = true, value_parser = moves_n)]
        moves: u32,
        /// Seconds each stream rate is tried (0.5 to 60).
        #[arg(long, value_name = "S", default_value_t = 2.0, allow_negative_numbers = true, value_parser = bench_seconds)]
        seconds: f64,
    },
}

fn over_seconds(s: &str) -> Result<f64, String> {
    finite_in(s, 0.0, 3600.0, "s")
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

/// `N` comma-separated millimetres, each finite and 0 to 1000.
fn mm_list<const N: usize>(s: &str, form: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != N {
        return Err(format!(
            "must be {form}: {N} numbers separated by commas, each from 0 to 1000 mm"
        ));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = mm(p.trim())?;
    }
    Ok(out)
}

fn xy_mm(s: &str) -> Result<(f64, f64), String> {
    mm_list::<2>(s, "X,Y").map(|[x, y]| (x, y))
}

fn rect_mm(s: &str) -> Result<[f64; 4], String> {
    mm_list::<4>(s, "X0,Y0,X1,Y1")
}

/// mm to the link's µm, rounded to the µm.
fn um(mm: f64) -> i32 {
    (mm * 1000.0).round() as i32
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
    pub(crate) fn input(message: String) -> Self {
        Self {
            code: 2,
            kind: "input",
            message,
        }
    }
    pub(crate) fn link(message: String) -> Self {
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
    let timeout = Duration::from_millis(cli.timeout);
    if let Command::Experiment { command } = &cli.command {
        return experiment::command(command, cli.port.as_deref(), timeout, cli.json);
    }
    if let Command::Ui {
        listen,
        allow_remote,
        every,
    } = &cli.command
    {
        return ui_command(cli, *listen, *allow_remote, *every);
    }
    let port = port::open(port_path(cli)?).map_err(Failure::link)?;
    let mut client = Client::new(port, timeout);
    // Every command starts with hello: a board speaking another protocol is named before
    // anything is sent that it would misread.
    let hello = client.hello()?;
    if let Command::Session {
        csv,
        seconds,
        every,
    } = &cli.command
    {
        return session::run(&mut client, csv, *seconds, *every, cli.json, timeout);
    }
    execute(&mut client, &cli.command, timeout, Some(hello))
}

/// The --port a command needs.
fn port_path(cli: &Cli) -> Result<&std::path::Path, Failure> {
    cli.port.as_deref().ok_or_else(|| {
        Failure::input(
            "--port: missing; this command talks to a board (the serial port: /dev/ttyACM0 for a Nucleo, or the path given to host-sim serve --pty)".into(),
        )
    })
}

/// Runs one command on an open link (`hello`: the board's answer to the hello already said).
pub(crate) fn execute<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    command: &Command,
    timeout: Duration,
    hello: Option<Hello>,
) -> Result<Done, Failure> {
    match command {
        Command::Hello => {
            let hello = match hello {
                Some(h) => h,
                None => client.hello()?,
            };
            let sensor = board_sensor(client)?;
            let mut hj = hello_json(&hello);
            hj["sensor"] = match sensor {
                saw_link::msg::Sensor::FourWire { plate_um } => json!({
                    "kind": "4-wire",
                    "plate_mm": [plate_um.0 as f64 / 1000.0, plate_um.1 as f64 / 1000.0],
                }),
                _ => json!({ "kind": "rheostat" }),
            };
            Ok(Done {
                text: format!("{}; reads {sensor}", hello_text(&hello)),
                json: json!({ "hello": hj }),
            })
        }
        Command::Push { file } => push(client, file),
        Command::Get { toml } => get(client, *toml),
        Command::Boundary { index, mm } => boundary(client, *index, *mm),
        Command::Window { index, to, rect } => window(client, *index, *to, *rect),
        Command::Set { index, keys } => set(client, *index, keys),
        Command::Drive { mode } => {
            let drive = match mode {
                Drive::Standing => DriveMode::Standing,
                Drive::Progressive => DriveMode::Progressive,
            };
            let reply = client.request(&Request::SetDrive(drive))?;
            applied(reply, format!("{} drive", drive_name(drive)))
        }
        Command::Counters { reset } => {
            match client.request(&Request::Counters { reset: *reset })? {
                Reply::Counters(c) => Ok(Done {
                    text: counters_text(&c),
                    json: json!({ "counters": c }),
                }),
                Reply::Counters2d(c) => Ok(Done {
                    text: counters_2d_text(&c),
                    json: json!({ "counters": c }),
                }),
                other => Err(unexpected(other)),
            }
        }
        Command::Stream {
            csv,
            seconds,
            every,
        } => stream(client, csv, *seconds, *every),
        Command::Ping { count, over } => ping(client, *count, *over),
        Command::Bench { moves, seconds } => bench(client, *moves, *seconds),
        Command::Save => save(client, timeout),
        Command::Session { .. } | Command::Ui { .. } | Command::Experiment { .. } => Err(Failure::input(
            "session, ui and experiment hold the port themselves: run them from the command line".into(),
        )),
    }
}

/// `saw ui` in a build without the panel (the `ui` feature off).
#[cfg(not(feature = "ui"))]
fn ui_command(
    _cli: &Cli,
    _listen: std::net::SocketAddr,
    _allow_remote: bool,
    _every: u16,
) -> Result<Done, Failure> {
    Err(Failure::input(
        "this saw was built without the panel (cargo feature `ui`)".into(),
    ))
}

/// `saw ui`: serves the panel until interrupted.
#[cfg(feature = "ui")]
fn ui_command(
    cli: &Cli,
    listen: std::net::SocketAddr,
    allow_remote: bool,
    every: u16,
) -> Result<Done, Failure> {
    if let Some(warning) = ui::check_listen(listen, allow_remote).map_err(Failure::input)? {
        eprintln!("{warning}");
    }
    let port = port_path(cli)?.to_path_buf();
    let handle = ui::start(ui::UiOptions {
        port: port.clone(),
        listen,
        allow_remote,
        timeout: Duration::from_millis(cli.timeout),
        every,
    })
    .map_err(Failure::input)?;
    eprintln!(
        "saw ui: http://{} (the panel for {}); Ctrl-C to stop",
        handle.addr,
        port.display()
    );
    if cli.json {
        // A script starting the panel reads where it is from stdout, as JSON like every answer
        // (the terminal lines above stay on stderr); the last line comes when it stops.
        use std::io::Write;
        let mut out = std::io::stdout().lock();
        let _ = writeln!(
            out,
            "{}",
            json!({ "ok": true, "result": {
                "listening": format!("http://{}", handle.addr),
                "port": port.display().to_string(),
            } })
        );
        let _ = out.flush();
    }
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

/// `saw window`: moves (`to`) or resizes (`rect`) a 2D window.
pub(crate) fn window<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    index: u8,
    to: Option<(f64, f64)>,
    rect: Option<[f64; 4]>,
) -> Result<Done, Failure> {
    use saw_core::plane::PointUm;
    let (request, what) = match (to, rect) {
        (Some((x, y)), None) => (
            Request::MoveWindow {
                window: index,
                to: PointUm::new(um(x), um(y)),
            },
            format!("window {index} moved to ({x} mm, {y} mm)"),
        ),
        (None, Some([x0, y0, x1, y1])) => (
            Request::ResizeWindow {
                window: index,
                lo: PointUm::new(um(x0), um(y0)),
                hi: PointUm::new(um(x1), um(y1)),
            },
            format!("window {index} resized to ({x0}, {y0}) – ({x1}, {y1}) mm"),
        ),
        _ => {
            return Err(Failure::input(
                "window: give --to X,Y (move) or --rect X0,Y0,X1,Y1 (resize), one of them".into(),
            ))
        }
    };
    let reply = client.request(&request).map_err(|e| no_2d(e, 1))?;
    applied(reply, what)
}

/// What a board whose firmware has no 2D scenes is told it lacks, when it answers a 2D request
/// "unknown request" (`saw`, the panel and Python's `sawlink` say the same).
pub const NO_2D_FIRMWARE: &str = "this board's firmware has no 2D scenes (it reads the slide rheostat): a 2D scene or a window edit needs a board with the 4-wire touch overlay";

/// A board whose firmware was built without 2D scenes (saw-link's `plane` feature off: the 1D
/// images) answers a 2D request "unknown request": said as the refusal it is, exit `code`.
fn no_2d(e: ClientError, code: u8) -> Failure {
    match e {
        ClientError::Link(saw_link::msg::LinkError::UnknownRequest { .. }) => Failure {
            code,
            kind: "refused",
            message: format!("refused, nothing changed: {NO_2D_FIRMWARE}"),
        },
        e => e.into(),
    }
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
                json: json!({ "saved": scene_hex(scene_id), "seconds": seconds }),
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

/// A scene id as text and JSON show it: `0x5ad0c3e1` (the id is a CRC-32).
pub fn scene_hex(id: u32) -> String {
    format!("{id:#010x}")
}

/// Where a scene came from, as JSON names it.
pub fn source_key(s: SceneSource) -> &'static str {
    match s {
        SceneSource::Default => "default",
        SceneSource::BuildTime => "build-time",
        SceneSource::Saved => "saved",
        SceneSource::Link => "link",
        _ => "unknown",
    }
}

/// A drive mode as the scene file writes it.
pub fn drive_name(d: DriveMode) -> &'static str {
    match d {
        DriveMode::Standing => "standing",
        DriveMode::Progressive => "progressive",
    }
}

fn hello_json(h: &Hello) -> Value {
    json!({
        "protocol": h.protocol,
        "firmware": h.firmware.as_str(),
        "board": h.board.as_str(),
        "sample_rate_hz": h.sample_rate_hz,
        "scene_id": scene_hex(h.scene_id),
        "scene_source": source_key(h.scene_source),
    })
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
            json: json!({ "applied": scene_hex(scene_id) }),
        }),
        Reply::Refused(e) => Err(Failure::refused(format!("refused, nothing changed: {e}"))),
        Reply::Refused2d(e) => Err(Failure::refused(format!("refused, nothing changed: {e}"))),
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
    let sensor =
        saw_core::scene_file::sensor_of(&name, text).map_err(|e| Failure::input(e.to_string()))?;
    if sensor == saw_core::scene_file::SensorKind::FourWire {
        return push_2d(client, &name, text);
    }
    let doc =
        saw_core::scene_file::parse(&name, text).map_err(|e| Failure::input(e.to_string()))?;
    match client.request(&Request::LoadScene(doc.config.clone()))? {
        Reply::Applied { scene_id } => Ok(Done {
            text: format!("{name}: running, scene {scene_id:#010x}"),
            json: json!({ "applied": scene_hex(scene_id), "file": name }),
        }),
        // The board's refusal, located in the file: the sentence host-sim gives this file.
        // A scene file the board refuses is a bad scene file, as one the reader refuses: exit 2
        // either way (docs/scenes.md, "When a file is refused"), kind "refused".
        Reply::Refused(e) => Err(Failure {
            code: 2,
            kind: "refused",
            message: doc.locate(&e).to_string(),
        }),
        // A board with the touch overlay: the file is 1D (issue #36).
        Reply::Refused2d(e) => Err(Failure {
            code: 2,
            kind: "refused",
            message: format!("{name}: refused by the board, nothing changed: {e}"),
        }),
        other => Err(unexpected(other)),
    }
}

/// A 2D scene file read for the board `hello` names, as host-sim reads it: dry-run for that
/// board's burst timer at its touch frame period (a board with the overlay counts frames as
/// samples, so `sample_rate_hz` is its frame rate), with the file's plate. `saw push`, the panel
/// and Python's `sawlink` prepare a 2D push with it. The error is the reader's sentence, or
/// one naming a board this tool does not know.
pub fn plane_scene_for_board(
    hello: &Hello,
    name: &str,
    text: &str,
) -> Result<saw_link::msg::PlaneScene, String> {
    let board = saw_boards::by_name(&hello.board).ok_or_else(|| {
        format!(
            "{name}: the board {} is not one this tool knows (saw-boards), so a 2D scene cannot be checked for it",
            hello.board
        )
    })?;
    let timer = saw_core::burst::BurstTimer {
        clock_hz: board.burst_timer_clk_hz,
        counter_bits: board.burst_timer_bits,
        max_burst_hz: board.max_burst_hz,
    };
    let frame_us = 1_000_000 / hello.sample_rate_hz.max(1);
    let config = saw_core::scene_file::load_2d_for_board(name, text, timer, frame_us)
        .map_err(|e| e.to_string())?;
    let plate_um = saw_core::scene_file::plate_um_of(name, text).map_err(|e| e.to_string())?;
    Ok(saw_link::msg::PlaneScene { plate_um, config })
}

/// Loads a 2D scene file (issue #36): read and dry-run here for the board's burst timer at its
/// touch frame period (what `hello` says: a board with the overlay counts frames as samples),
/// as host-sim reads it, then sent with its plate. A board with the rheostat refuses it with
/// its sentence (exit 2, as every refused file).
fn push_2d<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    name: &str,
    text: &str,
) -> Result<Done, Failure> {
    let hello = client.hello()?;
    let scene = plane_scene_for_board(&hello, name, text).map_err(Failure::input)?;
    match client
        .request(&Request::LoadScene2d(scene))
        .map_err(|e| no_2d(e, 2))?
    {
        Reply::Applied { scene_id } => Ok(Done {
            text: format!("{name}: running, scene {scene_id:#010x}"),
            json: json!({ "applied": scene_hex(scene_id), "file": name }),
        }),
        Reply::Refused2d(e) => Err(Failure {
            code: 2,
            kind: "refused",
            message: format!("{name}: refused by the board, nothing changed: {e}"),
        }),
        other => Err(unexpected(other)),
    }
}

/// A 2D scene as JSON with the scene file's keys and units, as [`scene_json`] a 1D one.
pub fn scene_json_2d(scene: &saw_link::msg::PlaneScene) -> Value {
    let text = saw_core::scene_file::to_scene_file_2d(&scene.config, scene.plate_um, "");
    match toml::from_str::<toml::Table>(&text) {
        Ok(t) => serde_json::to_value(t).unwrap_or(Value::Null),
        Err(_) => Value::Null,
    }
}

fn scene_2d_text(scene_id: u32, source: SceneSource, p: &saw_link::msg::PlaneScene) -> String {
    let sc = &p.config.scene;
    let mm = |um: i32| um as f64 / 1000.0;
    let n = sc.windows.len();
    let mut s = format!(
        "scene {scene_id:#010x}, {}; 2D, {n} window{} on a {} x {} mm plate, band {} mm, {} drive
  background: {}",
        source_name(source),
        if n == 1 { "" } else { "s" },
        p.plate_um.0 as f64 / 1000.0,
        p.plate_um.1 as f64 / 1000.0,
        sc.band_um as f64 / 1000.0,
        drive_name(sc.drive),
        plane_texture_text(&sc.background)
    );
    // Edges are numbered as the controller numbers them (and the stream's `edge` and host-sim's
    // reports name them): the felt outlines' sides first, window by window, each outline from
    // its first vertex, then the free segments.
    let mut next_edge = 0usize;
    for (i, w) in sc.windows.iter().enumerate() {
        let felt = if w.edge {
            let sides = w.outline.vertices.len();
            next_edge += sides;
            format!(
                ", outline felt as edges {}–{} (edge {} from the first vertex)",
                next_edge - sides,
                next_edge - 1,
                next_edge - sides
            )
        } else {
            String::new()
        };
        let pts: Vec<String> = w
            .outline
            .vertices
            .iter()
            .map(|v| format!("({}, {})", mm(v.x_um), mm(v.y_um)))
            .collect();
        s += &format!(
            "
  window {i}: {}{}, at {} mm",
            plane_texture_text(&w.texture),
            felt,
            pts.join(" ")
        );
    }
    for (i, e) in sc.free_edges.iter().enumerate() {
        s += &format!(
            "
  edge {}: ({}, {}) to ({}, {}) mm",
            next_edge + i,
            mm(e.a.x_um),
            mm(e.a.y_um),
            mm(e.b.x_um),
            mm(e.b.y_um)
        );
    }
    s
}

pub(crate) fn plane_texture_text(t: &saw_core::plane::PlaneTexture) -> String {
    match t {
        saw_core::plane::PlaneTexture::Plain(t) => texture_text(t),
        saw_core::plane::PlaneTexture::Oriented(o) => format!(
            "grating λ {} mm, ridges' normal at {}°",
            o.grating.wavelength_um as f64 / 1000.0,
            significant((o.normal.1 as f64).atan2(o.normal.0 as f64).to_degrees(), 4)
        ),
    }
}

fn get<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    toml: bool,
) -> Result<Done, Failure> {
    // The file's title: which scene it was read back from.
    let title = |scene_id: u32, source: SceneSource| {
        format!(
            "Read back with `saw get --toml`: scene {scene_id:#010x}, {}.",
            source_name(source)
        )
    };
    match client.request(&Request::GetScene)? {
        Reply::Scene2d {
            scene_id,
            source,
            scene,
        } => Ok(Done {
            text: if toml {
                saw_core::scene_file::to_scene_file_2d(
                    &scene.config,
                    scene.plate_um,
                    &title(scene_id, source),
                )
                .trim_end()
                .to_string()
            } else {
                scene_2d_text(scene_id, source, &scene)
            },
            json: json!({
                "scene_id": scene_hex(scene_id),
                "scene_source": source_key(source),
                "scene": scene_json_2d(&scene),
            }),
        }),
        Reply::Scene {
            scene_id,
            source,
            config,
        } => Ok(Done {
            text: if toml {
                saw_core::scene_file::to_scene_file(&config, &title(scene_id, source))
                    .trim_end()
                    .to_string()
            } else {
                scene_text(scene_id, source, &config)
            },
            json: json!({
                "scene_id": scene_hex(scene_id),
                "scene_source": source_key(source),
                "scene": scene_json(&config),
            }),
        }),
        other => Err(unexpected(other)),
    }
}

/// A scene as JSON with the scene file's keys and units (docs/scenes.md): what `saw get
/// --json` prints, and what a scene file written from it as TOML reads back as.
pub fn scene_json(c: &Config) -> Value {
    let text = saw_core::scene_file::to_scene_file(c, "");
    match toml::from_str::<toml::Table>(&text) {
        Ok(t) => serde_json::to_value(t).unwrap_or(Value::Null),
        Err(_) => Value::Null,
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
    let n = c.scene.textures.len();
    let mut s = format!(
        "scene {scene_id:#010x}, {}; {n} region{} over {} mm, {} drive",
        source_name(source),
        if n == 1 { "" } else { "s" },
        c.calibration.length_um as f64 / 1000.0,
        drive_name(c.scene.drive)
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
        Texture::Material(m) => format!("material Δμ {}", significant(m.delta_mu.into(), 3)),
        Texture::Random(r) => format!("random about {} Hz", r.center_millihz as f64 / 1000.0),
        other => other.kind().into(),
    }
}

/// `v` to `digits` significant digits, without trailing zeros: 0.05732819 → "0.0573".
pub fn significant(v: f64, digits: i32) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (digits - 1 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
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
    let given = region_toml(keys).map_err(Failure::input)?;
    // The region is read in the board's scene: lengths are checked against its substrate, and
    // the values not named are the region's own.
    let config = match client.request(&Request::GetScene)? {
        Reply::Scene { config, .. } => config,
        // A board with the overlay has no regions: its own sentence for a 1D edit (the session's
        // `WrongSensor`, which it answers `boundary` with), exit 1 as every refused edit.
        Reply::Scene2d { .. } => {
            let e = saw_link::msg::Refused2d::WrongSensor {
                asked: saw_link::msg::SceneKind::Line,
                board: board_sensor(client)?,
            };
            return Err(Failure::refused(format!("refused, nothing changed: {e}")));
        }
        other => return Err(unexpected(other)),
    };
    let texture = merged_texture(&config, index, &given).map_err(Failure::input)?;
    let reply = client.request(&Request::SetTexture {
        region: index,
        texture,
    })?;
    applied(reply, format!("region {index}: {}", texture_text(&texture)))
}

/// Region `index` of `config` with the keys of `given` (a `[[region]]` table from
/// [`region_toml`]) over its own: the same kind keeps every value not named; a new `kind` starts
/// from that kind's defaults. Checked as a scene file is; errors name the region and the key.
pub fn merged_texture(config: &Config, index: u8, given: &str) -> Result<Texture, String> {
    let n = config.scene.textures.len();
    let at = usize::from(index);
    if at >= n {
        return Err(format!(
            "region {index}: the board's scene has {n} region{} (0 to {})",
            if n == 1 { "" } else { "s" },
            n - 1
        ));
    }
    let given: toml::Table = toml::from_str(given).map_err(|e| e.to_string())?;
    let given = given
        .get("region")
        .and_then(|r| r.as_array())
        .and_then(|r| r.first())
        .and_then(|r| r.as_table())
        .cloned()
        .unwrap_or_default();
    let mut file: toml::Table = toml::from_str(&saw_core::scene_file::to_scene_file(config, ""))
        .map_err(|e| e.to_string())?;
    let region = file
        .get_mut("region")
        .and_then(|r| r.as_array_mut())
        .and_then(|r| r.get_mut(at))
        .and_then(|r| r.as_table_mut())
        .ok_or_else(|| format!("region {index}: not in the board's scene"))?;
    let new_kind = given
        .get("kind")
        .is_some_and(|k| Some(k) != region.get("kind"));
    if new_kind {
        // A new kind: only the region's extent carries over.
        region.retain(|k, _| k == "until_mm");
    }
    for (k, v) in given {
        region.insert(k, v);
    }
    let text = toml::to_string(&file).map_err(|e| e.to_string())?;
    let doc = saw_core::scene_file::parse("set", &text).map_err(|e| {
        let field = e.field.to_string();
        let prefix = format!("region[{at}].");
        match field.strip_prefix(&prefix) {
            Some(key) => format!("region {index}: `{key}`: {}", e.message),
            None => format!("region {index}: {}: {}", field, e.message),
        }
    })?;
    doc.config
        .scene
        .textures
        .get(at)
        .copied()
        .ok_or_else(|| format!("region {index}: not in the scene read back"))
}

fn counters_2d_text(c: &saw_link::msg::Counters2d) -> String {
    let k = &c.core;
    let l = &c.link;
    format!(
        "touch readings {}\nsensor faults {}\nlifts {}\nwindow switches {}\ngate actions {}\nf_b clamped {}\n\
         edge pulses {} (skipped {})\nridge pulses {} (skipped {})\n\
         link frames {} (refused {})\nstream records {} (dropped {})",
        k.readings,
        k.faults,
        k.lifts,
        k.window_switches,
        k.gate_actions,
        k.clamped,
        k.edge_pulses,
        k.edges_skipped,
        k.ridge_pulses,
        k.ridges_skipped,
        l.frames_ok,
        l.frames_bad,
        l.records_sent,
        l.records_dropped
    )
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

pub use record::{csv_line, CSV_HEADER};

/// The counts of a run that streamed: before and after, from the board.
fn stream_counts<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
) -> Result<(u32, u32), Failure> {
    let c = counters(client)?;
    Ok((c.link.records_dropped, c.link.frames_bad))
}

/// Streams to `csv` for `seconds`: pings before and after for the clock alignment, and only
/// records sampled after the board started this stream.
fn stream<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    csv: &std::path::Path,
    seconds: f64,
    every: u16,
) -> Result<Done, Failure> {
    let mut run = StreamRun::start(client, csv, every)?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    run.rec.drain_until(client, end)?;
    run.finish(client, format!("in {seconds} s"))
}

/// A stream being recorded, from its start to its summary.
pub(crate) struct StreamRun {
    pub(crate) rec: record::Recorder,
    before: (u32, u32),
    start_pings: Vec<saw_link::clock::Ping>,
    rate_hz: f64,
    csv: String,
}

impl StreamRun {
    /// Aligns the clocks, opens the file and starts the stream.
    pub(crate) fn start<P: std::io::Read + std::io::Write>(
        client: &mut Client<P>,
        csv: &std::path::Path,
        every: u16,
    ) -> Result<Self, Failure> {
        let start_pings = record::pings(client, record::PINGS, Duration::ZERO)?;
        // Back to back: the offset only (a rate fitted over a millisecond would be noise).
        let align = saw_link::clock::Alignment::offset(&start_pings)
            .ok_or_else(|| Failure::link("no ping answered".into()))?;
        let plane = board_is_2d(client)?;
        let rec = record::Recorder::create(csv, align, plane)?;
        let before = stream_counts(client)?;
        let started = client.start_stream(every)?;
        Ok(Self {
            rec,
            before,
            start_pings,
            rate_hz: started.sample_rate_hz as f64 / every as f64,
            csv: csv.display().to_string(),
        })
    }

    /// Stops the stream, measures the drift over it and sums it up.
    pub(crate) fn finish<P: std::io::Read + std::io::Write>(
        mut self,
        client: &mut Client<P>,
        how_long: String,
    ) -> Result<Done, Failure> {
        client.stop_stream()?;
        self.rec.finish()?;
        let end_pings = record::pings(client, record::PINGS, Duration::ZERO)?;
        let all: Vec<_> = self.start_pings.iter().chain(&end_pings).copied().collect();
        let drift = saw_link::clock::Alignment::fit(&all).unwrap_or(self.rec.align);
        let after = stream_counts(client)?;
        let dropped = after.0.wrapping_sub(self.before.0);
        let refused_by_board = after.1.wrapping_sub(self.before.1);
        let r = &self.rec;
        let (first_us, last_us) = r.span_us.unwrap_or((0, 0));
        // The host times in the file are from the offset before the stream; the drift measured
        // over it adds this much at the last record.
        let drift_error_us =
            drift.drift_ppm().abs() * 1e-6 * (last_us.saturating_sub(first_us)) as f64;
        let text = format!(
            "{} records {how_long} to {} ({:.0} records/s asked), {:.3} s of board time ({first_us} to {last_us} µs since boot), {} scene change{}\n\
             dropped by the board {dropped}; frames lost on the line {}; frames from the board that failed their check {}; frames the board refused {refused_by_board}; stale records left out {}\n\
             clocks: board boot at host Unix time {:.6} s, host times within ±{:.2} ms (half the quickest round trip before the stream {:.2} ms, and the board clock's drift of {:+.1} ± {:.1} ppm over the stream, {:.2} ms at its end)",
            r.records,
            self.csv,
            self.rate_hz,
            r.span_s(),
            r.changes,
            if r.changes == 1 { "" } else { "s" },
            r.frames_lost,
            client.bad_frames(),
            client.stale_records(),
            r.align.host_us(0) * 1e-6,
            (r.align.error_us + drift_error_us) * 1e-3,
            r.align.error_us * 1e-3,
            drift.drift_ppm(),
            drift.drift_error_ppm(),
            drift_error_us * 1e-3,
        );
        Ok(Done {
            text,
            json: json!({
                "records": r.records, "frames": r.frames, "dropped": dropped,
                "frames_lost": r.frames_lost, "bad_frames": client.bad_frames(),
                "refused_by_board": refused_by_board, "stale_records": client.stale_records(),
                "first_us": first_us, "last_us": last_us, "board_seconds": r.span_s(),
                "scene_changes": r.changes, "rate_hz": self.rate_hz, "csv": self.csv,
                "clock": record::alignment_json(&r.align),
                "drift": record::alignment_json(&drift),
            }),
        })
    }
}

/// `saw ping`: round trips spread over `over` seconds and the alignment they give.
fn ping<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    count: u32,
    over: f64,
) -> Result<Done, Failure> {
    let gap = Duration::from_secs_f64(over / (count - 1).max(1) as f64);
    let pings = record::pings(client, count as usize, gap)?;
    let a = saw_link::clock::Alignment::fit(&pings)
        .ok_or_else(|| Failure::link("no ping answered".into()))?;
    let mut rtt: Vec<u64> = pings.iter().map(|p| p.round_trip_us()).collect();
    rtt.sort_unstable();
    let (min, median, max) = (rtt[0], rtt[rtt.len() / 2], rtt[rtt.len() - 1]);
    let last = pings[pings.len() - 1].board_us;
    let drift = if a.span_us == 0 {
        "no drift measured (no time between the pings fitted)".to_string()
    } else {
        format!(
            "the board clock {:+.1} ± {:.1} ppm against this host's (positive: fast), measured over {:.3} s",
            a.drift_ppm(),
            a.drift_error_ppm(),
            a.span_us as f64 * 1e-6
        )
    };
    Ok(Done {
        text: format!(
            "{count} round trips: {min} µs quickest, {median} µs median, {max} µs slowest\n\
             board clock {last} µs since boot; boot at host Unix time {:.6} s; {drift}; mapped times within ±{:.0} µs",
            a.host_us(0) * 1e-6,
            a.error_us
        ),
        json: json!({
            "round_trip_us": { "min": min, "median": median, "max": max },
            "board_us": last,
            "clock": record::alignment_json(&a),
        }),
    })
}

/// Round trips of live edits and the lossless stream rate: boundary 0's moves on a board with
/// the rheostat, window 0's on one with the touch overlay (the 2D analogue: a live edit of the
/// scene's geometry), each restored after.
fn bench<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    moves: u32,
    seconds: f64,
) -> Result<Done, Failure> {
    let (edit, requests) = match client.request(&Request::GetScene)? {
        Reply::Scene { config, .. } => ("boundary", boundary_moves(&config)?),
        Reply::Scene2d { scene, .. } => ("window", window_moves(&scene)?),
        other => return Err(unexpected(other)),
    };
    let [there, back, home] = requests;
    let mut rtt_us: Vec<f64> = Vec::with_capacity(moves as usize);
    for i in 0..moves {
        // A real move each time, always a valid layout.
        let request = if i % 2 == 0 { &there } else { &back };
        let t = Instant::now();
        match client.request(request)? {
            Reply::Applied { .. } => {}
            other => return Err(bench_refused(other)),
        }
        rtt_us.push(t.elapsed().as_secs_f64() * 1e6);
    }
    // Back where it was: the same scene, so the board reports its source as before.
    match client.request(&home)? {
        Reply::Applied { .. } => {}
        other => return Err(bench_refused(other)),
    }
    let plane = edit == "window";
    rtt_us.sort_by(f64::total_cmp);
    let pick = |q: f64| rtt_us[((rtt_us.len() - 1) as f64 * q).round() as usize];
    let (median, p99, max) = (pick(0.5), pick(0.99), pick(1.0));

    let hello = client.hello()?;
    let mut rates = Vec::new();
    let mut tried: Vec<(f64, u32)> = Vec::new();
    for every in [1u16, 2, 3, 4, 5, 10] {
        let before = counters(client)?.link.records_dropped;
        client.start_stream(every)?;
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        let mut records = 0u64;
        if plane {
            while let Some((_, s)) = client.next_stream_2d(end)? {
                records += s.records.len() as u64;
            }
        } else {
            while let Some((_, s)) = client.next_stream(end)? {
                records += s.records.len() as u64;
            }
        }
        // Frames still in flight after the stop are dropped by the client.
        client.stop_stream()?;
        let dropped = counters(client)?.link.records_dropped.wrapping_sub(before);
        let rate = hello.sample_rate_hz as f64 / every as f64;
        tried.push((rate, dropped));
        rates.push(
            json!({ "every": every, "rate_hz": rate, "records": records, "dropped": dropped }),
        );
    }
    let lossless = fastest_lossless(&tried);
    let text = format!(
        "{edit} move round trip over {moves} moves: median {:.0} µs, 99th percentile {:.0} µs, max {:.0} µs\n\
         fastest stream without a drop over {seconds} s: {}",
        median,
        p99,
        max,
        lossless.map_or("none of the rates tried".into(), |r| format!("{r:.0} records/s"))
    );
    Ok(Done {
        text,
        json: json!({
            "edit": edit, "moves": moves, "rtt_us": { "median": median, "p99": p99, "max": max },
            "lossless_rate_hz": lossless, "rates": rates,
        }),
    })
}

/// The fastest stream rate that dropped nothing, when no slower rate tried dropped either:
/// `(rate_hz, dropped)` pairs fastest first. A rate whose slower rates dropped was lossless by
/// chance (a quiet moment of the line or the host), not a rate to stream at.
fn fastest_lossless(tried: &[(f64, u32)]) -> Option<f64> {
    tried
        .iter()
        .rev()
        .take_while(|(_, dropped)| *dropped == 0)
        .last()
        .map(|(rate, _)| *rate)
}

/// `bench`'s boundary moves on a 1D scene: boundary 0 0.1 mm up, back 0.1 mm below where it was,
/// and home.
fn boundary_moves(config: &Config) -> Result<[Request; 3], Failure> {
    let Some(&at_um) = config.scene.boundaries_um.first() else {
        return Err(Failure::input(
            "the active scene has no boundary to move".into(),
        ));
    };
    let at = |at_um| Request::MoveBoundary { index: 0, at_um };
    Ok([at(at_um + 100), at(at_um.saturating_sub(100)), at(at_um)])
}

/// `bench`'s window moves on a 2D scene: window 0 (its bounding box's lower-left corner) 0.1 mm
/// along x, back, and home. Towards the plate's middle along x, or along y if the window spans
/// the plate's width, so every move stays on the plate.
fn window_moves(scene: &saw_link::msg::PlaneScene) -> Result<[Request; 3], Failure> {
    use saw_core::plane::PointUm;
    let Some(w) = scene.config.scene.windows.first() else {
        return Err(Failure::input(
            "the active scene has no window to move".into(),
        ));
    };
    let v = &w.outline.vertices;
    let (lo_x, hi_x) = v.iter().fold((i32::MAX, i32::MIN), |(lo, hi), p| {
        (lo.min(p.x_um), hi.max(p.x_um))
    });
    let (lo_y, hi_y) = v.iter().fold((i32::MAX, i32::MIN), |(lo, hi), p| {
        (lo.min(p.y_um), hi.max(p.y_um))
    });
    let (w_um, h_um) = (scene.plate_um.0 as i64, scene.plate_um.1 as i64);
    // A step of 0.1 mm that keeps the window on the plate, by axis: + if there is room above, −
    // if below, none if the window spans that side of the plate within 0.1 mm.
    let step = |lo: i32, hi: i32, size: i64| {
        if hi as i64 + 100 <= size {
            Some(100)
        } else if lo >= 100 {
            Some(-100)
        } else {
            None
        }
    };
    let home = PointUm::new(lo_x, lo_y);
    let moved = match (step(lo_x, hi_x, w_um), step(lo_y, hi_y, h_um)) {
        (Some(dx), _) => PointUm::new(lo_x + dx, lo_y),
        (None, Some(dy)) => PointUm::new(lo_x, lo_y + dy),
        (None, None) => {
            return Err(Failure::input(
                "window 0 covers the whole plate: there is no room to move it".into(),
            ))
        }
    };
    let to = |to| Request::MoveWindow { window: 0, to };
    Ok([to(moved), to(home), to(home)])
}

/// A bench move the board did not apply: its refusal (exit 1), or an out-of-turn reply.
fn bench_refused(reply: Reply) -> Failure {
    match reply {
        Reply::Refused(e) => Failure::refused(format!("refused, nothing changed: {e}")),
        Reply::Refused2d(e) => Failure::refused(format!("refused, nothing changed: {e}")),
        other => unexpected(other),
    }
}

fn counters<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
) -> Result<Counters, Failure> {
    match client.request(&Request::Counters { reset: false })? {
        Reply::Counters(c) => Ok(c),
        // A 2D board's link counts are the same; its core's are not read here.
        Reply::Counters2d(c) => Ok(Counters {
            core: Default::default(),
            link: c.link,
        }),
        other => Err(unexpected(other)),
    }
}

/// Whether the board reads the touch overlay (runs 2D scenes). A board of protocol 2 from
/// before issue #36 answers `Sensor` with "unknown request": the rheostat.
pub fn board_is_2d<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
) -> Result<bool, Failure> {
    Ok(matches!(
        board_sensor(client)?,
        saw_link::msg::Sensor::FourWire { .. }
    ))
}

/// The sensor the board reads (the rheostat for a board that predates the question).
pub fn board_sensor<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
) -> Result<saw_link::msg::Sensor, Failure> {
    match client.request(&Request::Sensor) {
        Ok(Reply::Sensor(s)) => Ok(s),
        Err(ClientError::Link(saw_link::msg::LinkError::UnknownRequest { .. })) => {
            Ok(saw_link::msg::Sensor::Rheostat)
        }
        Ok(other) => Err(unexpected(other)),
        Err(e) => Err(e.into()),
    }
}

#[cfg(test)]
mod tests {
    use super::fastest_lossless;

    /// `saw get` numbers a 2D scene's edges as the stream and host-sim do: the felt outlines'
    /// sides first, then the free segments. `scenes/2d-concave.toml` felt window 1 has six
    /// sides, so its first free segment, (50, 40) to (75, 40) mm, is edge 6 (it read "edge 0").
    #[test]
    fn get_numbers_edges_as_the_stream_does() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../scenes/2d-concave.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let timer = saw_core::burst::BurstTimer {
            clock_hz: 90_000_000,
            counter_bits: 16,
            max_burst_hz: 2_000,
        };
        let config = saw_core::scene_file::load_2d_for_board(path, &text, timer, 280).unwrap();
        let plate_um = saw_core::scene_file::plate_um_of(path, &text).unwrap();
        let scene = saw_link::msg::PlaneScene { plate_um, config };
        let text = super::scene_2d_text(1, saw_link::msg::SceneSource::Link, &scene);
        assert!(
            text.contains("outline felt as edges 0–5 (edge 0 from the first vertex)"),
            "{text}"
        );
        assert!(text.contains("edge 6: (50, 40) to (75, 40) mm"), "{text}");
        assert!(text.contains("edge 7: (50, 45) to (75, 55) mm"), "{text}");
        assert!(!text.contains("edge 0:"), "{text}");
    }

    /// The fastest rate with no drop at it or below: a quiet moment at a fast rate, with a slower
    /// one dropping, is not lossless.
    #[test]
    fn the_lossless_rate_is_the_fastest_with_no_drop_at_or_below_it() {
        let rates = [10_000.0, 5_000.0, 3_333.3, 2_500.0, 2_000.0, 1_000.0];
        let with = |drops: [u32; 6]| -> Vec<(f64, u32)> { rates.into_iter().zip(drops).collect() };
        assert_eq!(fastest_lossless(&with([9, 4, 0, 0, 0, 0])), Some(3_333.3));
        assert_eq!(fastest_lossless(&with([0, 0, 0, 0, 0, 0])), Some(10_000.0));
        // Every fourth dropped after every second did not: every second is not lossless.
        assert_eq!(fastest_lossless(&with([9, 0, 0, 3, 0, 0])), Some(2_000.0));
        assert_eq!(fastest_lossless(&with([9, 4, 3, 2, 1, 1])), None);
    }
}
