//! `sawlink.Experiment` and `sawlink.analyze`: the experiment crate's runner, session log and
//! analysis from Python, so a PsychoPy script runs a protocol's trials itself — the runner
//! hands it the next trial, the script presents it (on the board through `present`, or by its
//! own means) and hands back the response, which is checked, logged and synced here — or
//! analyses data it recorded. Order, progress, the log, the CSV and the analysis are
//! `saw_experiment`'s, as for `saw experiment run` and `analyze`; this only converts at the
//! door (docs/experiment-python.md).
//!
//! ```python
//! exp = sawlink.Experiment("experiments/nara-roughness.toml", "s01", "sessions", board=board)
//! while (trial := exp.next_trial()) is not None:
//!     for k in range(len(trial["intervals"])):
//!         exp.present(k)
//!     exp.respond(ask(trial["question"], trial["words"], trial["values"]))
//! ```

use std::path::PathBuf;
use std::time::{Duration, Instant};

use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyInt, PyTuple};
use saw_experiment::analysis::paired::Variant;
use saw_experiment::analysis::report::{self, Options};
use saw_experiment::exploration;
use saw_experiment::protocol;
use saw_experiment::runner::{Runner, RunnerError};
use saw_experiment::session::{self, Header, Log, Shown, TrialRecord};
use serde_json::{json, Value};

use crate::{input, stalled, to_python, whole_in, Board, SawError};

create_exception!(
    sawlink,
    ExperimentError,
    SawError,
    "A protocol, a session log or a data file refused, or the session's files not written: the experiment crate's own sentence."
);

/// Bootstrap resamples of the psychometric fits.
const BOOTSTRAP: (i64, i64) = (0, 100_000);
/// Subject indices, as `saw experiment run --subject-index`.
const SUBJECT_INDEX: (i64, i64) = (0, 100_000);
/// Stream decimation while a stimulus is explored: 1 kHz on a 10 kHz board, as `saw
/// experiment run` (well within the line: docs/link.md).
const EXPLORE_EVERY: u16 = 10;
/// The program the session header names.
const PROGRAM: &str = concat!("sawlink ", env!("CARGO_PKG_VERSION"));

fn refused(msg: impl std::fmt::Display) -> PyErr {
    ExperimentError::new_err(msg.to_string())
}

/// The crate's sentences name `saw experiment run`'s flags; here they are arguments.
fn pythonic(msg: String) -> String {
    msg.replace("--subject ", "subject ")
        .replace(
            "run without --resume",
            "make the Experiment without resume=True",
        )
        .replace("--resume continues", "resume=True continues")
        .replace("--resume", "resume=True")
}

/// Waits `d` with the GIL released, in slices, so Ctrl-C raises `KeyboardInterrupt`.
fn sleep(py: Python<'_>, d: Duration) -> PyResult<()> {
    let end = Instant::now() + d;
    loop {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Ok(());
        }
        py.allow_threads(|| std::thread::sleep(left.min(Duration::from_millis(50))));
        py.check_signals()?;
    }
}

/// A protocol run with one participant: the runner and its log (`<subject>.log.jsonl`, `.csv`,
/// `.json` in `out_dir`), and the board the stimuli are presented on, if any.
#[pyclass(module = "sawlink")]
pub struct Experiment {
    runner: Runner,
    log: Log,
    board: Option<Py<Board>>,
    /// What `present` showed of the pending trial, per interval.
    shown: Vec<Option<Shown>>,
    /// When the pending trial's first interval was presented (UTC).
    started_utc: Option<String>,
    /// When `next_trial` first handed the pending trial out.
    handed_out: Option<Instant>,
    /// When the last interval presented ended, or the last response was taken: the protocol's
    /// pause counts from it.
    last_end: Option<Instant>,
    /// Whether an interval of the pending trial was presented (a response's time counts from
    /// the last one's end).
    presented: bool,
}

impl Experiment {
    fn board_mut<'py>(&self, py: Python<'py>, k: usize) -> PyResult<PyRefMut<'py, Board>> {
        let board = self.board.as_ref().ok_or_else(|| {
            refused(format!(
                "interval {k} is a scene for the board and this Experiment has no board: give board=sawlink.Board(port) when making it, or present the trial yourself and only respond"
            ))
        })?;
        board
            .bind(py)
            .try_borrow_mut()
            .map_err(|_| SawError::new_err("the board is in use by another call"))
    }

    /// Resets the per-trial state for the trial now pending.
    fn next_pending(&mut self) {
        let n = self.runner.next_trial().map_or(0, |t| t.intervals.len());
        self.shown = vec![None; n];
        self.started_utc = None;
        self.handed_out = None;
        self.presented = false;
    }
}

/// Loads a scene's text on the board: the id it confirmed (a refusal raises `Refused`, located
/// in the scene as `saw push` does).
fn load(py: Python<'_>, b: &mut Board, what: &str, text: &str) -> PyResult<u32> {
    let wait = b.timeout;
    b.push_text(py, what, text, wait)
}

/// Streams `seconds` of telemetry: the records of scene `scene_id` sampled in the window and
/// the board's time at the window's start. The stream is stopped whatever happens.
fn explore(
    py: Python<'_>,
    b: &mut Board,
    seconds: f64,
    scene_id: u32,
) -> PyResult<(Vec<saw_link::msg::Record>, u64)> {
    let wait = b.timeout;
    let start = b.start_stream(py, EXPLORE_EVERY)?;
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut records = Vec::new();
    let outcome = (|| loop {
        let now = Instant::now();
        if now >= end {
            return Ok(());
        }
        match b.next_frame(py, end.min(now + wait))? {
            // Only the stimulus' own scene: the client already drops records from before the
            // stream started; this also holds if a scene change raced the window.
            Some((_, s)) => {
                records.extend(s.records.into_iter().filter(|r| r.scene_id == scene_id))
            }
            None if Instant::now() >= end => return Ok(()),
            None => return Err(stalled(wait)),
        }
        py.check_signals()?;
    })();
    let stopped = b.stop_stream(py);
    outcome?;
    stopped?;
    Ok((records, start.from_us))
}

#[pymethods]
impl Experiment {
    /// Begins (or with `resume=True` continues) `subject`'s session of the protocol file
    /// `protocol_path`, its files in `out_dir`. `subject_index` (0 for a study's first subject)
    /// counterbalances orders; by default the number of sessions already in `out_dir` (on
    /// resume: the log's). `board`: a `sawlink.Board` for `present`.
    #[new]
    #[pyo3(signature = (protocol_path, subject, out_dir, subject_index = None, resume = false, board = None))]
    fn new(
        py: Python<'_>,
        protocol_path: PathBuf,
        subject: &str,
        out_dir: PathBuf,
        subject_index: Option<i64>,
        resume: bool,
        board: Option<Py<Board>>,
    ) -> PyResult<Self> {
        session::check_subject(subject).map_err(|e| input(pythonic(e)))?;
        let index = subject_index
            .map(|i| whole_in("subject_index", i, SUBJECT_INDEX).map(|i| i as u32))
            .transpose()?;
        let protocol = protocol::load(&protocol_path).map_err(refused)?;
        let board_json = match &board {
            None => Value::Null,
            Some(b) => {
                let b = b.bind(py).borrow();
                if b.client.is_none() {
                    return Err(SawError::new_err(format!(
                        "the board on {} is closed: open a new Board",
                        b.port.display()
                    )));
                }
                let h = &b.hello;
                json!({
                    "board": h.board.as_str(),
                    "firmware": h.firmware.as_str(),
                    "protocol": h.protocol,
                    "sample_rate_hz": h.sample_rate_hz,
                    "scene_id_at_start": format!("{:#010x}", h.scene_id),
                })
            }
        };
        let (runner, log) = if resume {
            let log = Log::resume(&out_dir, subject).map_err(|e| refused(pythonic(e)))?;
            if log.header().protocol_text != protocol.text {
                return Err(refused(format!(
                    "{}: the protocol file differs from the one this session began with (kept in {}); resume with that file",
                    protocol.file,
                    log.paths().log.display()
                )));
            }
            let index = session::subject_index(&protocol, index, Some(log.header()), &out_dir)
                .map_err(|e| refused(format!("subject_index: {e}")))?;
            let runner =
                Runner::resume(protocol, subject, index, &log.replay()).map_err(refused)?;
            (runner, log)
        } else {
            let index = session::subject_index(&protocol, index, None, &out_dir)
                .map_err(|e| refused(format!("subject_index: {e}")))?;
            let runner = Runner::new(protocol, subject, index).map_err(refused)?;
            let header = Header::new(&runner, board_json, PROGRAM);
            let log = Log::create(&out_dir, header).map_err(|e| refused(pythonic(e)))?;
            (runner, log)
        };
        let mut e = Experiment {
            runner,
            log,
            board,
            shown: Vec::new(),
            started_utc: None,
            handed_out: None,
            last_end: None,
            presented: false,
        };
        e.next_pending();
        Ok(e)
    }

    /// The trial awaiting a response (the same until it is answered), or None when the session
    /// is over: `{"number", "block", "block_number", "design", "intervals": [{"stimulus",
    /// "prompt", "beta_um"}], "question", "words", "values", "track", "level", "target",
    /// "break_before"}`. An interval's `prompt` is what the experimenter hands over (an
    /// external object), None for a scene on the board.
    fn next_trial(&mut self, py: Python<'_>) -> PyResult<Option<PyObject>> {
        match self.runner.next_trial() {
            None => Ok(None),
            Some(t) => {
                self.handed_out.get_or_insert_with(Instant::now);
                to_python(py, t).map(Some)
            }
        }
    }

    /// Presents interval `k` (0-based) of the pending trial: a scene is loaded on the board and
    /// the finger's exploration streamed for the protocol's `explore_s`; an external object's
    /// window is timed with the board's RF off. Not sooner than `pause_s` after the previous
    /// interval (or response). With `rf_off_between` the RF-off scene follows. Returns the
    /// exploration: `{"interval", "stimulus", "scene_id", "board_from_us", "board_to_us",
    /// "records", "explored_s", "strokes", "mean_speed_mm_s", "peak_speed_mm_s",
    /// "distance_mm", "f_b_hz", "faults"}` (None for what an external object does not give).
    /// Presenting an interval again replaces what is logged for it.
    fn present(&mut self, py: Python<'_>, k: i64) -> PyResult<PyObject> {
        let trial = self
            .runner
            .next_trial()
            .cloned()
            .ok_or_else(|| refused(RunnerError::Finished))?;
        let n = trial.intervals.len();
        if k < 0 || k as usize >= n {
            return Err(input(format!(
                "k = {k}: trial {} has {n} intervals, 0 to {}",
                trial.number,
                n - 1
            )));
        }
        let k = k as usize;
        let iv = &trial.intervals[k];
        let timing = self.runner.protocol().timing;
        let off_scene = self.runner.protocol().off_scene.clone();
        if let Some(last) = self.last_end {
            sleep(
                py,
                Duration::from_secs_f64(timing.pause_s).saturating_sub(last.elapsed()),
            )?;
        }
        let started = session::now_utc();
        let mut s = Shown {
            stimulus: iv.stimulus.clone(),
            ..Shown::default()
        };
        match &iv.scene {
            Some(text) => {
                let mut b = self.board_mut(py, k)?;
                let id = load(py, &mut b, &iv.stimulus, text)?;
                let (records, from_us) = explore(py, &mut b, timing.explore_s, id)?;
                s.scene_id = Some(id);
                s.board_from_us = Some(from_us);
                s.board_to_us = records.last().map(|r| r.time_us);
                s.exploration = Some(exploration::summarize(&records));
                if timing.rf_off_between {
                    load(py, &mut b, "the RF-off scene", &off_scene)?;
                }
            }
            None => {
                // An object handed over: the board's RF off while it is explored.
                if self.board.is_some() {
                    let mut b = self.board_mut(py, k)?;
                    load(py, &mut b, "the RF-off scene", &off_scene)?;
                }
                sleep(py, Duration::from_secs_f64(timing.explore_s))?;
            }
        }
        let mut out = json!({
            "interval": k,
            "stimulus": s.stimulus,
            "scene_id": s.scene_id,
            "board_from_us": s.board_from_us,
            "board_to_us": s.board_to_us,
        });
        let summary = match &s.exploration {
            Some(e) => serde_json::to_value(e).unwrap_or_default(),
            None => json!({
                "records": null, "explored_s": null, "strokes": null, "mean_speed_mm_s": null,
                "peak_speed_mm_s": null, "distance_mm": null, "f_b_hz": null, "faults": null,
            }),
        };
        if let (Some(o), Value::Object(m)) = (out.as_object_mut(), summary) {
            // The window's scene ids are the board's confirmation; `scene_id` says it once.
            o.extend(m.into_iter().filter(|(key, _)| key != "scene_ids"));
        }
        self.started_utc.get_or_insert(started);
        self.shown[k] = Some(s);
        self.presented = true;
        self.last_end = Some(Instant::now());
        to_python(py, &out)
    }

    /// Answers the pending trial with `value` (one of the trial's `values`), logs it — with what
    /// `present` showed, or only the stimuli' names for intervals the script presented itself —
    /// and syncs the log before returning. `response_ms`: the response time the script
    /// measured (default: from the end of the last interval presented, or from when
    /// `next_trial` handed the trial out). A value the trial does not allow raises ValueError
    /// and changes nothing. Returns `{"trial", "response", "word", "correct", "reversal"}`.
    #[pyo3(signature = (value, response_ms = None))]
    fn respond(
        &mut self,
        py: Python<'_>,
        value: &Bound<'_, PyAny>,
        response_ms: Option<f64>,
    ) -> PyResult<PyObject> {
        let trial = self
            .runner
            .next_trial()
            .cloned()
            .ok_or_else(|| refused(RunnerError::Finished))?;
        let not_allowed = |shown: String| {
            PyValueError::new_err(format!(
                "response {shown} is not one this trial allows (it takes {})",
                trial
                    .values
                    .iter()
                    .map(|v| v.to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        };
        if !value.is_instance_of::<PyInt>() || value.is_instance_of::<PyBool>() {
            return Err(not_allowed(format!(
                "{} (a {}, not an int)",
                value.repr()?,
                value.get_type().name()?
            )));
        }
        let value: i32 = value
            .extract::<i64>()
            .ok()
            .and_then(|v| i32::try_from(v).ok())
            .ok_or_else(|| not_allowed(value.to_string()))?;
        if let Some(ms) = response_ms {
            if !ms.is_finite() || ms < 0.0 {
                return Err(input(format!(
                    "response_ms = {ms}: must be a finite number of ms from 0"
                )));
            }
        }
        let now = Instant::now();
        let response_ms = response_ms.unwrap_or_else(|| {
            let from = if self.presented {
                self.last_end
            } else {
                self.handed_out
            };
            from.map_or(0.0, |t| now.duration_since(t).as_secs_f64() * 1e3)
        });
        let before = self.runner.clone();
        let outcome = self.runner.respond(value).map_err(|e| match e {
            RunnerError::Response { .. } => PyValueError::new_err(e.to_string()),
            other => refused(other),
        })?;
        let shown: Vec<Shown> = trial
            .intervals
            .iter()
            .zip(&self.shown)
            .map(|(iv, s)| {
                s.clone().unwrap_or_else(|| Shown {
                    stimulus: iv.stimulus.clone(),
                    ..Shown::default()
                })
            })
            .collect();
        let started = self.started_utc.clone().unwrap_or_else(session::now_utc);
        let logged = self.log.records().len();
        if let Err(e) = self
            .log
            .append(TrialRecord::new(&outcome, shown, started, response_ms))
        {
            if self.log.records().len() == logged {
                // Not in the log: the trial is still pending, as if never answered.
                self.runner = before;
                return Err(refused(format!(
                    "{e}: trial {} was not logged and is still the one to answer",
                    trial.number
                )));
            }
            self.next_pending();
            self.last_end = Some(now);
            return Err(refused(format!(
                "{e}: trial {} is in the log (synced); its CSV and sidecar are rewritten after the next trial",
                trial.number
            )));
        }
        self.next_pending();
        self.last_end = Some(now);
        to_python(py, &outcome)
    }

    /// Loads the protocol's RF-off scene on the board (between blocks, at a break, at the end).
    /// Returns its scene id.
    fn rf_off(&mut self, py: Python<'_>) -> PyResult<u32> {
        let off_scene = self.runner.protocol().off_scene.clone();
        if self.board.is_none() {
            return Err(refused(
                "rf_off: this Experiment has no board (give board=sawlink.Board(port) when making it)",
            ));
        }
        let mut b = self.board_mut(py, 0)?;
        load(py, &mut b, "the RF-off scene", &off_scene)
    }

    /// Trials answered (those of earlier runs of a resumed session included).
    #[getter]
    fn answered(&self) -> u32 {
        self.runner.answered()
    }

    /// Trials a session of this protocol has (staircases: their trial limits).
    #[getter]
    fn planned_trials(&self) -> u32 {
        self.runner.planned_trials()
    }

    /// Every trial has a response.
    #[getter]
    fn finished(&self) -> bool {
        self.runner.next_trial().is_none()
    }

    /// The tidy CSV, a row per trial, rewritten after every response.
    #[getter]
    fn csv_path(&self) -> PathBuf {
        self.log.paths().csv.clone()
    }

    /// The append-only log (JSON lines): what a resume replays.
    #[getter]
    fn log_path(&self) -> PathBuf {
        self.log.paths().log.clone()
    }

    /// The JSON sidecar: the session header and the scene id each stimulus ran as.
    #[getter]
    fn sidecar_path(&self) -> PathBuf {
        self.log.paths().sidecar.clone()
    }

    /// The participant's id.
    #[getter]
    fn subject(&self) -> String {
        self.runner.subject().to_string()
    }

    /// The participant's index in the study.
    #[getter]
    fn subject_index(&self) -> u32 {
        self.runner.subject_index()
    }

    /// The experiment's name.
    #[getter]
    fn name(&self) -> String {
        self.runner.protocol().name.clone()
    }

    /// Shown before the first trial.
    #[getter]
    fn instructions(&self) -> String {
        self.runner.protocol().instructions.clone()
    }

    /// `{"explore_s", "pause_s", "rf_off_between"}`.
    #[getter]
    fn timing(&self, py: Python<'_>) -> PyResult<PyObject> {
        let t = self.runner.protocol().timing;
        to_python(
            py,
            &json!({"explore_s": t.explore_s, "pause_s": t.pause_s, "rf_off_between": t.rf_off_between}),
        )
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    /// Leaves the board with its RF off (if it has a board that is still open).
    #[pyo3(signature = (*exc))]
    fn __exit__(&mut self, py: Python<'_>, exc: &Bound<'_, PyTuple>) -> PyResult<bool> {
        let open = self
            .board
            .as_ref()
            .is_some_and(|b| b.bind(py).borrow().client.is_some());
        if open {
            let off = self.rf_off(py);
            // An exception in the block is the one to see; otherwise the board's refusal.
            if exc.get_item(0).is_ok_and(|e| e.is_none()) {
                off?;
            }
        }
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!(
            "Experiment({:?}, subject {:?}, {} of {} trials answered)",
            self.runner.protocol().name,
            self.runner.subject(),
            self.runner.answered(),
            self.runner.planned_trials()
        )
    }
}

/// Analyses CSV files — session CSVs an `Experiment` (or `saw experiment run`) wrote, or a
/// lab's own `subject,first,second,score` — as `saw experiment analyze` does, and returns the
/// report as `saw --json experiment analyze` prints it: `{"paired": [{"block", "subjects",
/// "judgments", "scheffe", "scale": {stimulus: value}, "thurstone", "bradley_terry"}],
/// "correlations", "tracks", "constant"}`. `files`: a path or a list of paths (a session's
/// sidecar beside its CSV gives the protocol's stimulus order). `method`: "scheffe", "ura",
/// "haga" or "nakaya" (default: each block's own, from the sidecar, else the one its data imply). `bootstrap`: resamples of the
/// constant-stimuli fits (0 to 100 000; 0 or 1: none).
#[pyfunction]
#[pyo3(signature = (files, method = None, bootstrap = 1000))]
fn analyze(
    py: Python<'_>,
    files: &Bound<'_, PyAny>,
    method: Option<&str>,
    bootstrap: i64,
) -> PyResult<PyObject> {
    let files: Vec<PathBuf> = match files.extract::<PathBuf>() {
        Ok(one) => vec![one],
        Err(_) => files.extract().map_err(|_| {
            input(format!(
                "files = {}: must be a path or a list of paths",
                files.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })?,
    };
    if files.is_empty() {
        return Err(input("files = []: name at least one CSV file".into()));
    }
    let method = match method {
        None => None,
        Some("scheffe") => Some(Variant::Scheffe),
        Some("ura") => Some(Variant::Ura),
        Some("haga") => Some(Variant::Haga),
        Some("nakaya") => Some(Variant::Nakaya),
        Some(other) => {
            return Err(input(format!(
                "method = {other:?}: must be \"scheffe\", \"ura\", \"haga\", \"nakaya\" or None (the variant the design implies)"
            )))
        }
    };
    let bootstrap = whole_in("bootstrap", bootstrap, BOOTSTRAP)? as u32;
    let mut opts = Options {
        method,
        bootstrap,
        ..Options::default()
    };
    let data = session::read_for_analysis(&files, &mut opts).map_err(refused)?;
    let report = py
        .allow_threads(|| report::analyze(&data, &opts))
        .map_err(refused)?;
    to_python(py, &report)
}

pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Experiment>()?;
    m.add_function(wrap_pyfunction!(analyze, m)?)?;
    m.add("ExperimentError", m.py().get_type::<ExperimentError>())?;
    Ok(())
}
