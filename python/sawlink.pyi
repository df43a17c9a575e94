# Type stubs for `sawlink` (maturin ships this file in the wheel as sawlink/__init__.pyi, with
# py.typed). Typed here: the board (`Board`, its records, recordings and streams, 1D and 2D), the
# experiment runner and the analysis (`Experiment`, `analyze`), and the exceptions. The
# module-level `__getattr__` below keeps anything not stubbed `Any` rather than an error.

from os import PathLike
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Sequence, Union

_Path = Union[str, PathLike[str]]

class SawError(Exception):
    """Every error this module raises: one sentence saying what went wrong and what to do."""

class InputError(SawError):
    """A value refused before anything was sent: the argument, the value and the rule."""

class ExperimentError(SawError):
    """A protocol, a session log or a data file refused, or the session's files not written:
    the experiment crate's own sentence."""

class PortError(SawError):
    """The port could not be opened or failed."""

class PortMissing(PortError):
    """No such port: the board is not plugged in (or no virtual board serves that path)."""

class PortBusy(PortError):
    """Another program (a `saw`, the web panel, another Board) holds the port."""

class NoAnswer(SawError):
    """The board did not answer within the call's timeout."""

class ProtocolError(SawError):
    """Another protocol version, a refused frame, an out-of-turn reply."""

class Refused(SawError):
    """The board refused the change and nothing changed (a 1D call on a board with the touch
    overlay, or a 2D one on a rheostat board, too)."""
    sentence: str

class SaveFailed(SawError):
    """The save failed; the scene saved before (if any) is kept."""
    sentence: str

class Record:
    """One telemetry record of a board with the slide rheostat (1D scenes)."""
    time_us: int
    scene_id: int
    change: int
    position_um: Optional[int]
    velocity_um_s: Optional[int]
    region: Optional[int]
    burst_millihz: int
    bursting: bool
    fault: Optional[str]
    @property
    def f_b_hz(self) -> float: ...

class Record2d:
    """One telemetry record of a board with the 4-wire touch overlay (2D scenes, issue #36)."""
    time_us: int
    scene_id: int
    change: int
    x_um: Optional[int]
    y_um: Optional[int]
    vx_um_s: Optional[int]
    vy_um_s: Optional[int]
    edge: Optional[int]
    burst_millihz: int
    bursting: bool
    lifted: bool
    fault: Optional[str]
    @property
    def window(self) -> Union[int, str, None]:
        """The window's index, "background", or None while nothing renders."""
    @property
    def f_b_hz(self) -> float: ...

class Recording:
    """Records gathered by `Board.record`: `Record`s, or `Record2d`s on a 2D board."""
    dropped: int
    frames_lost: int
    bad_frames: int
    stale: int
    from_us: int
    rate_hz: float
    every: int
    @property
    def plane(self) -> bool: ...
    def __len__(self) -> int: ...
    def __getitem__(self, i: int) -> Union[Record, Record2d]: ...
    def columns(self) -> Dict[str, List[Any]]: ...
    def to_pandas(self) -> Any: ...

class Stream:
    """A live stream from `Board.stream`: iterate for records; `with` stops it."""
    rate_hz: float
    from_us: int
    @property
    def dropped(self) -> int: ...
    @property
    def frames_lost(self) -> int: ...
    def __iter__(self) -> Iterator[Union[Record, Record2d]]: ...
    def __next__(self) -> Union[Record, Record2d]: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Stream": ...
    def __exit__(self, *exc: Any) -> bool: ...

class Board:
    """A board (or a virtual one) on a serial port, opened once and locked while open."""

    def __init__(self, port: _Path, timeout_s: float = 1.0) -> None: ...
    @property
    def port(self) -> Path: ...
    @property
    def sample_rate_hz(self) -> int: ...
    @property
    def plane(self) -> bool:
        """The board reads the 4-wire touch overlay and runs 2D scenes."""
    def hello(self, timeout_s: Optional[float] = None) -> Dict[str, Any]: ...
    def push(self, scene: Union[_Path, Dict[str, Any]], timeout_s: Optional[float] = None) -> int: ...
    def push_text(self, text: str, name: str = "<text>", timeout_s: Optional[float] = None) -> int: ...
    def get(self, timeout_s: Optional[float] = None) -> Dict[str, Any]: ...
    def set(self, region: int, *pairs: str, timeout_s: Optional[float] = None, **keys: Any) -> int: ...
    def boundary(self, index: int, mm: float, timeout_s: Optional[float] = None) -> int: ...
    def move_window(
        self, index: int, x_mm: float, y_mm: float, timeout_s: Optional[float] = None
    ) -> int: ...
    def resize_window(
        self,
        index: int,
        x0_mm: float,
        y0_mm: float,
        x1_mm: float,
        y1_mm: float,
        timeout_s: Optional[float] = None,
    ) -> int: ...
    def drive(self, mode: str, timeout_s: Optional[float] = None) -> int: ...
    def counters(self, reset: bool = False, timeout_s: Optional[float] = None) -> Dict[str, Any]: ...
    def save(self, timeout_s: Optional[float] = None) -> Dict[str, Any]: ...
    def ping(self) -> Dict[str, int]: ...
    def record(self, seconds: float, every: int = 10, timeout_s: Optional[float] = None) -> Recording: ...
    def stream(
        self, every: int = 10, seconds: Optional[float] = None, timeout_s: Optional[float] = None
    ) -> Stream: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Board": ...
    def __exit__(self, *exc: Any) -> bool: ...

def scene_id_of_file(path: _Path) -> int: ...

PROTOCOL_VERSION: int
SAVE_TIMEOUT_S: float

class Experiment:
    """A protocol run with one participant: the runner, its log (`<subject>.log.jsonl`, `.csv`,
    `.json` in `out_dir`) and the board the stimuli are presented on, if any."""

    def __init__(
        self,
        protocol_path: _Path,
        subject: str,
        out_dir: _Path,
        subject_index: Optional[int] = None,
        resume: bool = False,
        board: Optional[Board] = None,
    ) -> None: ...
    def next_trial(self) -> Optional[Dict[str, Any]]:
        """The trial awaiting a response, or None when the session is over: number, block,
        block_number, design, intervals ([{stimulus, prompt, beta_um}]), question, words,
        values, track, level, target, break_before."""
    def present(self, k: int) -> Dict[str, Any]:
        """Presents interval k (0-based) of the pending trial; returns its exploration:
        interval, stimulus, scene_id, board_from_us, board_to_us, records, explored_s, strokes,
        mean_speed_mm_s, peak_speed_mm_s, distance_mm, f_b_hz, faults."""
    def respond(self, value: int, response_ms: Optional[float] = None) -> Dict[str, Any]:
        """Answers the pending trial (ValueError for a value it does not allow, nothing
        changed), logs and syncs it; returns trial, response, word, correct, reversal."""
    def rf_off(self) -> int:
        """Loads the protocol's RF-off scene on the board; its scene id."""
    @property
    def answered(self) -> int: ...
    @property
    def planned_trials(self) -> int: ...
    @property
    def finished(self) -> bool: ...
    @property
    def csv_path(self) -> Path: ...
    @property
    def log_path(self) -> Path: ...
    @property
    def sidecar_path(self) -> Path: ...
    @property
    def subject(self) -> str: ...
    @property
    def subject_index(self) -> int: ...
    @property
    def name(self) -> str: ...
    @property
    def instructions(self) -> str: ...
    @property
    def timing(self) -> Dict[str, Any]:
        """explore_s, pause_s, rf_off_between."""
    def __enter__(self) -> "Experiment": ...
    def __exit__(self, *exc: Any) -> bool: ...

def analyze(
    files: Union[_Path, Sequence[_Path]],
    method: Optional[str] = None,
    bootstrap: int = 1000,
) -> Dict[str, Any]:
    """Analyses session CSVs (or a lab's `subject,first,second,score` CSV) as `saw experiment
    analyze` does; the report as `saw --json experiment analyze` prints it: paired (per block
    Scheffé's analysis, `scale` keyed by stimulus, Thurstone, Bradley–Terry), correlations,
    tracks, constant. `method`: "scheffe", "ura", "haga", "nakaya" or None."""

def __getattr__(name: str) -> Any: ...
