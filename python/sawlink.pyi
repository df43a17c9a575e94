# Type stubs for `sawlink` (maturin ships this file in the wheel as sawlink/__init__.pyi, with
# py.typed). Typed here: the experiment runner and the analysis (`Experiment`, `analyze`,
# `ExperimentError`). The rest of the module (Board, Stream, Recording, Record, the other
# exceptions) is not stubbed yet: the module-level `__getattr__` below tells type checkers this
# stub is incomplete, so those names are `Any` rather than errors.

from os import PathLike
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Union

_Path = Union[str, PathLike[str]]

class SawError(Exception):
    """Every error this module raises: one sentence saying what went wrong and what to do."""

class InputError(SawError):
    """A value refused before anything was sent: the argument, the value and the rule."""

class ExperimentError(SawError):
    """A protocol, a session log or a data file refused, or the session's files not written:
    the experiment crate's own sentence."""

class Board:
    """A board on a serial port (not stubbed yet: its attributes are `Any`)."""

    def __init__(self, port: _Path, timeout_s: float = 1.0) -> None: ...
    def __getattr__(self, name: str) -> Any: ...

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
