//! `sawlink`: the Python module over the link client (`saw_link::client::Client`). A thin layer:
//! the port is opened (and locked) by `saw::port`, scene files are read by
//! `saw_core::scene_file`, requests and replies are `saw_link`'s; this file only converts values
//! at the door and maps every failure to a typed Python exception carrying one sentence.
//!
//! ```python
//! import sawlink
//! with sawlink.Board("/tmp/saw-board", timeout_s=1.0) as board:
//!     board.push("scenes/grating.toml")
//!     rec = board.record(seconds=5, every=10)
//! ```

use std::collections::VecDeque;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use saw::port::{self, Port};
use saw_core::gate::DriveMode;
use saw_link::client::{Client, ClientError, StreamStart};
use saw_link::msg::{Header, Hello, Record, Reply, Request, PROTOCOL_VERSION};

mod experiment;

create_exception!(
    sawlink,
    SawError,
    PyException,
    "Every error this module raises: one sentence saying what went wrong and what to do."
);
create_exception!(
    sawlink,
    PortError,
    SawError,
    "The port could not be opened or failed."
);
create_exception!(
    sawlink,
    PortMissing,
    PortError,
    "No such port: the board is not plugged in (or no virtual board serves that path)."
);
create_exception!(
    sawlink,
    PortBusy,
    PortError,
    "Another program (a `saw`, the web panel, another Board) holds the port."
);
create_exception!(
    sawlink,
    NoAnswer,
    SawError,
    "The board did not answer within the call's timeout."
);
create_exception!(
    sawlink,
    ProtocolError,
    SawError,
    "The board speaks another protocol version, refused the request's frame or answered out of turn."
);
create_exception!(
    sawlink,
    Refused,
    SawError,
    "The board refused the change and nothing changed; `.sentence` is the board's own sentence."
);
create_exception!(
    sawlink,
    SaveFailed,
    SawError,
    "The save failed; the scene saved before (if any) is kept. `.sentence` is the board's."
);
create_exception!(
    sawlink,
    InputError,
    SawError,
    "A value refused before anything was sent: the argument, the value and the rule."
);

/// The least and most a call may wait for its answer, s (as `saw --timeout`: 10 to 60 000 ms).
const TIMEOUT_S: (f64, f64) = (0.01, 60.0);
/// Boundary positions, mm (as `saw boundary`).
const MM: (f64, f64) = (0.0, 1000.0);
/// A recording's length, s (as `saw stream --seconds`).
const SECONDS: (f64, f64) = (0.1, 86_400.0);
/// Decimation (as `saw stream --every`).
const EVERY: (i64, i64) = (1, 10_000);

fn input(msg: String) -> PyErr {
    InputError::new_err(msg)
}

/// A finite number in `lo..=hi`, or one line naming the argument, the value and the rule.
fn finite_in(name: &str, v: f64, (lo, hi): (f64, f64), unit: &str) -> PyResult<f64> {
    if !v.is_finite() || v < lo || v > hi {
        return Err(input(format!(
            "{name} = {v} {unit}: must be a finite number from {lo} to {hi} {unit}"
        )));
    }
    Ok(v)
}

fn whole_in(name: &str, v: i64, (lo, hi): (i64, i64)) -> PyResult<i64> {
    if v < lo || v > hi {
        return Err(input(format!(
            "{name} = {v}: must be a whole number from {lo} to {hi}"
        )));
    }
    Ok(v)
}

fn index_u8(name: &str, v: i64) -> PyResult<u8> {
    Ok(whole_in(name, v, (0, 255))? as u8)
}

/// A Python exception for a client failure.
fn link_err(e: ClientError) -> PyErr {
    let text = e.to_string();
    match e {
        ClientError::NoAnswer { .. } => NoAnswer::new_err(text),
        ClientError::Io(_) => PortError::new_err(text),
        _ => ProtocolError::new_err(text),
    }
}

fn stalled(wait: Duration) -> PyErr {
    NoAnswer::new_err(format!(
        "no stream frame within {} ms: is the board still there?",
        wait.as_millis()
    ))
}

fn unexpected(r: Reply) -> PyErr {
    ProtocolError::new_err(format!(
        "the board answered with an unexpected reply: {r:?}"
    ))
}

/// An exception of type `T` whose message is `message` and whose `.sentence` is the board's.
fn with_sentence<T: pyo3::PyTypeInfo>(py: Python<'_>, message: String, sentence: String) -> PyErr {
    let err = PyErr::new::<T, _>(message);
    // Setting an attribute on a fresh exception instance cannot fail; if it somehow did, the
    // message still says everything.
    let _ = err.value(py).setattr("sentence", sentence);
    err
}

/// A serde value as plain Python objects (dicts, lists, numbers, strings, None), via `json`:
/// the same shape `saw --json` prints.
fn to_python<T: serde::Serialize>(py: Python<'_>, v: &T) -> PyResult<PyObject> {
    let text = serde_json::to_string(v)
        .map_err(|e| SawError::new_err(format!("cannot convert a reply: {e}")))?;
    Ok(py.import("json")?.call_method1("loads", (text,))?.unbind())
}

/// A Python value of a scene-file dict as TOML (`key` names it in errors).
fn to_toml(key: &str, v: &Bound<'_, PyAny>) -> PyResult<toml::Value> {
    // bool before int: Python's bool is an int.
    if let Ok(b) = v.downcast::<PyBool>() {
        return Ok(toml::Value::Boolean(b.is_true()));
    }
    if v.is_instance_of::<PyInt>() {
        let i: i64 = v
            .extract()
            .map_err(|_| input(format!("{key} = {v}: must fit a 64-bit integer")))?;
        return Ok(toml::Value::Integer(i));
    }
    if v.is_instance_of::<PyFloat>() {
        let f: f64 = v.extract()?;
        if !f.is_finite() {
            return Err(input(format!("{key} = {f}: must be a finite number")));
        }
        return Ok(toml::Value::Float(f));
    }
    if let Ok(s) = v.downcast::<PyString>() {
        return Ok(toml::Value::String(s.to_cow()?.into_owned()));
    }
    if let Ok(d) = v.downcast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, item) in d.iter() {
            let k: String = k
                .extract()
                .map_err(|_| input(format!("{key}: a key {k} is not a string")))?;
            let name = if key.is_empty() {
                k.clone()
            } else {
                format!("{key}.{k}")
            };
            table.insert(k, to_toml(&name, &item)?);
        }
        return Ok(toml::Value::Table(table));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for (i, item) in v.try_iter()?.enumerate() {
            out.push(to_toml(&format!("{key}[{i}]"), &item?)?);
        }
        return Ok(toml::Value::Array(out));
    }
    Err(input(format!(
        "{key} = {v}: a scene file holds numbers, booleans, strings, lists and tables, not {}",
        v.get_type().name()?
    )))
}

/// One `key=value` of `set` as `saw set` takes it on its command line.
fn key_value(key: &str, v: &Bound<'_, PyAny>) -> PyResult<String> {
    let value = match to_toml(key, v)? {
        // A string goes as written: `saw::region_toml` quotes what TOML does not read.
        toml::Value::String(s) => s,
        other => other.to_string(),
    };
    Ok(format!("{key}={value}"))
}

/// One telemetry record.
#[pyclass(frozen, get_all, name = "Record", module = "sawlink")]
#[derive(Clone, Debug)]
pub struct PyRecord {
    /// The sample's time, µs since the board booted.
    time_us: u64,
    /// The id of the scene in force at this sample (what push/set/boundary/drive returned).
    scene_id: u32,
    /// Scene changes since boot at this sample: it steps at every push or edit.
    change: u32,
    /// Position, µm (None while the sensor is faulty).
    position_um: Option<i32>,
    /// Velocity, µm/s (None until the estimator has a full window).
    velocity_um_s: Option<i32>,
    /// Region under the finger.
    region: Option<u8>,
    /// Burst frequency in force, mHz (0: no bursts).
    burst_millihz: u32,
    /// The burst timer gates the carrier.
    bursting: bool,
    /// The sensor fault in force (`RailLow`, `RailHigh`, `Stale`), or None.
    fault: Option<String>,
}

impl PyRecord {
    fn of(r: &Record) -> Self {
        PyRecord {
            time_us: r.time_us,
            scene_id: r.scene_id,
            change: r.change,
            position_um: r.position_um,
            velocity_um_s: r.velocity_um_s,
            region: r.region,
            burst_millihz: r.burst_millihz,
            bursting: r.bursting,
            fault: r.fault.map(|f| format!("{f:?}")),
        }
    }
}

#[pymethods]
impl PyRecord {
    /// Burst frequency in force, Hz.
    #[getter]
    fn f_b_hz(&self) -> f64 {
        self.burst_millihz as f64 / 1000.0
    }

    fn __repr__(&self) -> String {
        let opt = |v: Option<i64>| v.map_or("None".to_string(), |v| v.to_string());
        format!(
            "Record(time_us={}, scene_id={:#010x}, change={}, position_um={}, velocity_um_s={}, region={}, burst_millihz={}, bursting={}, fault={})",
            self.time_us,
            self.scene_id,
            self.change,
            opt(self.position_um.map(i64::from)),
            opt(self.velocity_um_s.map(i64::from)),
            opt(self.region.map(i64::from)),
            self.burst_millihz,
            if self.bursting { "True" } else { "False" },
            self.fault.as_deref().map_or("None".to_string(), |f| format!("{f:?}"))
        )
    }
}

/// The column names of a recording, in order.
const COLUMNS: [&str; 10] = [
    "time_us",
    "scene_id",
    "change",
    "position_um",
    "velocity_um_s",
    "region",
    "burst_millihz",
    "f_b_hz",
    "bursting",
    "fault",
];

/// Records gathered by `Board.record`, with what the link lost while they were gathered.
#[pyclass(frozen, module = "sawlink")]
pub struct Recording {
    records: Vec<PyRecord>,
    /// Records the board dropped during the recording (its queue full: the line was busy).
    #[pyo3(get)]
    dropped: u64,
    /// Stream frames lost on the line (gaps in the frames' running number).
    #[pyo3(get)]
    frames_lost: u64,
    /// Frames the client refused (noise), counted since the board was opened.
    #[pyo3(get)]
    bad_frames: u64,
    /// Records dropped by the client as stale: sampled before this recording's stream started
    /// (in transit from an earlier one).
    #[pyo3(get)]
    stale: u64,
    /// The board's clock when it started the stream, µs since boot: every record is at or after.
    #[pyo3(get)]
    from_us: u64,
    /// Records per second asked for.
    #[pyo3(get)]
    rate_hz: f64,
    /// The decimation asked for.
    #[pyo3(get)]
    every: u16,
}

#[pymethods]
impl Recording {
    fn __len__(&self) -> usize {
        self.records.len()
    }

    fn __getitem__(&self, i: isize) -> PyResult<PyRecord> {
        let n = self.records.len() as isize;
        let j = if i < 0 { i + n } else { i };
        if j < 0 || j >= n {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "record {i} of a recording of {n}"
            )));
        }
        Ok(self.records[j as usize].clone())
    }

    /// The records as a dict of lists, one list per field (`pandas.DataFrame(rec.columns())`).
    fn columns<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let r = &self.records;
        d.set_item(COLUMNS[0], r.iter().map(|r| r.time_us).collect::<Vec<_>>())?;
        d.set_item(COLUMNS[1], r.iter().map(|r| r.scene_id).collect::<Vec<_>>())?;
        d.set_item(COLUMNS[2], r.iter().map(|r| r.change).collect::<Vec<_>>())?;
        d.set_item(
            COLUMNS[3],
            r.iter().map(|r| r.position_um).collect::<Vec<_>>(),
        )?;
        d.set_item(
            COLUMNS[4],
            r.iter().map(|r| r.velocity_um_s).collect::<Vec<_>>(),
        )?;
        d.set_item(COLUMNS[5], r.iter().map(|r| r.region).collect::<Vec<_>>())?;
        d.set_item(
            COLUMNS[6],
            r.iter().map(|r| r.burst_millihz).collect::<Vec<_>>(),
        )?;
        d.set_item(COLUMNS[7], r.iter().map(|r| r.f_b_hz()).collect::<Vec<_>>())?;
        d.set_item(COLUMNS[8], r.iter().map(|r| r.bursting).collect::<Vec<_>>())?;
        d.set_item(
            COLUMNS[9],
            r.iter().map(|r| r.fault.clone()).collect::<Vec<_>>(),
        )?;
        Ok(d)
    }

    /// A pandas DataFrame of `columns()`; pandas is imported only here, and only if installed.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let pandas = py.import("pandas").map_err(|_| {
            pyo3::exceptions::PyImportError::new_err(
                "to_pandas needs pandas (pip install pandas); columns() gives the same data as a dict of lists",
            )
        })?;
        pandas.call_method1("DataFrame", (self.columns(py)?,))
    }

    fn __repr__(&self) -> String {
        format!(
            "Recording({} records at {} records/s, {} dropped, {} frames lost)",
            self.records.len(),
            self.rate_hz,
            self.dropped,
            self.frames_lost
        )
    }
}

/// A board (or a virtual one) on a serial port, opened once and locked while open.
#[pyclass(module = "sawlink")]
pub struct Board {
    client: Option<Client<Port>>,
    port: PathBuf,
    timeout: Duration,
    hello: Hello,
    /// The stream is running (a `Stream` iterator is open).
    streaming: bool,
}

/// What a stream is told per frame, for `Stream` and `Board.record`.
#[derive(Default)]
struct Tally {
    last_seq: Option<u32>,
    frames_lost: u64,
    /// The board's drop count in the first and the last frame. It is a running count (the
    /// virtual board's since boot), so a stream's own drops are its growth.
    first_dropped: Option<u32>,
    last_dropped: u32,
}

impl Tally {
    fn frame(&mut self, h: &Header, dropped: u32) {
        if let Some(prev) = self.last_seq {
            self.frames_lost += h.seq.wrapping_sub(prev).saturating_sub(1) as u64;
        }
        self.last_seq = Some(h.seq);
        self.first_dropped.get_or_insert(dropped);
        self.last_dropped = dropped;
    }

    /// Drops seen in the frames so far (those before the first frame not among them).
    fn dropped_seen(&self) -> u64 {
        self.first_dropped
            .map_or(0, |first| self.last_dropped.wrapping_sub(first) as u64)
    }
}

impl Board {
    fn client(&mut self) -> PyResult<&mut Client<Port>> {
        self.client.as_mut().ok_or_else(|| {
            SawError::new_err(format!(
                "the board on {} is closed: open a new Board",
                self.port.display()
            ))
        })
    }

    fn wait(&self, timeout_s: Option<f64>) -> PyResult<Duration> {
        match timeout_s {
            None => Ok(self.timeout),
            Some(t) => Ok(Duration::from_secs_f64(finite_in(
                "timeout_s",
                t,
                TIMEOUT_S,
                "s",
            )?)),
        }
    }

    /// Sends `request`, waits up to `wait` with the GIL released.
    fn ask(&mut self, py: Python<'_>, request: Request, wait: Duration) -> PyResult<Reply> {
        if self.streaming {
            return Err(SawError::new_err(
                "a stream is running on this board: close it (or leave its `with` block) first",
            ));
        }
        let client = self.client()?;
        py.allow_threads(|| client.request_within(&request, wait))
            .map_err(link_err)
    }

    fn applied(&mut self, py: Python<'_>, request: Request, wait: Duration) -> PyResult<u32> {
        match self.ask(py, request, wait)? {
            Reply::Applied { scene_id } => Ok(scene_id),
            Reply::Refused(e) => Err(with_sentence::<Refused>(
                py,
                format!("refused, nothing changed: {e}"),
                e.to_string(),
            )),
            other => Err(unexpected(other)),
        }
    }

    fn scene(&mut self, py: Python<'_>, wait: Duration) -> PyResult<(u32, Reply)> {
        match self.ask(py, Request::GetScene, wait)? {
            r @ Reply::Scene { scene_id, .. } => Ok((scene_id, r)),
            other => Err(unexpected(other)),
        }
    }

    /// Loads the scene file `text` (named `name`): read and checked here, compiled on the board.
    fn push_text(
        &mut self,
        py: Python<'_>,
        name: &str,
        text: &str,
        wait: Duration,
    ) -> PyResult<u32> {
        let doc = saw_core::scene_file::parse(name, text).map_err(|e| input(e.to_string()))?;
        match self.ask(py, Request::LoadScene(doc.config.clone()), wait)? {
            Reply::Applied { scene_id } => Ok(scene_id),
            // The board's refusal, located in the file as `saw push` prints it.
            Reply::Refused(e) => Err(with_sentence::<Refused>(
                py,
                doc.locate(&e).to_string(),
                e.to_string(),
            )),
            other => Err(unexpected(other)),
        }
    }

    /// Starts the stream (every `every` samples): the client hands on only records sampled
    /// after the board's answer (`from_us`), none of an earlier stream's still in transit.
    fn start_stream(&mut self, py: Python<'_>, every: u16) -> PyResult<StreamStart> {
        if self.streaming {
            return Err(SawError::new_err(
                "a stream is running on this board: close it (or leave its `with` block) first",
            ));
        }
        let client = self.client()?;
        py.allow_threads(|| client.start_stream(every))
            .map_err(link_err)
    }

    /// The board's count of records dropped (since boot or the last counters reset).
    fn records_dropped(&mut self, py: Python<'_>, wait: Duration) -> PyResult<u32> {
        match self.ask(py, Request::Counters { reset: false }, wait)? {
            Reply::Counters(c) => Ok(c.link.records_dropped),
            other => Err(unexpected(other)),
        }
    }

    /// Stops the stream; frames still in flight are dropped by the client.
    fn stop_stream(&mut self, py: Python<'_>) -> PyResult<()> {
        self.streaming = false;
        let client = self.client()?;
        py.allow_threads(|| client.stop_stream()).map_err(link_err)
    }

    fn next_frame(
        &mut self,
        py: Python<'_>,
        deadline: Instant,
    ) -> PyResult<Option<(Header, saw_link::msg::Stream)>> {
        let client = self.client()?;
        py.allow_threads(|| client.next_stream(deadline))
            .map_err(link_err)
    }
}

/// Opens `path` as `saw` does; a missing or busy port raises its own type.
fn open(path: &PathBuf) -> PyResult<Port> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(PortMissing::new_err(format!(
                "port {} does not exist: is the board plugged in (or `host-sim serve --pty {}` running)?",
                path.display(),
                path.display()
            )))
        }
        _ => {}
    }
    // `saw::port::open` words a busy port as "is busy" (serialport's lock, TIOCEXCL, refused);
    // it returns a sentence, not a type, so the type is read from it.
    port::open(path).map_err(|text| {
        if text.contains("is busy") {
            PortBusy::new_err(text)
        } else {
            PortError::new_err(text)
        }
    })
}

#[pymethods]
impl Board {
    /// Opens the port (exclusively, as `saw` does) and says hello: a board speaking another
    /// protocol version is refused here. `timeout_s` (0.01 to 60 s) is every call's wait unless
    /// the call gives its own.
    #[new]
    #[pyo3(signature = (port, timeout_s = 1.0))]
    fn new(py: Python<'_>, port: PathBuf, timeout_s: f64) -> PyResult<Self> {
        let timeout = Duration::from_secs_f64(finite_in("timeout_s", timeout_s, TIMEOUT_S, "s")?);
        let p = py.allow_threads(|| open(&port))?;
        let mut board = Board {
            client: Some(Client::new(p, timeout)),
            port,
            timeout,
            hello: Hello {
                protocol: 0,
                firmware: Default::default(),
                board: Default::default(),
                sample_rate_hz: 0,
                scene_id: 0,
                scene_source: saw_link::msg::SceneSource::Default,
            },
            streaming: false,
        };
        board.hello = board.hello_reply(py, timeout)?;
        Ok(board)
    }

    /// The port's path.
    #[getter]
    fn port(&self) -> PathBuf {
        self.port.clone()
    }

    /// Samples per second of the board's control loop (from its hello).
    #[getter]
    fn sample_rate_hz(&self) -> u32 {
        self.hello.sample_rate_hz
    }

    /// Who is there: protocol, firmware, board, samples/s, the active scene's id and source.
    #[pyo3(signature = (timeout_s = None))]
    fn hello(&mut self, py: Python<'_>, timeout_s: Option<f64>) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?;
        let h = self.hello_reply(py, wait)?;
        self.hello = h.clone();
        // The names `saw --json hello` uses (a source as a word: "default", "saved", "link"),
        // with the scene id as a Python int.
        let mut v = serde_json::to_value(&h)
            .map_err(|e| SawError::new_err(format!("cannot convert a reply: {e}")))?;
        v["scene_source"] = saw::source_key(h.scene_source).into();
        to_python(py, &v)
    }

    /// Loads a scene: a scene file's path, or a dict shaped like one (`{"substrate": {...},
    /// "region": [{"kind": "grating", ...}, ...]}`, as `tomllib` reads a file). Read and checked
    /// here as `saw push` does, compiled on the board. Returns the scene id now running; raises
    /// `Refused` (nothing changed) with the board's `.sentence`, `InputError` for a file that
    /// does not read.
    #[pyo3(signature = (scene, timeout_s = None))]
    fn push(
        &mut self,
        py: Python<'_>,
        scene: &Bound<'_, PyAny>,
        timeout_s: Option<f64>,
    ) -> PyResult<u32> {
        let wait = self.wait(timeout_s)?;
        let (name, text) = if scene.is_instance_of::<PyDict>() {
            let toml::Value::Table(t) = to_toml("", scene)? else {
                unreachable!("a dict converts to a table")
            };
            let text = toml::to_string(&t)
                .map_err(|e| input(format!("the scene dict does not write as TOML: {e}")))?;
            ("<dict>".to_string(), text)
        } else {
            let path: PathBuf = scene.extract().map_err(|_| {
                input(format!(
                    "scene = {scene}: must be a scene file's path or a dict shaped like a scene file"
                ))
            })?;
            let name = path.display().to_string();
            let text = std::fs::read_to_string(&path).map_err(|e| input(format!("{name}: {e}")))?;
            (name, text)
        };
        self.push_text(py, &name, &text, wait)
    }

    /// The active scene: `{"scene_id": int, "scene_source": str, "scene": dict}`, the scene with the
    /// scene file's keys and units as `saw --json get` prints it.
    #[pyo3(signature = (timeout_s = None))]
    fn get(&mut self, py: Python<'_>, timeout_s: Option<f64>) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?;
        let (_, reply) = self.scene(py, wait)?;
        let Reply::Scene {
            scene_id,
            source,
            config,
        } = reply
        else {
            unreachable!("scene() returns only a Scene")
        };
        let d = PyDict::new(py);
        d.set_item("scene_id", scene_id)?;
        d.set_item("scene_source", saw::source_key(source))?;
        // The scene file's keys and units (`saw --json get`): pushed back as a dict it is the
        // same scene.
        d.set_item("scene", to_python(py, &saw::scene_json(&config))?)?;
        Ok(d.into_any().unbind())
    }

    /// Changes region `region`'s texture, written as the keys of a `[[region]]` table:
    /// `board.set(1, f_b_hz=80)` keeps the region's other values; `board.set(1, kind="grating",
    /// wavelength_mm=1.5)` gives it a new kind from that kind's defaults (or `board.set(1,
    /// "kind=grating", "wavelength_mm=1.5")`, as `saw set` takes them). Returns the scene id
    /// now running.
    #[pyo3(signature = (region, *pairs, timeout_s = None, **keys))]
    fn set(
        &mut self,
        py: Python<'_>,
        region: i64,
        pairs: Vec<String>,
        timeout_s: Option<f64>,
        keys: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<u32> {
        let region = index_u8("region", region)?;
        let wait = self.wait(timeout_s)?;
        let mut all = pairs;
        if let Some(keys) = keys {
            for (k, v) in keys.iter() {
                let k: String = k.extract()?;
                all.push(key_value(&k, &v)?);
            }
        }
        if all.is_empty() {
            return Err(input(
                "set: no keys given (kind=… and the kind's fields)".into(),
            ));
        }
        let table = saw::region_toml(&all).map_err(input)?;
        // Over the region's own values in the board's scene, as `saw set` does: the keys named
        // change, the rest stay (a new kind starts from its defaults).
        let (_, reply) = self.scene(py, wait)?;
        let Reply::Scene { config, .. } = reply else {
            unreachable!("scene() returns only a Scene")
        };
        let texture = saw::merged_texture(&config, region, &table).map_err(input)?;
        self.applied(py, Request::SetTexture { region, texture }, wait)
    }

    /// Moves boundary `index` (where region `index` ends) to `mm` (0 to 1000 mm), live.
    /// Returns the scene id now running.
    #[pyo3(signature = (index, mm, timeout_s = None))]
    fn boundary(
        &mut self,
        py: Python<'_>,
        index: i64,
        mm: f64,
        timeout_s: Option<f64>,
    ) -> PyResult<u32> {
        let index = index_u8("index", index)?;
        let mm = finite_in("mm", mm, MM, "mm")?;
        let wait = self.wait(timeout_s)?;
        let at_um = (mm * 1000.0).round() as u32;
        self.applied(py, Request::MoveBoundary { index, at_um }, wait)
    }

    /// `"standing"` (both IDTs) or `"progressive"` (one IDT). Returns the scene id now running.
    #[pyo3(signature = (mode, timeout_s = None))]
    fn drive(&mut self, py: Python<'_>, mode: &str, timeout_s: Option<f64>) -> PyResult<u32> {
        let drive = match mode {
            "standing" => DriveMode::Standing,
            "progressive" => DriveMode::Progressive,
            other => {
                return Err(input(format!(
                    "mode = {other:?}: must be \"standing\" or \"progressive\""
                )))
            }
        };
        let wait = self.wait(timeout_s)?;
        self.applied(py, Request::SetDrive(drive), wait)
    }

    /// The board's counters since boot or the last reset, as `saw --json counters` prints
    /// them: `{"core": {...}, "link": {...}}`. `reset` starts a new count after this read.
    #[pyo3(signature = (reset = false, timeout_s = None))]
    fn counters(
        &mut self,
        py: Python<'_>,
        reset: bool,
        timeout_s: Option<f64>,
    ) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?;
        match self.ask(py, Request::Counters { reset }, wait)? {
            Reply::Counters(c) => to_python(py, &c),
            other => Err(unexpected(other)),
        }
    }

    /// Saves the active scene to flash (the board boots into it). Waits the longer of the
    /// timeout and `saw`'s SAVE_TIMEOUT (4 s: an F446 sector erase). Returns `{"scene_id":
    /// int, "seconds": float}` (how long the answer took, host time); raises `SaveFailed`.
    #[pyo3(signature = (timeout_s = None))]
    fn save(&mut self, py: Python<'_>, timeout_s: Option<f64>) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?.max(saw::SAVE_TIMEOUT);
        let asked = Instant::now();
        match self.ask(py, Request::Save, wait)? {
            Reply::Saved { scene_id } => {
                let d = PyDict::new(py);
                d.set_item("scene_id", scene_id)?;
                d.set_item("seconds", asked.elapsed().as_secs_f64())?;
                Ok(d.into_any().unbind())
            }
            Reply::SaveFailed(e) => Err(with_sentence::<SaveFailed>(
                py,
                format!("save failed: {e}"),
                e.to_string(),
            )),
            other => Err(unexpected(other)),
        }
    }

    /// Streams `seconds` (0.1 to 86 400 s) of telemetry, one record every `every` samples
    /// (1 to 10 000; 10 = 1 kHz on a 10 kHz board), and returns them as a `Recording`: every
    /// record sampled after the board started this stream, none of an earlier one's. A stream
    /// that stalls for `timeout_s` raises `NoAnswer`.
    #[pyo3(signature = (seconds, every = 10, timeout_s = None))]
    fn record(
        &mut self,
        py: Python<'_>,
        seconds: f64,
        every: i64,
        timeout_s: Option<f64>,
    ) -> PyResult<Recording> {
        let seconds = finite_in("seconds", seconds, SECONDS, "s")?;
        let every = whole_in("every", every, EVERY)? as u16;
        let wait = self.wait(timeout_s)?;
        let dropped_before = self.records_dropped(py, wait)?;
        let start = self.start_stream(py, every)?;
        let rate_hz = start.sample_rate_hz as f64 / every as f64;
        let end = Instant::now() + Duration::from_secs_f64(seconds);
        let mut records = Vec::with_capacity((rate_hz * seconds) as usize + 64);
        let mut tally = Tally::default();
        let stale_before = self.client()?.stale_records();
        let outcome = (|| loop {
            let now = Instant::now();
            if now >= end {
                return Ok(());
            }
            match self.next_frame(py, end.min(now + wait))? {
                Some((h, s)) => {
                    tally.frame(&h, s.dropped);
                    records.extend(s.records.iter().map(PyRecord::of));
                }
                None if Instant::now() >= end => return Ok(()),
                None => return Err(stalled(wait)),
            }
            // Ctrl-C in a long recording raises KeyboardInterrupt (the stream is stopped below).
            py.check_signals()?;
        })();
        // Stopped whatever happened; the recording's own failure is the one reported.
        let stopped = self.stop_stream(py);
        outcome?;
        stopped?;
        // The board's own count over the recording, as `saw stream` reports it: it also holds
        // drops before the first frame, which no frame's count can show.
        let dropped = self.records_dropped(py, wait)?.wrapping_sub(dropped_before) as u64;
        let client = self.client()?;
        Ok(Recording {
            records,
            dropped,
            frames_lost: tally.frames_lost,
            bad_frames: client.bad_frames(),
            stale: client.stale_records() - stale_before,
            from_us: start.from_us,
            rate_hz,
            every,
        })
    }

    /// A live stream: iterate for records as they come, one every `every` samples (sampled
    /// after the board started it); it ends after `seconds` if given, else when closed (`with
    /// board.stream() as s:` closes it). A wait of `timeout_s` for the next frame raises
    /// `NoAnswer`. Other calls on the board are refused while it runs.
    #[pyo3(signature = (every = 10, seconds = None, timeout_s = None))]
    fn stream(
        slf: &Bound<'_, Self>,
        every: i64,
        seconds: Option<f64>,
        timeout_s: Option<f64>,
    ) -> PyResult<Stream> {
        let py = slf.py();
        let every = whole_in("every", every, EVERY)? as u16;
        let seconds = seconds
            .map(|s| finite_in("seconds", s, SECONDS, "s"))
            .transpose()?;
        let mut b = slf.borrow_mut();
        let wait = b.wait(timeout_s)?;
        let dropped_before = b.records_dropped(py, wait)?;
        let start = b.start_stream(py, every)?;
        b.streaming = true;
        Ok(Stream {
            board: slf.clone().unbind(),
            pending: VecDeque::new(),
            tally: Tally::default(),
            end: seconds.map(|s| Instant::now() + Duration::from_secs_f64(s)),
            wait,
            open: true,
            rate_hz: start.sample_rate_hz as f64 / every as f64,
            from_us: start.from_us,
            dropped_before,
            dropped_after_close: None,
        })
    }

    /// One round trip of a ping: `{"board_us": int, "host_sent_us": int, "host_received_us":
    /// int, "round_trip_us": int}` (host times: µs since the Unix epoch, carried by the
    /// monotonic clock; board time: µs since its boot, the clock of the records' `time_us`).
    fn ping<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        if self.streaming {
            return Err(SawError::new_err(
                "a stream is running on this board: close it (or leave its `with` block) first",
            ));
        }
        let client = self.client()?;
        let p = py.allow_threads(|| client.ping()).map_err(link_err)?;
        let d = PyDict::new(py);
        d.set_item("board_us", p.board_us)?;
        d.set_item("host_sent_us", p.host_sent_us)?;
        d.set_item("host_received_us", p.host_received_us)?;
        d.set_item("round_trip_us", p.round_trip_us())?;
        Ok(d)
    }

    /// Closes the port (stopping a stream left running). Further calls raise `SawError`.
    fn close(&mut self, py: Python<'_>) -> PyResult<()> {
        if self.streaming && self.client.is_some() {
            // The port closes whatever the board says to the stop.
            let _ = self.stop_stream(py);
        }
        self.client = None;
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&mut self, py: Python<'_>, _exc: &Bound<'_, PyTuple>) -> PyResult<bool> {
        self.close(py)?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!(
            "Board({:?}, {} running {}, {})",
            self.port.display().to_string(),
            self.hello.board,
            self.hello.firmware,
            if self.client.is_some() {
                "open"
            } else {
                "closed"
            }
        )
    }
}

impl Board {
    fn hello_reply(&mut self, py: Python<'_>, wait: Duration) -> PyResult<Hello> {
        match self.ask(py, Request::Hello, wait)? {
            Reply::Hello(h) if h.protocol == PROTOCOL_VERSION => Ok(h),
            // Client::hello's check, here with the call's own timeout.
            Reply::Hello(h) => Err(link_err(ClientError::WrongVersion {
                board: h.protocol,
                host: PROTOCOL_VERSION,
            })),
            other => Err(unexpected(other)),
        }
    }
}

/// A running stream (from `Board.stream`): an iterator of records and a context manager that
/// stops the stream on exit.
#[pyclass(module = "sawlink")]
pub struct Stream {
    board: Py<Board>,
    pending: VecDeque<PyRecord>,
    tally: Tally,
    end: Option<Instant>,
    wait: Duration,
    open: bool,
    /// Records per second asked for.
    #[pyo3(get)]
    rate_hz: f64,
    /// The board's clock when it started the stream, µs since boot: every record is at or after.
    #[pyo3(get)]
    from_us: u64,
    /// The board's dropped-records counter before the stream started.
    dropped_before: u32,
    /// The stream's drops by that counter, once closed.
    dropped_after_close: Option<u64>,
}

#[pymethods]
impl Stream {
    /// Records the board dropped in this stream: while it runs, the growth of the frames' count
    /// since the first frame; once closed, the board's counter over the whole stream.
    #[getter]
    fn dropped(&self) -> u64 {
        self.dropped_after_close
            .unwrap_or_else(|| self.tally.dropped_seen())
    }

    /// Stream frames lost on the line (gaps in their running number).
    #[getter]
    fn frames_lost(&self) -> u64 {
        self.tally.frames_lost
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<PyRecord>> {
        loop {
            if let Some(r) = self.pending.pop_front() {
                return Ok(Some(r));
            }
            if !self.open {
                return Ok(None);
            }
            let now = Instant::now();
            let stall = now + self.wait;
            let deadline = self.end.map_or(stall, |e| e.min(stall));
            if self.end.is_some_and(|e| now >= e) {
                self.close(py)?;
                return Ok(None);
            }
            let frame = self.board.borrow_mut(py).next_frame(py, deadline)?;
            match frame {
                Some((h, s)) => {
                    self.tally.frame(&h, s.dropped);
                    self.pending.extend(s.records.iter().map(PyRecord::of));
                }
                None if self.end.is_some_and(|e| Instant::now() >= e) => {}
                None => return Err(stalled(self.wait)),
            }
        }
    }

    /// Stops the stream on the board; records still buffered here are still yielded.
    fn close(&mut self, py: Python<'_>) -> PyResult<()> {
        if !self.open {
            return Ok(());
        }
        self.open = false;
        let mut b = self.board.borrow_mut(py);
        if b.client.is_none() {
            return Ok(());
        }
        b.stop_stream(py)?;
        let after = b.records_dropped(py, self.wait)?;
        self.dropped_after_close = Some(after.wrapping_sub(self.dropped_before) as u64);
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_exc))]
    fn __exit__(&mut self, py: Python<'_>, _exc: &Bound<'_, PyTuple>) -> PyResult<bool> {
        self.close(py)?;
        Ok(false)
    }
}

impl Drop for Stream {
    /// A stream dropped while open (a `for` loop left by `break` without `with`) is stopped,
    /// so the board takes requests again.
    fn drop(&mut self) {
        if self.open {
            Python::with_gil(|py| {
                // Nobody is left to tell of a failed stop; the next call finds the port's state.
                let _ = self.close(py);
            });
        }
    }
}

/// The scene id a configuration has on every host and board (the CRC-32 of its encoding).
#[pyfunction]
fn scene_id_of_file(path: PathBuf) -> PyResult<u32> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(&path).map_err(|e| input(format!("{name}: {e}")))?;
    let doc = saw_core::scene_file::parse(&name, &text).map_err(|e| input(e.to_string()))?;
    Ok(saw_link::scene_id(&doc.config))
}

#[pymodule]
fn sawlink(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<Board>()?;
    m.add_class::<Stream>()?;
    m.add_class::<Recording>()?;
    m.add_class::<PyRecord>()?;
    m.add_function(wrap_pyfunction!(scene_id_of_file, m)?)?;
    experiment::register(m)?;
    m.add("SawError", py.get_type::<SawError>())?;
    m.add("PortError", py.get_type::<PortError>())?;
    m.add("PortMissing", py.get_type::<PortMissing>())?;
    m.add("PortBusy", py.get_type::<PortBusy>())?;
    m.add("NoAnswer", py.get_type::<NoAnswer>())?;
    m.add("ProtocolError", py.get_type::<ProtocolError>())?;
    m.add("Refused", py.get_type::<Refused>())?;
    m.add("SaveFailed", py.get_type::<SaveFailed>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add("PROTOCOL_VERSION", PROTOCOL_VERSION)?;
    m.add("SAVE_TIMEOUT_S", saw::SAVE_TIMEOUT.as_secs_f64())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
