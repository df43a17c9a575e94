//! `saw experiment`: the front end of the experiment crate (`saw_experiment`). `run` presents a
//! protocol's trials on the board and asks the participant (in the terminal, or a simulated
//! participant); `check` reads a protocol and prints its plan; `analyze` prints (or charts) what
//! the analysis returns. Order, progress, the log and the analysis are the crate's; this only
//! presents, asks and prints.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clap::{Subcommand, ValueEnum};
use saw_experiment::exploration;
use saw_experiment::protocol::{self, Protocol};
use saw_experiment::runner::{Runner, Trial};
use saw_experiment::session::{self, Header, Log, Shown, TrialRecord};
use saw_link::client::Client;
use saw_link::msg::{Hello, Record, Reply, Request};
use serde_json::{json, Value};

use crate::{scene_hex, Done, Failure};

/// The experiment commands.
#[derive(Subcommand, Debug)]
pub enum ExperimentCommand {
    /// Run a protocol with a participant: each stimulus loaded to the board before it is
    /// presented, the exploration streamed and summarised, the response asked in the terminal,
    /// every trial logged and synced before the next (docs/experiment.md).
    Run {
        /// The protocol file (TOML; experiments/ holds the seed paper's study).
        protocol: PathBuf,
        /// The participant's id (letters, digits, '-', '_', '.'; it names the session's files).
        #[arg(long, value_name = "ID")]
        subject: String,
        /// The participant's number in the study, 0 for the first (0 to 100000): it
        /// counterbalances block orders and pair orders across subjects. Default: the number
        /// of sessions already in --out.
        #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = subject_index)]
        subject_index: Option<u32>,
        /// Where the session's files go (<subject>.log.jsonl, .csv, .json).
        #[arg(long, value_name = "DIR", default_value = "sessions")]
        out: PathBuf,
        /// Continue the subject's session from its log: the trial in progress when it stopped
        /// is run again, the order unchanged.
        #[arg(long)]
        resume: bool,
        /// A simulated participant answers instead of a person (tests, planning): a Thurstonian
        /// observer on the f_b the board produced, its spec from FILE (docs/experiment.md,
        /// "The simulated participant"), or the default observer with `--simulate default`.
        #[arg(long, value_name = "FILE|default")]
        simulate: Option<String>,
        /// The simulated participant's noise seed (0 to 9223372036854775807; default: the subject
        /// index).
        #[arg(long, value_name = "N", requires = "simulate", allow_negative_numbers = true, value_parser = seed_n)]
        observer_seed: Option<u64>,
        /// Ask on web pages as well as in the terminal: the participant's view (large response
        /// buttons, for a tablet) at http://ADDR:PORT/participant and the experimenter's at
        /// /experimenter, both URLs printed with the run's token, which every request needs.
        /// A page or the terminal may answer; the first answer counts (docs/experiment-panel.md).
        #[arg(long, value_name = "ADDR:PORT", conflicts_with = "simulate")]
        panel: Option<std::net::SocketAddr>,
        /// Allow a non-loopback --panel address (a tablet on the lab's network).
        #[arg(long, requires = "panel")]
        allow_remote: bool,
    },
    /// Read a protocol and print its plan: stimuli, blocks, trials per subject, how long.
    Check {
        /// The protocol file.
        protocol: PathBuf,
    },
    /// Analyse sessions' CSVs (or a lab's own `subject,first,second,score` CSV): scale values,
    /// the ANOVA, the yardstick; thresholds and psychometric fits for staircases and
    /// constant stimuli.
    Analyze {
        /// CSV files: session CSVs of `saw experiment run`, or `subject,first,second,score`.
        #[arg(required = true, value_name = "FILE")]
        files: Vec<PathBuf>,
        /// The paired-comparison variant to analyse by (default: the one the design implies).
        #[arg(long, value_enum)]
        method: Option<Method>,
        /// Write a chart (PNG): the scale with yardstick bars, staircase tracks, the fits.
        #[arg(long, short = 'o', value_name = "PNG")]
        output: Option<PathBuf>,
    },
}

/// Scheffé's variants, as typed.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum Method {
    /// Scheffé's original: order effect, one pair per subject.
    Scheffe,
    /// Ura's: order effect, every ordered pair per subject.
    Ura,
    /// Haga's: no order effect, one pair per subject.
    Haga,
    /// Nakaya's: no order effect, every unordered pair per subject.
    Nakaya,
}

fn subject_index(s: &str) -> Result<u32, String> {
    crate::whole_in(s, 0, 100_000, "")
}

fn seed_n(s: &str) -> Result<u64, String> {
    crate::whole_in(s, 0, i64::MAX as i128, "")
}

/// Runs an experiment command; `port` and `timeout` for `run`.
pub fn command(
    cmd: &ExperimentCommand,
    port: Option<&Path>,
    timeout: Duration,
    json_out: bool,
) -> Result<Done, Failure> {
    match cmd {
        ExperimentCommand::Check { protocol } => check(protocol),
        ExperimentCommand::Analyze {
            files,
            method,
            output,
        } => crate::experiment_analyze::analyze(files, *method, output.as_deref()),
        ExperimentCommand::Run {
            protocol,
            subject,
            subject_index,
            out,
            resume,
            simulate,
            observer_seed,
            panel,
            allow_remote,
        } => {
            let p = protocol::load(protocol).map_err(|e| Failure::input(e.to_string()))?;
            session::check_subject(subject).map_err(Failure::input)?;
            let port = port.ok_or_else(|| {
                Failure::input("--port: missing; `saw experiment run` presents on a board (the path of the serial port)".into())
            })?;
            let participant: Box<dyn Participant> = match (simulate, panel) {
                (Some(spec), _) => Box::new(Simulated::new(spec, *observer_seed, *subject_index)?),
                (None, None) => Box::new(Terminal::new(json_out)),
                #[cfg(feature = "ui")]
                (None, Some(listen)) => Box::new(crate::ui::experiment::Panel::start(
                    crate::ui::experiment::PanelOptions {
                        listen: *listen,
                        allow_remote: *allow_remote,
                        json: json_out,
                        protocol: p.clone(),
                        subject: subject.clone(),
                        subject_index: *subject_index,
                        out: out.clone(),
                    },
                )?),
                #[cfg(not(feature = "ui"))]
                (None, Some(_)) => {
                    let _ = allow_remote;
                    return Err(Failure::input(
                        "--panel: this saw was built without the panel (cargo feature `ui`)".into(),
                    ));
                }
            };
            on_interrupt();
            let opened = crate::port::open(port).map_err(Failure::link)?;
            let mut client = Client::new(opened, timeout);
            let hello = client.hello()?;
            run(
                &mut client,
                &hello,
                p,
                RunOptions {
                    subject: subject.clone(),
                    subject_index: *subject_index,
                    out: out.clone(),
                    resume: *resume,
                },
                participant,
            )
        }
    }
}

/// How a run is set up.
pub struct RunOptions {
    /// The participant's id.
    pub subject: String,
    /// Its index (None: the sessions already in `out`).
    pub subject_index: Option<u32>,
    /// The sessions' directory.
    pub out: PathBuf,
    /// Continue the subject's log.
    pub resume: bool,
}

/// Who answers: a person at the terminal or a simulated participant.
pub trait Participant {
    /// Before the first trial.
    fn instructions(&mut self, text: &str) -> Result<(), Failure>;
    /// A break: returns when the participant is ready.
    fn rest(&mut self, done: u32, planned: u32) -> Result<(), Failure>;
    /// The experimenter hands over an external object; returns when it is in place.
    fn hand_over(&mut self, interval: usize, stimulus: &str, prompt: &str) -> Result<(), Failure>;
    /// The participant explores interval `interval` now.
    fn explore(&mut self, interval: usize, of: usize);
    /// A trial begins (the experimenter's bearings: which, of how many, in which block).
    fn begin(&mut self, _trial: &Trial, _planned: u32) {}
    /// The response to `trial`, having felt `shown` (what the finger did and the f_b the board
    /// produced).
    fn respond(&mut self, trial: &Trial, shown: &[Shown]) -> Result<i32, Failure>;
}

/// A person at this terminal: prompts on stderr, answers from stdin.
pub struct Terminal {
    json: bool,
}

impl Terminal {
    fn new(json: bool) -> Self {
        Terminal { json }
    }

    fn line(&self) -> Result<String, Failure> {
        let mut s = String::new();
        let n = std::io::stdin()
            .lock()
            .read_line(&mut s)
            .map_err(|e| Failure::input(format!("stdin: {e}")))?;
        if n == 0 {
            return Err(Failure::input(
                "stdin ended before the session did: the log keeps every trial answered; --resume continues".into(),
            ));
        }
        Ok(s.trim().to_string())
    }
}

impl Participant for Terminal {
    fn instructions(&mut self, text: &str) -> Result<(), Failure> {
        if !text.is_empty() {
            eprintln!("\n{text}\n");
        }
        eprint!("Press Enter to begin. ");
        self.line().map(|_| ())
    }

    fn rest(&mut self, done: u32, planned: u32) -> Result<(), Failure> {
        eprint!("Break ({done} of {planned} trials done). Press Enter to go on. ");
        self.line().map(|_| ())
    }

    fn hand_over(&mut self, interval: usize, stimulus: &str, prompt: &str) -> Result<(), Failure> {
        eprint!(
            "[experimenter] interval {}: {prompt} ({stimulus}); press Enter when it is in place. ",
            interval + 1
        );
        self.line().map(|_| ())
    }

    fn explore(&mut self, interval: usize, of: usize) {
        eprintln!("Explore {} of {of} now.", interval + 1);
    }

    fn begin(&mut self, trial: &Trial, planned: u32) {
        eprintln!(
            "\n— trial {} of {planned}, block \"{}\"",
            trial.number + 1,
            trial.block
        );
    }

    fn respond(&mut self, trial: &Trial, _shown: &[Shown]) -> Result<i32, Failure> {
        loop {
            eprintln!("{}", trial.question);
            for (v, w) in trial.values.iter().zip(&trial.words) {
                eprintln!("  {v:>3}  {w}");
            }
            eprint!("> ");
            let _ = std::io::stderr().flush();
            discard_typed_ahead();
            let s = self.line()?;
            match s.parse::<i32>() {
                Ok(v) if trial.values.contains(&v) => return Ok(v),
                _ => {
                    let _ = self.json;
                    eprintln!(
                        "{s:?} is not an answer here: type one of {}",
                        trial
                            .values
                            .iter()
                            .map(|v| v.to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    )
                }
            }
        }
    }
}

/// Ctrl-C (SIGINT) or SIGTERM during a session: one line saying that the log keeps every
/// trial answered and how to go on, then exit 130 as a shell expects. The log is synced at
/// each trial, so there is nothing to flush; only async-signal-safe calls in the handler.
fn on_interrupt() {
    use nix::sys::signal::{sigaction, SaFlags, SigAction, SigHandler, SigSet, Signal};
    extern "C" fn stop(_: i32) {
        const SAID: &[u8] = b"\nsaw experiment: interrupted; the log keeps every trial answered (the one in progress is not): --resume continues\n";
        // SAFETY: write(2) and _exit(2) are async-signal-safe; SAID is static.
        unsafe {
            nix::libc::write(2, SAID.as_ptr().cast(), SAID.len());
            nix::libc::_exit(130);
        }
    }
    let action = SigAction::new(SigHandler::Handler(stop), SaFlags::empty(), SigSet::empty());
    for sig in [Signal::SIGINT, Signal::SIGTERM] {
        // SAFETY: the handler only calls async-signal-safe functions.
        let _ = unsafe { sigaction(sig, &action) };
    }
}

/// Drops what was typed at the terminal before the question was asked (a key pressed while
/// exploring is not an answer; the panel refuses those too). Nothing to drop when stdin is a
/// pipe: a script's answers are meant in order.
fn discard_typed_ahead() {
    use std::os::fd::AsFd;
    let stdin = std::io::stdin();
    if nix::unistd::isatty(stdin.as_fd()).unwrap_or(false) {
        let _ = nix::sys::termios::tcflush(stdin.as_fd(), nix::sys::termios::FlushArg::TCIFLUSH);
    }
}

/// The simulated participant: answers through the same runner as a person.
pub struct Simulated(saw_experiment::simulate::Participant);

impl Simulated {
    fn new(spec: &str, seed: Option<u64>, subject_index: Option<u32>) -> Result<Self, Failure> {
        let mut s: saw_experiment::observer::ObserverSpec = if spec == "default" {
            saw_experiment::observer::ObserverSpec::default()
        } else {
            let text = std::fs::read_to_string(spec)
                .map_err(|e| Failure::input(format!("--simulate {spec}: {e}")))?;
            toml::from_str(&text).map_err(|e| {
                Failure::input(format!(
                    "--simulate {spec}: {}",
                    e.message().lines().next().unwrap_or("")
                ))
            })?
        };
        // Each subject its own noise unless a seed is given.
        s.seed = seed.unwrap_or(u64::from(subject_index.unwrap_or(0)));
        saw_experiment::simulate::Participant::new(s)
            .map(Simulated)
            .map_err(|e| Failure::input(format!("--simulate {spec}: {e}")))
    }
}

impl Participant for Simulated {
    fn instructions(&mut self, _: &str) -> Result<(), Failure> {
        Ok(())
    }
    fn rest(&mut self, _: u32, _: u32) -> Result<(), Failure> {
        Ok(())
    }
    fn hand_over(&mut self, _: usize, _: &str, _: &str) -> Result<(), Failure> {
        Ok(())
    }
    fn explore(&mut self, _: usize, _: usize) {}

    fn respond(&mut self, trial: &Trial, shown: &[Shown]) -> Result<i32, Failure> {
        Ok(self.0.respond(trial, shown))
    }
}

/// Stream decimation during exploration: 1 kHz on a 10 kHz board, well within the line
/// (docs/link.md: every 4th sample is lossless).
const EXPLORE_EVERY: u16 = 10;

/// Loads a scene's text on the board: the scene id it confirmed.
fn load<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    what: &str,
    text: &str,
) -> Result<u32, Failure> {
    let doc = saw_core::scene_file::parse(what, text).map_err(|e| Failure::input(e.to_string()))?;
    match client.request(&Request::LoadScene(doc.config.clone()))? {
        Reply::Applied { scene_id } => Ok(scene_id),
        Reply::Refused(e) => Err(Failure {
            code: 2,
            kind: "refused",
            message: format!("the board refused {what}: {}", doc.locate(&e)),
        }),
        other => Err(Failure::link(format!(
            "unexpected answer to a scene load: {other:?}"
        ))),
    }
}

/// Streams for `seconds`: the records of scene `scene_id` sampled in the window.
fn explore<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    seconds: f64,
    scene_id: Option<u32>,
) -> Result<(Vec<Record>, Option<u64>), Failure> {
    let started = client.start_stream(EXPLORE_EVERY)?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut records = Vec::new();
    while let Some((_, s)) = client.next_stream(end)? {
        // Only the stimulus' own scene: the client already drops records from before the
        // stream started; this also holds if a scene change raced the window.
        records.extend(
            s.records
                .into_iter()
                .filter(|r| scene_id.is_none_or(|id| r.scene_id == id)),
        );
    }
    client.stop_stream()?;
    Ok((records, Some(started.from_us)))
}

/// Runs (or resumes) a session.
pub fn run<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    hello: &Hello,
    protocol: Protocol,
    opts: RunOptions,
    mut participant: Box<dyn Participant>,
) -> Result<Done, Failure> {
    let paths = session::Paths::new(&opts.out, &opts.subject);
    let (mut runner, mut log) = if opts.resume {
        let log = Log::resume(&opts.out, &opts.subject).map_err(Failure::input)?;
        if log.header().protocol_text != protocol.text {
            return Err(Failure::input(format!(
                "{}: the protocol file differs from the one this session began with (kept in {}); resume with that file",
                protocol.file,
                paths.log.display()
            )));
        }
        let index =
            session::subject_index(&protocol, opts.subject_index, Some(log.header()), &opts.out)
                .map_err(|e| Failure::input(format!("--subject-index: {e}")))?;
        let runner = Runner::resume(protocol, &opts.subject, index, &log.replay())
            .map_err(|e| Failure::input(e.to_string()))?;
        (runner, log)
    } else {
        let index = session::subject_index(&protocol, opts.subject_index, None, &opts.out)
            .map_err(|e| Failure::input(format!("--subject-index: {e}")))?;
        let runner = Runner::new(protocol, &opts.subject, index)
            .map_err(|e| Failure::input(e.to_string()))?;
        let header = Header::new(
            &runner,
            board_json(hello),
            &format!("saw {}", env!("CARGO_PKG_VERSION")),
        );
        let log = Log::create(&opts.out, header).map_err(Failure::input)?;
        (runner, log)
    };
    let resumed_at = runner.answered();
    let planned = runner.planned_trials();
    let off_scene = runner.protocol().off_scene.clone();
    if resumed_at == 0 {
        participant.instructions(&runner.protocol().instructions)?;
    }
    while let Some(trial) = runner.next_trial().cloned() {
        // A failure mid-trial (the board pulled, stdin closed) loses that trial only: the log
        // holds every one answered, and the message says how to go on.
        let answered = runner.answered();
        present_trial(client, &trial, &mut runner, &mut log, &mut *participant, resumed_at, planned, &off_scene)
            .map_err(|mut f| {
                f.message = format!(
                    "{} (at trial {}; the log {} keeps the {answered} trials answered: --resume runs this one again)",
                    f.message,
                    trial.number,
                    paths.log.display()
                );
                f
            })?;
    }
    load(client, "the RF-off scene", &off_scene)?;
    let trials = log.records().len();
    Ok(Done {
        text: format!(
            "{} trials of subject {} in {} ({} this run); the CSV is {}",
            trials,
            opts.subject,
            paths.log.display(),
            trials as u32 - resumed_at,
            paths.csv.display()
        ),
        json: json!({
            "trials": trials,
            "this_run": trials as u32 - resumed_at,
            "subject": opts.subject,
            "log": paths.log.display().to_string(),
            "csv": paths.csv.display().to_string(),
            "sidecar": paths.sidecar.display().to_string(),
        }),
    })
}

/// Presents one trial, asks, logs it.
#[allow(clippy::too_many_arguments)]
fn present_trial<P: std::io::Read + std::io::Write>(
    client: &mut Client<P>,
    trial: &Trial,
    runner: &mut Runner,
    log: &mut Log,
    participant: &mut dyn Participant,
    resumed_at: u32,
    planned: u32,
    off_scene: &str,
) -> Result<(), Failure> {
    let timing = runner.protocol().timing;
    participant.begin(trial, planned);
    if trial.break_before && trial.number > resumed_at {
        load(client, "the RF-off scene", off_scene)?;
        participant.rest(trial.number, planned)?;
    }
    let started_utc = session::now_utc();
    let mut shown = Vec::new();
    let n = trial.intervals.len();
    for (k, iv) in trial.intervals.iter().enumerate() {
        let mut s = Shown {
            stimulus: iv.stimulus.clone(),
            ..Shown::default()
        };
        match &iv.scene {
            Some(text) => {
                let id = load(client, &iv.stimulus, text)?;
                s.scene_id = Some(id);
                participant.explore(k, n);
                let (records, from_us) = explore(client, timing.explore_s, Some(id))?;
                s.board_from_us = from_us;
                s.board_to_us = records.last().map(|r| r.time_us);
                s.exploration = Some(exploration::summarize(&records));
            }
            None => {
                // An object handed over: the board's RF off while it is explored.
                load(client, "the RF-off scene", off_scene)?;
                participant.hand_over(k, &iv.stimulus, iv.prompt.as_deref().unwrap_or(""))?;
                participant.explore(k, n);
                std::thread::sleep(Duration::from_secs_f64(timing.explore_s));
            }
        }
        shown.push(s);
        if timing.rf_off_between {
            load(client, "the RF-off scene", off_scene)?;
        }
        if k + 1 < n {
            std::thread::sleep(Duration::from_secs_f64(timing.pause_s));
        }
    }
    let asked = Instant::now();
    let value = participant.respond(trial, &shown)?;
    let response_ms = asked.elapsed().as_secs_f64() * 1e3;
    let outcome = runner
        .respond(value)
        .map_err(|e| Failure::input(e.to_string()))?;
    log.append(TrialRecord::new(&outcome, shown, started_utc, response_ms))
        .map_err(Failure::input)?;
    if runner.next_trial().is_some() {
        std::thread::sleep(Duration::from_secs_f64(timing.pause_s));
    }
    Ok(())
}

fn board_json(h: &Hello) -> Value {
    json!({
        "board": h.board.as_str(),
        "firmware": h.firmware.as_str(),
        "protocol": h.protocol,
        "sample_rate_hz": h.sample_rate_hz,
        "scene_id_at_start": scene_hex(h.scene_id),
    })
}

/// `saw experiment check`: the protocol's plan.
fn check(path: &Path) -> Result<Done, Failure> {
    use saw_experiment::protocol::{Design, PairedVariant};
    let p = protocol::load(path).map_err(|e| Failure::input(e.to_string()))?;
    let r = Runner::new(p.clone(), "check", 0).map_err(|e| Failure::input(e.to_string()))?;
    let trials = r.planned_trials();
    let adaptive = p
        .blocks
        .iter()
        .any(|b| matches!(b.design, Design::Staircase { .. }));
    let per_trial_s = 2.0 * p.timing.explore_s + 2.0 * p.timing.pause_s;
    let minutes = trials as f64 * per_trial_s / 60.0;
    let mut text = format!(
        "{}: \"{}\", {} stimuli, {} block{}, {}{} trials per subject (about {:.1} min at {} s per exploration and {} s pauses, before the answers)",
        p.file,
        p.name,
        p.stimuli.len(),
        p.blocks.len(),
        if p.blocks.len() == 1 { "" } else { "s" },
        if adaptive { "at most " } else { "" },
        trials,
        minutes,
        p.timing.explore_s,
        p.timing.pause_s
    );
    let mut blocks = Vec::new();
    for b in &p.blocks {
        let names = |ix: &[usize]| {
            ix.iter()
                .map(|&i| p.stimuli[i].name.clone())
                .collect::<Vec<_>>()
                .join(", ")
        };
        let (line, n) = match &b.design {
            Design::Paired {
                variant, stimuli, ..
            } => {
                let t = stimuli.len() as u32;
                let (n, who) = match variant {
                    PairedVariant::Ura => (t * (t - 1), String::new()),
                    PairedVariant::Nakaya => (t * (t - 1) / 2, String::new()),
                    // One pair a subject: a complete design needs a subject per pair.
                    PairedVariant::Scheffe => (
                        1,
                        format!("; a complete design takes a multiple of {} subjects", t * (t - 1)),
                    ),
                    PairedVariant::Haga => (
                        1,
                        format!(
                            "; a complete design takes a multiple of {} subjects ({} pairs in both orders)",
                            t * (t - 1),
                            t * (t - 1) / 2
                        ),
                    ),
                };
                (
                    format!(
                        "paired comparisons ({} variant) of {}: {n} trial{} per subject{who}",
                        variant.name(),
                        names(stimuli),
                        if n == 1 { "" } else { "s" }
                    ),
                    n,
                )
            }
            Design::Constant {
                standard,
                vary,
                levels,
                repeats,
            } => {
                let n = levels.len() as u32 * repeats;
                (
                    format!(
                        "constant stimuli on \"{}\", {vary} raised by {} ({repeats} each): {n} trials",
                        p.stimuli[*standard].name,
                        levels
                            .iter()
                            .map(|l| l.to_string())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                    n,
                )
            }
            Design::Staircase {
                standard,
                vary,
                tracks,
            } => {
                let n: u32 = tracks.iter().map(|t| t.max_trials.unwrap_or(0)).sum();
                (
                    format!(
                        "{} staircase{} on \"{}\"'s {vary} ({}): at most {n} trials",
                        tracks.len(),
                        if tracks.len() == 1 { "" } else { "s" },
                        p.stimuli[*standard].name,
                        tracks
                            .iter()
                            .map(|t| format!(
                                "{}: {}-down-{}-up from {}",
                                t.name, t.down, t.up, t.start
                            ))
                            .collect::<Vec<_>>()
                            .join("; ")
                    ),
                    n,
                )
            }
        };
        text += &format!("\n  block \"{}\": {line}", b.name);
        blocks.push(json!({"name": b.name, "design": b.design.name(), "trials": n}));
    }
    Ok(Done {
        text,
        json: json!({
            "file": p.file,
            "name": p.name,
            "stimuli": p.stimuli.iter().map(|s| s.name.clone()).collect::<Vec<_>>(),
            "blocks": blocks,
            "trials_per_subject": trials,
            "trials_are_a_limit": adaptive,
            "minutes_per_subject": minutes,
        }),
    })
}
