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
//!
//! A board with the 4-wire touch overlay (issue #36) runs 2D scenes: the same `push`, `get`,
//! `counters`, `record` and `stream` carry them (`Record2d`s, the 2D columns), `move_window` and
//! `resize_window` edit them; a 1D call on it (or a 2D one on a rheostat board) raises `Refused`
//! with the board's sentence.

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
use saw_link::msg::{
    Header, Hello, Record, Record2d, Refused2d, Reply, Request, SceneKind, Sensor,
    Stream as StreamFrame, Stream2d, PROTOCOL_VERSION,
};

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

/// A point on the plate from two coordinates in mm, each checked as `saw window` checks them
/// (finite, 0 to 1000 mm), to the board's µm.
fn point_um(x: (&str, f64), y: (&str, f64)) -> PyResult<saw_core::plane::PointUm> {
    let x_mm = finite_in(x.0, x.1, MM, "mm")?;
    let y_mm = finite_in(y.0, y.1, MM, "mm")?;
    Ok(saw_core::plane::PointUm::new(
        (x_mm * 1000.0).round() as i32,
        (y_mm * 1000.0).round() as i32,
    ))
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

/// One 2D telemetry record (a board with the touch overlay): the columns of `saw stream`'s 2D
/// CSV (docs/link.md, "2D scenes").
#[pyclass(frozen, name = "Record2d", module = "sawlink")]
#[derive(Clone, Debug)]
pub struct PyRecord2d {
    /// The reading's time, µs since the board booted.
    #[pyo3(get)]
    time_us: u64,
    /// The id of the scene in force at this reading.
    #[pyo3(get)]
    scene_id: u32,
    /// Scene changes since boot at this reading.
    #[pyo3(get)]
    change: u32,
    /// The finger on the plate, µm (None while lifted or faulted).
    #[pyo3(get)]
    x_um: Option<i32>,
    /// The finger on the plate, µm (None while lifted or faulted).
    #[pyo3(get)]
    y_um: Option<i32>,
    /// Velocity along x, µm/s, where the scene reads it (None elsewhere).
    #[pyo3(get)]
    vx_um_s: Option<i32>,
    /// Velocity along y, µm/s, where the scene reads it (None elsewhere).
    #[pyo3(get)]
    vy_um_s: Option<i32>,
    /// What is under the finger while it renders (the `window` getter).
    place: Option<saw_core::plane::Place>,
    /// The edge whose pulse fired at this reading, or None.
    #[pyo3(get)]
    edge: Option<u8>,
    /// Burst frequency in force, mHz (0: no bursts).
    #[pyo3(get)]
    burst_millihz: u32,
    /// Bursts (or an edge pulse) are running.
    #[pyo3(get)]
    bursting: bool,
    /// No finger on the overlay.
    #[pyo3(get)]
    lifted: bool,
    /// The touch fault in force (`"RailLow-x"`, `"RailHigh-y"`, `"Stale"`), or None.
    #[pyo3(get)]
    fault: Option<String>,
}

impl PyRecord2d {
    fn of(r: &Record2d) -> Self {
        PyRecord2d {
            time_us: r.time_us,
            scene_id: r.scene_id,
            change: r.change,
            x_um: r.position.map(|p| p.x_um),
            y_um: r.position.map(|p| p.y_um),
            vx_um_s: r.velocity_um_s.map(|v| v.0),
            vy_um_s: r.velocity_um_s.map(|v| v.1),
            place: r.place,
            edge: r.edge,
            burst_millihz: r.burst_millihz,
            bursting: r.bursting,
            lifted: r.lifted,
            fault: r.fault.map(saw::record::fault_2d_name),
        }
    }

    /// The `window` value: the window's index, `"background"`, or None.
    fn window_object(&self, py: Python<'_>) -> PyResult<Option<PyObject>> {
        use saw_core::plane::Place;
        Ok(match self.place {
            Some(Place::Window(i)) => Some(i.into_pyobject(py)?.into_any().unbind()),
            Some(Place::Background) => Some("background".into_pyobject(py)?.into_any().unbind()),
            None => None,
        })
    }
}

#[pymethods]
impl PyRecord2d {
    /// Burst frequency in force, Hz.
    #[getter]
    fn f_b_hz(&self) -> f64 {
        self.burst_millihz as f64 / 1000.0
    }

    /// The window under the finger: its index, `"background"`, or None while nothing renders
    /// (lifted, landing, a fault), as the CSV's `window` column.
    #[getter]
    fn window(&self, py: Python<'_>) -> PyResult<Option<PyObject>> {
        self.window_object(py)
    }

    fn __repr__(&self) -> String {
        use saw_core::plane::Place;
        let opt = |v: Option<i32>| v.map_or("None".to_string(), |v| v.to_string());
        let window = match self.place {
            Some(Place::Window(i)) => i.to_string(),
            Some(Place::Background) => "'background'".to_string(),
            None => "None".to_string(),
        };
        format!(
            "Record2d(time_us={}, scene_id={:#010x}, change={}, x_um={}, y_um={}, vx_um_s={}, vy_um_s={}, window={}, edge={}, burst_millihz={}, bursting={}, lifted={}, fault={})",
            self.time_us,
            self.scene_id,
            self.change,
            opt(self.x_um),
            opt(self.y_um),
            opt(self.vx_um_s),
            opt(self.vy_um_s),
            window,
            self.edge.map_or("None".to_string(), |e| e.to_string()),
            self.burst_millihz,
            if self.bursting { "True" } else { "False" },
            if self.lifted { "True" } else { "False" },
            self.fault.as_deref().map_or("None".to_string(), |f| format!("{f:?}"))
        )
    }
}

/// The records of a recording: a rheostat board's or a touch overlay's.
enum Records {
    Line(Vec<PyRecord>),
    Plane(Vec<PyRecord2d>),
}

impl Records {
    fn len(&self) -> usize {
        match self {
            Records::Line(r) => r.len(),
            Records::Plane(r) => r.len(),
        }
    }

    /// Appends a frame's records (of the same board, so of the same kind).
    fn append(&mut self, batch: Records) {
        match (self, batch) {
            (Records::Line(a), Records::Line(b)) => a.extend(b),
            (Records::Plane(a), Records::Plane(b)) => a.extend(b),
            // A board does not change its sensor; were it to, its records would not belong in
            // one table.
            _ => {}
        }
    }

    /// Each record as the Python object `Stream` yields.
    fn into_objects(self, py: Python<'_>) -> PyResult<Vec<PyObject>> {
        match self {
            Records::Line(r) => r
                .into_iter()
                .map(|r| Ok(Bound::new(py, r)?.into_any().unbind()))
                .collect(),
            Records::Plane(r) => r
                .into_iter()
                .map(|r| Ok(Bound::new(py, r)?.into_any().unbind()))
                .collect(),
        }
    }
}

/// The column names of a 2D recording, in order (the 2D CSV's, without the host time).
const COLUMNS_2D: [&str; 14] = [
    "time_us",
    "scene_id",
    "change",
    "x_um",
    "y_um",
    "vx_um_s",
    "vy_um_s",
    "window",
    "edge",
    "burst_millihz",
    "f_b_hz",
    "bursting",
    "lifted",
    "fault",
];

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

/// Records gathered by `Board.record`, with what the link lost while they were gathered: `Record`s
/// from a rheostat board, `Record2d`s from one with the touch overlay.
#[pyclass(frozen, module = "sawlink")]
pub struct Recording {
    records: Records,
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

    /// The board runs 2D scenes: the records are `Record2d`s, the columns the 2D ones.
    #[getter]
    fn plane(&self) -> bool {
        matches!(self.records, Records::Plane(_))
    }

    fn __getitem__(&self, py: Python<'_>, i: isize) -> PyResult<PyObject> {
        let n = self.records.len() as isize;
        let j = if i < 0 { i + n } else { i };
        if j < 0 || j >= n {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "record {i} of a recording of {n}"
            )));
        }
        let j = j as usize;
        Ok(match &self.records {
            Records::Line(r) => Bound::new(py, r[j].clone())?.into_any().unbind(),
            Records::Plane(r) => Bound::new(py, r[j].clone())?.into_any().unbind(),
        })
    }

    /// The records as a dict of lists, one list per field (`pandas.DataFrame(rec.columns())`):
    /// `Record`'s fields, or on a 2D board `Record2d`'s (x_um, y_um, vx_um_s, vy_um_s, window,
    /// edge, …, lifted, fault).
    fn columns<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let r = match &self.records {
            Records::Line(r) => r,
            Records::Plane(r) => {
                let c = &COLUMNS_2D;
                d.set_item(c[0], r.iter().map(|r| r.time_us).collect::<Vec<_>>())?;
                d.set_item(c[1], r.iter().map(|r| r.scene_id).collect::<Vec<_>>())?;
                d.set_item(c[2], r.iter().map(|r| r.change).collect::<Vec<_>>())?;
                d.set_item(c[3], r.iter().map(|r| r.x_um).collect::<Vec<_>>())?;
                d.set_item(c[4], r.iter().map(|r| r.y_um).collect::<Vec<_>>())?;
                d.set_item(c[5], r.iter().map(|r| r.vx_um_s).collect::<Vec<_>>())?;
                d.set_item(c[6], r.iter().map(|r| r.vy_um_s).collect::<Vec<_>>())?;
                let windows = r
                    .iter()
                    .map(|r| r.window_object(py))
                    .collect::<PyResult<Vec<_>>>()?;
                d.set_item(c[7], windows)?;
                d.set_item(c[8], r.iter().map(|r| r.edge).collect::<Vec<_>>())?;
                d.set_item(c[9], r.iter().map(|r| r.burst_millihz).collect::<Vec<_>>())?;
                d.set_item(c[10], r.iter().map(|r| r.f_b_hz()).collect::<Vec<_>>())?;
                d.set_item(c[11], r.iter().map(|r| r.bursting).collect::<Vec<_>>())?;
                d.set_item(c[12], r.iter().map(|r| r.lifted).collect::<Vec<_>>())?;
                d.set_item(c[13], r.iter().map(|r| r.fault.clone()).collect::<Vec<_>>())?;
                return Ok(d);
            }
        };
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
    /// The board's touch overlay, µm (width, height), when it reads one (runs 2D scenes); None
    /// for the slide rheostat. Asked at open and at every `hello()`.
    overlay: Option<(u32, u32)>,
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
        self.ask_raw(py, request, wait)?.map_err(link_err)
    }

    fn applied(&mut self, py: Python<'_>, request: Request, wait: Duration) -> PyResult<u32> {
        let plane_request = matches!(
            request,
            Request::MoveWindow { .. } | Request::ResizeWindow { .. }
        );
        let reply = match self.ask_raw(py, request, wait)? {
            Ok(r) => r,
            Err(e) if plane_request => return Err(no_2d(py, e)),
            Err(e) => return Err(link_err(e)),
        };
        match reply {
            Reply::Applied { scene_id } => Ok(scene_id),
            Reply::Refused(e) => Err(with_sentence::<Refused>(
                py,
                format!("refused, nothing changed: {e}"),
                e.to_string(),
            )),
            // A 2D edit refused, or a 1D one on a board with the overlay (and the reverse).
            Reply::Refused2d(e) => Err(with_sentence::<Refused>(
                py,
                format!("refused, nothing changed: {e}"),
                e.to_string(),
            )),
            other => Err(unexpected(other)),
        }
    }

    /// Sends `request` as [`Self::ask`] does: a running stream or a closed board raises here;
    /// the client's own failure is left for the caller to word.
    fn ask_raw(
        &mut self,
        py: Python<'_>,
        request: Request,
        wait: Duration,
    ) -> PyResult<Result<Reply, ClientError>> {
        if self.streaming {
            return Err(SawError::new_err(
                "a stream is running on this board: close it (or leave its `with` block) first",
            ));
        }
        let client = self.client()?;
        Ok(py.allow_threads(|| client.request_within(&request, wait)))
    }

    /// The board's active scene: `Reply::Scene` (1D) or `Reply::Scene2d`.
    fn scene(&mut self, py: Python<'_>, wait: Duration) -> PyResult<Reply> {
        match self.ask(py, Request::GetScene, wait)? {
            r @ (Reply::Scene { .. } | Reply::Scene2d { .. }) => Ok(r),
            other => Err(unexpected(other)),
        }
    }

    /// The sensor the board reads: the overlay's plate, or None for the rheostat (also a board
    /// from before 2D scenes, which answers "unknown request").
    fn sensor(&mut self, py: Python<'_>, wait: Duration) -> PyResult<Option<(u32, u32)>> {
        match self.ask_raw(py, Request::Sensor, wait)? {
            Ok(Reply::Sensor(Sensor::FourWire { plate_um })) => Ok(Some(plate_um)),
            Ok(Reply::Sensor(_)) => Ok(None),
            Err(ClientError::Link(saw_link::msg::LinkError::UnknownRequest { .. })) => Ok(None),
            Ok(other) => Err(unexpected(other)),
            Err(e) => Err(link_err(e)),
        }
    }

    /// A 1D call on a board with the overlay: the board's own sentence (the session's
    /// `Refused2d::WrongSensor`), raised before anything is sent where the call would first have
    /// to read a 1D scene the board does not have.
    fn not_1d(&self, py: Python<'_>, plate_um: (u32, u32)) -> PyErr {
        let e = Refused2d::WrongSensor {
            asked: SceneKind::Line,
            board: Sensor::FourWire { plate_um },
        };
        with_sentence::<Refused>(py, format!("refused, nothing changed: {e}"), e.to_string())
    }

    /// Loads the scene file `text` (named `name`): read and checked here, compiled on the board.
    fn push_text(
        &mut self,
        py: Python<'_>,
        name: &str,
        text: &str,
        wait: Duration,
    ) -> PyResult<u32> {
        let sensor =
            saw_core::scene_file::sensor_of(name, text).map_err(|e| input(e.to_string()))?;
        if sensor == saw_core::scene_file::SensorKind::FourWire {
            return self.push_2d(py, name, text, wait);
        }
        let doc = saw_core::scene_file::parse(name, text).map_err(|e| input(e.to_string()))?;
        match self.ask(py, Request::LoadScene(doc.config.clone()), wait)? {
            Reply::Applied { scene_id } => Ok(scene_id),
            // The board's refusal, located in the file as `saw push` prints it.
            Reply::Refused(e) => Err(with_sentence::<Refused>(
                py,
                doc.locate(&e).to_string(),
                e.to_string(),
            )),
            // A board with the touch overlay: the file is 1D.
            Reply::Refused2d(e) => Err(with_sentence::<Refused>(
                py,
                format!("{name}: refused by the board, nothing changed: {e}"),
                e.to_string(),
            )),
            other => Err(unexpected(other)),
        }
    }

    /// Loads a 2D scene file (`[sensor] kind = "4-wire"`): read and dry-run here for the board
    /// `hello` named, at its frame period, as `saw push` does (`saw::plane_scene_for_board`),
    /// then sent with its plate.
    fn push_2d(&mut self, py: Python<'_>, name: &str, text: &str, wait: Duration) -> PyResult<u32> {
        let scene = saw::plane_scene_for_board(&self.hello, name, text).map_err(input)?;
        let reply = self
            .ask_raw(py, Request::LoadScene2d(scene), wait)?
            .map_err(|e| no_2d(py, e))?;
        match reply {
            Reply::Applied { scene_id } => Ok(scene_id),
            Reply::Refused2d(e) => Err(with_sentence::<Refused>(
                py,
                format!("{name}: refused by the board, nothing changed: {e}"),
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
            Reply::Counters2d(c) => Ok(c.link.records_dropped),
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
    ) -> PyResult<Option<(Header, StreamFrame)>> {
        let client = self.client()?;
        py.allow_threads(|| client.next_stream(deadline))
            .map_err(link_err)
    }

    fn next_frame_2d(
        &mut self,
        py: Python<'_>,
        deadline: Instant,
    ) -> PyResult<Option<(Header, Stream2d)>> {
        let client = self.client()?;
        py.allow_threads(|| client.next_stream_2d(deadline))
            .map_err(link_err)
    }

    /// The next stream frame of whichever kind the board sends (its sensor's): its header, the
    /// board's drop count and its records.
    fn next_records(
        &mut self,
        py: Python<'_>,
        deadline: Instant,
    ) -> PyResult<Option<(Header, u32, Records)>> {
        if self.overlay.is_some() {
            let Some((h, s)) = self.next_frame_2d(py, deadline)? else {
                return Ok(None);
            };
            let records = s.records.iter().map(PyRecord2d::of).collect();
            Ok(Some((h, s.dropped, Records::Plane(records))))
        } else {
            let Some((h, s)) = self.next_frame(py, deadline)? else {
                return Ok(None);
            };
            let records = s.records.iter().map(PyRecord::of).collect();
            Ok(Some((h, s.dropped, Records::Line(records))))
        }
    }
}

/// A 2D request's failure: a board whose firmware has no 2D scenes answers "unknown request",
/// raised as the refusal it is (`saw`'s sentence); any other failure as usual.
fn no_2d(py: Python<'_>, e: ClientError) -> PyErr {
    match e {
        ClientError::Link(saw_link::msg::LinkError::UnknownRequest { .. }) => {
            with_sentence::<Refused>(
                py,
                format!("refused, nothing changed: {}", saw::NO_2D_FIRMWARE),
                saw::NO_2D_FIRMWARE.to_string(),
            )
        }
        e => link_err(e),
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
            overlay: None,
            streaming: false,
        };
        board.hello = board.hello_reply(py, timeout)?;
        board.overlay = board.sensor(py, timeout)?;
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

    /// The board reads the 4-wire touch overlay and runs 2D scenes (asked at open and at
    /// every `hello()`).
    #[getter]
    fn plane(&self) -> bool {
        self.overlay.is_some()
    }

    /// Who is there: protocol, firmware, board, samples/s (a board with the overlay: touch
    /// frames/s), the active scene's id and source, and the sensor it reads (`{"kind":
    /// "rheostat"}` or `{"kind": "4-wire", "plate_mm": [w, h]}`, as `saw --json hello`).
    #[pyo3(signature = (timeout_s = None))]
    fn hello(&mut self, py: Python<'_>, timeout_s: Option<f64>) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?;
        let h = self.hello_reply(py, wait)?;
        self.hello = h.clone();
        self.overlay = self.sensor(py, wait)?;
        // The names `saw --json hello` uses (a source as a word: "default", "saved", "link"),
        // with the scene id as a Python int.
        let mut v = serde_json::to_value(&h)
            .map_err(|e| SawError::new_err(format!("cannot convert a reply: {e}")))?;
        v["scene_source"] = saw::source_key(h.scene_source).into();
        v["sensor"] = match self.overlay {
            Some((w, h)) => serde_json::json!({
                "kind": "4-wire",
                "plate_mm": [w as f64 / 1000.0, h as f64 / 1000.0],
            }),
            None => serde_json::json!({ "kind": "rheostat" }),
        };
        to_python(py, &v)
    }

    /// Loads a scene: a scene file's path, or a dict shaped like one (`{"substrate": {...},
    /// "region": [{"kind": "grating", ...}, ...]}`, as `tomllib` reads a file; a 2D scene's
    /// `{"sensor": {"kind": "4-wire"}, "screen": {...}, "window": [...]}`). Read and checked
    /// here as `saw push` does, compiled on the board. Returns the scene id now running; raises
    /// `Refused` (nothing changed) with the board's `.sentence` (a 1D scene on a board with the
    /// overlay, a 2D one on a rheostat board too), `InputError` for a file that does not read.
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

    /// Loads a scene given as the text of a scene file (`name` stands for the file in error
    /// messages), as `push` loads a file. Returns the scene id now running.
    #[pyo3(name = "push_text", signature = (text, name = "<text>", timeout_s = None))]
    fn push_text_py(
        &mut self,
        py: Python<'_>,
        text: &str,
        name: &str,
        timeout_s: Option<f64>,
    ) -> PyResult<u32> {
        let wait = self.wait(timeout_s)?;
        self.push_text(py, name, text, wait)
    }

    /// The active scene: `{"scene_id": int, "scene_source": str, "scene": dict}`, the scene with the
    /// scene file's keys and units as `saw --json get` prints it.
    #[pyo3(signature = (timeout_s = None))]
    fn get(&mut self, py: Python<'_>, timeout_s: Option<f64>) -> PyResult<PyObject> {
        let wait = self.wait(timeout_s)?;
        // The scene file's keys and units (`saw --json get`): pushed back as a dict it is the
        // same scene (a 2D scene with its [sensor] and [screen] tables).
        let (scene_id, source, scene) = match self.scene(py, wait)? {
            Reply::Scene {
                scene_id,
                source,
                config,
            } => (scene_id, source, saw::scene_json(&config)),
            Reply::Scene2d {
                scene_id,
                source,
                scene,
            } => (scene_id, source, saw::scene_json_2d(&scene)),
            other => return Err(unexpected(other)),
        };
        let d = PyDict::new(py);
        d.set_item("scene_id", scene_id)?;
        d.set_item("scene_source", saw::source_key(source))?;
        d.set_item("scene", to_python(py, &scene)?)?;
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
        // change, the rest stay (a new kind starts from its defaults). A board with the overlay
        // has no regions: its own refusal of a 1D edit.
        let config = match self.scene(py, wait)? {
            Reply::Scene { config, .. } => config,
            Reply::Scene2d { scene, .. } => {
                let plate = self.overlay.unwrap_or(scene.plate_um);
                return Err(self.not_1d(py, plate));
            }
            other => return Err(unexpected(other)),
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

    /// Moves 2D window `index` whole so its bounding box's lower-left corner is at (`x_mm`,
    /// `y_mm`) on the plate (each 0 to 1000 mm; the board refuses a point off its plate), live,
    /// as `saw window INDEX --to X,Y`. Returns the scene id now running.
    #[pyo3(signature = (index, x_mm, y_mm, timeout_s = None))]
    fn move_window(
        &mut self,
        py: Python<'_>,
        index: i64,
        x_mm: f64,
        y_mm: f64,
        timeout_s: Option<f64>,
    ) -> PyResult<u32> {
        let window = index_u8("index", index)?;
        let to = point_um(("x_mm", x_mm), ("y_mm", y_mm))?;
        let wait = self.wait(timeout_s)?;
        self.applied(py, Request::MoveWindow { window, to }, wait)
    }

    /// Gives 2D window `index`, an axis-aligned rectangle, the corners (`x0_mm`, `y0_mm`)
    /// lower-left and (`x1_mm`, `y1_mm`) upper-right (each 0 to 1000 mm), live, as `saw window
    /// INDEX --rect X0,Y0,X1,Y1`; a polygon window is refused (it only moves). Returns the scene
    /// id now running.
    #[pyo3(signature = (index, x0_mm, y0_mm, x1_mm, y1_mm, timeout_s = None))]
    #[allow(clippy::too_many_arguments)]
    fn resize_window(
        &mut self,
        py: Python<'_>,
        index: i64,
        x0_mm: f64,
        y0_mm: f64,
        x1_mm: f64,
        y1_mm: f64,
        timeout_s: Option<f64>,
    ) -> PyResult<u32> {
        let window = index_u8("index", index)?;
        let lo = point_um(("x0_mm", x0_mm), ("y0_mm", y0_mm))?;
        let hi = point_um(("x1_mm", x1_mm), ("y1_mm", y1_mm))?;
        let wait = self.wait(timeout_s)?;
        self.applied(py, Request::ResizeWindow { window, lo, hi }, wait)
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
            // A board with the overlay: the 2D core's (readings, lifts, window switches, edge
            // pulses, …), the same link counters.
            Reply::Counters2d(c) => to_python(py, &c),
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
    /// record sampled after the board started this stream, none of an earlier one's (`Record`s;
    /// on a board with the touch overlay `Record2d`s, one every `every` touch frames). A stream
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
        let capacity = (rate_hz * seconds) as usize + 64;
        let mut records = if self.overlay.is_some() {
            Records::Plane(Vec::with_capacity(capacity))
        } else {
            Records::Line(Vec::with_capacity(capacity))
        };
        let mut tally = Tally::default();
        let stale_before = self.client()?.stale_records();
        let outcome = (|| loop {
            let now = Instant::now();
            if now >= end {
                return Ok(());
            }
            match self.next_records(py, end.min(now + wait))? {
                Some((h, dropped, batch)) => {
                    tally.frame(&h, dropped);
                    records.append(batch);
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

    /// A live stream: iterate for records as they come (`Record`s, or `Record2d`s on a board
    /// with the touch overlay), one every `every` samples (sampled after the board started
    /// it); it ends after `seconds` if given, else when closed (`with
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
    /// `Record`s or `Record2d`s, as the board sends them.
    pending: VecDeque<PyObject>,
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

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<PyObject>> {
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
            let frame = self.board.borrow_mut(py).next_records(py, deadline)?;
            match frame {
                Some((h, dropped, batch)) => {
                    self.tally.frame(&h, dropped);
                    self.pending.extend(batch.into_objects(py)?);
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
    m.add_class::<PyRecord2d>()?;
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
