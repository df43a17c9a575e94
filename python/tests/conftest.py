"""Fixtures: the virtual board of `host-sim serve --pty PATH` as a subprocess (the same core and
link code as the firmware, docs/link.md), and a `sawlink.Board` opened on it.

`SAWLINK_HOST_SIM` names the host-sim binary (default: target/release/host-sim, which
scripts/python.sh --test builds)."""

import os
import signal
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

import sawlink

REPO = Path(__file__).resolve().parents[2]
# 1D scenes: a file with a [sensor] table is a 2D scene (issue #36, `scenes/2d-*.toml`, the rule
# of saw_core::scene_file::sensor_of), which runs on a board with the touch overlay
# (test_plane.py).
SCENES = sorted(p for p in (REPO / "scenes").glob("*.toml")
                if "sensor" not in tomllib.loads(p.read_text()))
SCENES_2D = sorted(p for p in (REPO / "scenes").glob("*.toml")
                   if "sensor" in tomllib.loads(p.read_text()))
HOST_SIM = Path(os.environ.get("SAWLINK_HOST_SIM", REPO / "target" / "release" / "host-sim"))


class VirtualBoard:
    """`host-sim serve --pty DIR/board [extra…]`, stopped (SIGINT: it removes its link) on close."""

    def __init__(self, directory: Path, *extra: str):
        if not HOST_SIM.exists():
            raise RuntimeError(f"{HOST_SIM} is missing: run `cargo build --release -p host-sim` "
                               "(scripts/python.sh --test does)")
        self.port = directory / "board"
        self.proc = subprocess.Popen(
            [str(HOST_SIM), "serve", "--pty", str(self.port), *extra],
            stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 10
        while not self.port.exists():
            if self.proc.poll() is not None:
                raise RuntimeError(f"host-sim serve exited: {self.proc.stderr.read()}")
            if time.monotonic() > deadline:
                self.close()
                raise RuntimeError("host-sim serve made no pty within 10 s")
            time.sleep(0.02)

    def close(self):
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stderr.close()


@pytest.fixture
def start_board(tmp_path):
    """Starts virtual boards in tmp_path (extra `host-sim serve` flags as arguments); each is
    stopped at the end of the test."""
    boards = []

    def start(*extra):
        vb = VirtualBoard(tmp_path, *extra)
        boards.append(vb)
        return vb

    yield start
    for vb in boards:
        vb.close()


@pytest.fixture
def vboard(start_board):
    return start_board()


@pytest.fixture
def board(vboard):
    with sawlink.Board(vboard.port, timeout_s=2.0) as b:
        yield b


def hold_port(port: Path):
    """Another process that opens `port` with sawlink and holds it until its stdin closes."""
    code = ("import sys, sawlink\n"
            f"b = sawlink.Board({str(port)!r})\n"
            "print('holding', flush=True)\n"
            "sys.stdin.read()\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = proc.stdout.readline()
    if line.strip() != "holding":
        proc.kill()
        raise RuntimeError(f"the holder did not open the port: {line} {proc.stderr.read()}")
    return proc
