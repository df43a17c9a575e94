//! A session on disk: the append-only log (JSON lines, one per trial, flushed and synced before
//! the next trial begins) and the outputs rewritten from it after every trial — the tidy CSV
//! (a row per trial) and the JSON sidecar. A `kill -9`, a crash or a pulled board loses at
//! most the trial in progress; resuming replays the log's responses into the runner.
//!
//! This is the crate's I/O, apart from the analysis (which reads the CSV's rows as data).

use std::fs::{self, File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use nix::fcntl::{Flock, FlockArg};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::exploration::Exploration;
use crate::runner::{Outcome, Runner};

/// One interval as it was shown.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Shown {
    /// The stimulus' name.
    pub stimulus: String,
    /// The scene id the board confirmed it runs (None: an external object).
    pub scene_id: Option<u32>,
    /// The board's time when the exploration window opened and closed, µs since boot.
    pub board_from_us: Option<u64>,
    /// See `board_from_us`.
    pub board_to_us: Option<u64>,
    /// What the finger did in the window (None: not measured, as for an external object).
    pub exploration: Option<Exploration>,
}

/// A trial as logged.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialRecord {
    /// 0-based over the session.
    pub number: u32,
    /// The block's name.
    pub block: String,
    /// `paired`, `constant` or `staircase`.
    pub design: String,
    /// The staircase track.
    pub track: Option<String>,
    /// The level added to the standard.
    pub level: Option<f64>,
    /// The comparison's interval (1 or 2).
    pub target: Option<u8>,
    /// The intervals in presentation order.
    pub shown: Vec<Shown>,
    /// The response value.
    pub response: i32,
    /// Its word.
    pub word: String,
    /// Two-interval designs: the comparison chosen.
    pub correct: Option<bool>,
    /// Staircases: a reversal at this trial.
    pub reversal: Option<bool>,
    /// When the first stimulus was presented (UTC, ISO 8601).
    pub started_utc: String,
    /// When the response was given.
    pub responded_utc: String,
    /// From the end of the last interval to the response, ms.
    pub response_ms: f64,
}

impl TrialRecord {
    /// A record of `outcome` with what was shown and when.
    pub fn new(
        outcome: &Outcome,
        shown: Vec<Shown>,
        started_utc: String,
        response_ms: f64,
    ) -> Self {
        TrialRecord {
            number: outcome.trial.number,
            block: outcome.trial.block.clone(),
            design: outcome.trial.design.to_string(),
            track: outcome.trial.track.clone(),
            level: outcome.trial.level,
            target: outcome.trial.target,
            shown,
            response: outcome.response,
            word: outcome.word.clone(),
            correct: outcome.correct,
            reversal: outcome.reversal,
            started_utc,
            responded_utc: now_utc(),
            response_ms,
        }
    }
}

/// The session's first log line: what was run, for whom, on what.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The experiment's name.
    pub experiment: String,
    /// The protocol file as given.
    pub protocol_file: String,
    /// Its text, whole (the sidecar keeps it: the log says exactly what was run).
    pub protocol_text: String,
    /// The protocol's seed.
    pub seed: u64,
    /// The subject's id.
    pub subject: String,
    /// The subject's index (counterbalancing).
    pub subject_index: u32,
    /// The order seed (the protocol's with the subject's).
    pub order_seed: u64,
    /// The blocks in this subject's order.
    pub block_order: Vec<String>,
    /// When the session began (UTC, ISO 8601).
    pub started_utc: String,
    /// The board: its identity, firmware and protocol versions as its hello gave them.
    pub board: Value,
    /// The program that ran it (`saw 0.1.0`, `sawlink 0.1.0`).
    pub runner: String,
}

impl Header {
    /// The header of a session of `runner`, on `board` (its hello as JSON).
    pub fn new(runner: &Runner, board: Value, program: &str) -> Self {
        let p = runner.protocol();
        Header {
            experiment: p.name.clone(),
            protocol_file: p.file.clone(),
            protocol_text: p.text.clone(),
            seed: p.seed,
            subject: runner.subject().to_string(),
            subject_index: runner.subject_index(),
            order_seed: runner.seed(),
            block_order: runner.block_order(),
            started_utc: now_utc(),
            board,
            runner: program.to_string(),
        }
    }
}

/// The time now, UTC, ISO 8601 with milliseconds (`2026-11-29T05:31:02.123Z`).
pub fn now_utc() -> String {
    chrono::Utc::now().to_rfc3339_opts(chrono::SecondsFormat::Millis, true)
}

/// A session's files in `dir`: `<subject>.log.jsonl`, `<subject>.csv`, `<subject>.json`.
#[derive(Clone, Debug)]
pub struct Paths {
    /// The append-only log.
    pub log: PathBuf,
    /// The tidy CSV.
    pub csv: PathBuf,
    /// The JSON sidecar.
    pub sidecar: PathBuf,
}

impl Paths {
    /// The files of `subject`'s session in `dir`.
    pub fn new(dir: &Path, subject: &str) -> Self {
        Paths {
            log: dir.join(format!("{subject}.log.jsonl")),
            csv: dir.join(format!("{subject}.csv")),
            sidecar: dir.join(format!("{subject}.json")),
        }
    }
}

/// A subject id usable as a file name: letters, digits, `-`, `_` and `.`, 1–64 characters.
pub fn check_subject(id: &str) -> Result<(), String> {
    let ok = !id.is_empty()
        && id.len() <= 64
        && !id.starts_with('.')
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "--subject {id:?} must be 1 to 64 letters, digits, '-', '_' or '.' (it names the session's files), not starting with '.'"
        ))
    }
}

/// The subject's index for a session in `dir`: `given`, or on resume the index the session
/// began with (a different one given is refused: the orders follow it), or for a new session
/// the number of sessions already in `dir` — except where the protocol has Scheffé's or Haga's
/// variant, whose pair per subject follows the index: there it must be given (counting files
/// repeats or skips one when two booths start at once or a pilot is thrown away).
pub fn subject_index(
    protocol: &crate::protocol::Protocol,
    given: Option<u32>,
    resumed: Option<&Header>,
    dir: &Path,
) -> Result<u32, String> {
    use crate::protocol::{Design, PairedVariant};
    if let Some(h) = resumed {
        return match given {
            Some(i) if i != h.subject_index => Err(format!(
                "subject index {i} differs from the {} the session began with; a resumed session keeps its index (its orders follow it)",
                h.subject_index
            )),
            _ => Ok(h.subject_index),
        };
    }
    if let Some(i) = given {
        return Ok(i);
    }
    let one_pair = protocol.blocks.iter().any(|b| {
        matches!(
            b.design,
            Design::Paired {
                variant: PairedVariant::Scheffe | PairedVariant::Haga,
                ..
            }
        )
    });
    if one_pair {
        return Err(
            "the subject index is required: in Scheffé's and Haga's variants it picks the pair the subject judges (0 for the study's first subject, 1 for the next, …)"
                .into(),
        );
    }
    Ok(std::fs::read_dir(dir).map_or(0, |d| {
        d.filter_map(Result::ok)
            .filter(|e| e.file_name().to_string_lossy().ends_with(".log.jsonl"))
            .count() as u32
    }))
}

/// An open session log.
#[derive(Debug)]
pub struct Log {
    paths: Paths,
    /// The log, locked (flock) while this session holds it: a second runner for the subject is
    /// refused rather than interleaving its trials.
    file: Flock<File>,
    header: Header,
    records: Vec<TrialRecord>,
}

/// A log read back: its header and trials.
#[derive(Clone, Debug)]
pub struct Read {
    /// The header.
    pub header: Header,
    /// The trials, in order.
    pub records: Vec<TrialRecord>,
    /// Bytes of a last line cut short (a kill mid-write), dropped.
    pub torn_bytes: usize,
}

/// Reads a log: a last line without its newline (cut by a kill mid-write) is dropped, any
/// other bad line refused with its line number.
pub fn read_log(path: &Path) -> Result<Read, String> {
    let f = File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut header: Option<Header> = None;
    let mut records = Vec::new();
    let mut torn_bytes = 0;
    let mut reader = BufReader::new(f);
    let mut line = String::new();
    let mut n = 0;
    loop {
        line.clear();
        let got = reader
            .read_line(&mut line)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        if got == 0 {
            break;
        }
        n += 1;
        if !line.ends_with('\n') {
            torn_bytes = got;
            break;
        }
        let v: Value = serde_json::from_str(&line)
            .map_err(|e| format!("{}:{n}: not a log line: {e}", path.display()))?;
        match v.get("kind").and_then(Value::as_str) {
            Some("session") if header.is_none() => {
                header = Some(
                    serde_json::from_value(v["session"].clone())
                        .map_err(|e| format!("{}:{n}: session header: {e}", path.display()))?,
                )
            }
            Some("trial") if header.is_some() => records.push(
                serde_json::from_value(v["trial"].clone())
                    .map_err(|e| format!("{}:{n}: trial: {e}", path.display()))?,
            ),
            _ => {
                return Err(format!(
                    "{}:{n}: a line of no kind this log expects here (a session header first, then trials)",
                    path.display()
                ))
            }
        }
    }
    let header =
        header.ok_or_else(|| format!("{}: the log has no session header", path.display()))?;
    Ok(Read {
        header,
        records,
        torn_bytes,
    })
}

impl Log {
    /// Starts a new session's log; refused when the subject already has one in `dir`.
    pub fn create(dir: &Path, header: Header) -> Result<Self, String> {
        let paths = Paths::new(dir, &header.subject);
        fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let exists = || {
            format!(
                "{} exists: subject {} has a session here already (--resume continues it)",
                paths.log.display(),
                header.subject
            )
        };
        if paths.log.exists() {
            return Err(exists());
        }
        // The header is written and synced under a temporary name, then linked to the log's
        // name (which fails if it exists): a log either has its whole header or is not there,
        // whatever kill comes between.
        let tmp = paths.log.with_extension("jsonl.new");
        let line = json!({"kind": "session", "session": header}).to_string();
        let io = |e: std::io::Error| format!("{}: {e}", paths.log.display());
        {
            let mut f = File::create(&tmp).map_err(io)?;
            writeln!(f, "{line}")
                .and_then(|_| f.sync_all())
                .map_err(io)?;
        }
        let linked = fs::hard_link(&tmp, &paths.log);
        let _ = fs::remove_file(&tmp);
        linked.map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                exists()
            } else {
                io(e)
            }
        })?;
        let file = lock(
            OpenOptions::new()
                .append(true)
                .open(&paths.log)
                .map_err(io)?,
            &paths.log,
        )?;
        let log = Log {
            paths,
            file,
            header,
            records: Vec::new(),
        };
        log.write_outputs()?;
        Ok(log)
    }

    /// Reopens `subject`'s log in `dir` to continue it: a torn last line is cut off, and the
    /// CSV and sidecar are rewritten (a kill between a trial's sync and their rename left them
    /// one trial behind).
    pub fn resume(dir: &Path, subject: &str) -> Result<Self, String> {
        let paths = Paths::new(dir, subject);
        if !paths.log.exists() {
            return Err(format!(
                "{}: no session of subject {subject} to resume (run without --resume to begin one)",
                paths.log.display()
            ));
        }
        let io = |e: std::io::Error| format!("{}: {e}", paths.log.display());
        // Locked before it is read: another runner cannot append between the read and ours.
        let file = lock(
            OpenOptions::new()
                .append(true)
                .open(&paths.log)
                .map_err(io)?,
            &paths.log,
        )?;
        let read = read_log(&paths.log)?;
        if read.header.subject != subject {
            return Err(format!(
                "{}: the log is subject {:?}'s, not {subject}'s",
                paths.log.display(),
                read.header.subject
            ));
        }
        if read.torn_bytes > 0 {
            let len = file.metadata().map_err(io)?.len();
            file.set_len(len.saturating_sub(read.torn_bytes as u64))
                .map_err(io)?;
        }
        let log = Log {
            paths,
            file,
            header: read.header,
            records: read.records,
        };
        log.write_outputs()?;
        Ok(log)
    }

    /// The header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The trials logged.
    pub fn records(&self) -> &[TrialRecord] {
        &self.records
    }

    /// The files.
    pub fn paths(&self) -> &Paths {
        &self.paths
    }

    /// What a resume replays: each trial's number, stimuli and response.
    pub fn replay(&self) -> Vec<(u32, Vec<String>, i32)> {
        self.records
            .iter()
            .map(|r| {
                (
                    r.number,
                    r.shown.iter().map(|s| s.stimulus.clone()).collect(),
                    r.response,
                )
            })
            .collect()
    }

    /// Appends a trial: written, flushed and synced before this returns, then the CSV and
    /// sidecar rewritten from the log.
    pub fn append(&mut self, record: TrialRecord) -> Result<(), String> {
        let line = json!({"kind": "trial", "trial": record}).to_string() + "\n";
        let io = |e: std::io::Error| format!("{}: {e}", self.paths.log.display());
        let before = self.file.metadata().map_err(io)?.len();
        // One write of the whole line, then the sync; on any failure the file is cut back to
        // where it was, so a retry neither glues onto half a line nor logs the trial twice.
        if let Err(e) = self
            .file
            .write_all(line.as_bytes())
            .and_then(|_| self.file.sync_data())
        {
            let _ = self.file.set_len(before);
            return Err(io(e));
        }
        self.records.push(record);
        self.write_outputs()
    }

    /// Rewrites the CSV and the sidecar (each to a temporary file renamed over the old one, so
    /// a reader never sees half of one).
    pub fn write_outputs(&self) -> Result<(), String> {
        write_atomic(&self.paths.csv, &csv(&self.header, &self.records))?;
        let sidecar = sidecar(&self.header, &self.records);
        write_atomic(
            &self.paths.sidecar,
            &(serde_json::to_string_pretty(&sidecar).unwrap_or_default() + "\n"),
        )
    }
}

/// Takes the session's lock on its log, or says who holds it.
fn lock(file: File, path: &Path) -> Result<Flock<File>, String> {
    Flock::lock(file, FlockArg::LockExclusiveNonblock).map_err(|(_, e)| {
        format!(
            "{}: another runner has this session open ({e}); one session of a subject at a time",
            path.display()
        )
    })
}

fn write_atomic(path: &Path, text: &str) -> Result<(), String> {
    // Each output its own temporary name (the CSV's and the sidecar's differ).
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    fs::write(&tmp, text)
        .and_then(|_| fs::rename(&tmp, path))
        .map_err(|e| format!("{}: {e}", path.display()))
}

/// The tidy CSV's columns, in order (docs/experiment.md, "The session CSV"). Per interval
/// (`1_`, `2_`): the stimulus, the scene id the board confirmed, and the exploration.
pub const CSV_COLUMNS: &[&str] = &[
    "subject",
    "subject_index",
    "trial",
    "block",
    "design",
    "track",
    "level",
    "target_interval",
    "first",
    "second",
    "response",
    "response_word",
    "score",
    "correct",
    "reversal",
    "started_utc",
    "responded_utc",
    "response_ms",
    "first_scene_id",
    "first_board_from_us",
    "first_explored_s",
    "first_strokes",
    "first_mean_speed_mm_s",
    "first_peak_speed_mm_s",
    "first_distance_mm",
    "first_f_b_hz",
    "first_faults",
    "second_scene_id",
    "second_board_from_us",
    "second_explored_s",
    "second_strokes",
    "second_mean_speed_mm_s",
    "second_peak_speed_mm_s",
    "second_distance_mm",
    "second_f_b_hz",
    "second_faults",
];

/// A CSV field: quoted when it holds a comma, a quote or a line break.
fn field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// A number as the CSV writes it: Rust's shortest round-trip form, `.` as the decimal point
/// whatever the locale.
fn num(v: f64) -> String {
    format!("{v}")
}

/// The session's tidy CSV.
pub fn csv(h: &Header, records: &[TrialRecord]) -> String {
    let mut out = CSV_COLUMNS.join(",") + "\n";
    for r in records {
        let opt = |v: Option<String>| v.unwrap_or_default();
        let mut row: Vec<String> = vec![
            field(&h.subject),
            h.subject_index.to_string(),
            r.number.to_string(),
            field(&r.block),
            r.design.clone(),
            opt(r.track.as_deref().map(field)),
            opt(r.level.map(num)),
            opt(r.target.map(|t| t.to_string())),
            field(r.shown.first().map_or("", |s| &s.stimulus)),
            field(r.shown.get(1).map_or("", |s| &s.stimulus)),
            r.response.to_string(),
            field(&r.word),
            // Paired comparisons' score is the response; two-interval designs have none.
            if r.design == "paired" {
                r.response.to_string()
            } else {
                String::new()
            },
            opt(r.correct.map(|c| u8::from(c).to_string())),
            opt(r.reversal.map(|c| u8::from(c).to_string())),
            r.started_utc.clone(),
            r.responded_utc.clone(),
            num(r.response_ms),
        ];
        for k in 0..2 {
            let s = r.shown.get(k);
            let e = s.and_then(|s| s.exploration.as_ref());
            row.push(opt(s
                .and_then(|s| s.scene_id)
                .map(|id| format!("{id:#010x}"))));
            row.push(opt(s.and_then(|s| s.board_from_us).map(|t| t.to_string())));
            row.push(opt(e.map(|e| num(e.explored_s))));
            row.push(opt(e.map(|e| e.strokes.to_string())));
            row.push(opt(e.map(|e| num(e.mean_speed_mm_s))));
            row.push(opt(e.map(|e| num(e.peak_speed_mm_s))));
            row.push(opt(e.map(|e| num(e.distance_mm))));
            row.push(opt(e.map(|e| num(e.f_b_hz))));
            row.push(opt(e.map(|e| e.faults.to_string())));
        }
        out += &row.join(",");
        out.push('\n');
    }
    out
}

/// The sidecar: the header, the format's version and the scene ids each stimulus ran as.
pub fn sidecar(h: &Header, records: &[TrialRecord]) -> Value {
    let mut scenes = serde_json::Map::new();
    for s in records.iter().flat_map(|r| r.shown.iter()) {
        if let Some(id) = s.scene_id {
            scenes
                .entry(s.stimulus.clone())
                .or_insert_with(|| json!(format!("{id:#010x}")));
        }
    }
    json!({
        "format": "saw-experiment session 1",
        "session": h,
        "trials": records.len(),
        "scene_ids": scenes,
    })
}

/// Reads the files an analysis is given — session CSVs (with the sidecar beside each, which
/// tells each block's stimulus order, variant and threshold rule into `opts`) or a lab's own
/// CSVs — into one data set; `saw experiment analyze` and the Python module's `analyze` both
/// read through here. A file named twice, one that cannot be read, and a set with no trials
/// are refused with a sentence.
pub fn read_for_analysis(
    files: &[PathBuf],
    opts: &mut crate::analysis::report::Options,
) -> Result<crate::analysis::input::Dataset, String> {
    use crate::analysis::input::{read_csv, sidecar_options, Dataset};
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    };
    let mut data = Dataset::default();
    for (k, f) in files.iter().enumerate() {
        let name = f.display().to_string();
        // The same file twice would read as every judgment made twice.
        if files[..k].iter().any(|g| same(f, g)) {
            return Err(format!("{name} is given twice; each file is read once"));
        }
        let text = fs::read_to_string(f).map_err(|e| format!("{name}: {e}"))?;
        read_csv(&name, &text, &mut data).map_err(|e| e.to_string())?;
        if let Ok(s) = fs::read_to_string(f.with_extension("json")) {
            sidecar_options(&s, opts);
        }
    }
    if data.paired.is_empty() && data.intervals.is_empty() {
        return Err(format!(
            "{}: no trials to analyse",
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    Ok(data)
}
