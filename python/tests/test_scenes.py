"""Scenes through the module: every file in scenes/ pushed (as a file and as a dict) and read
back equal; live edits (boundary, set, drive) read back; refusals carry the board's sentence."""

import math
import tomllib

import pytest

import sawlink
from conftest import SCENES


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_every_scene_round_trips_by_id_and_content(board, path):
    with open(path, "rb") as f:
        file = tomllib.load(f)
    boot = board.hello()
    scene_id = board.push(path)
    got = board.get()
    assert got["scene_id"] == scene_id
    # A pushed scene is the link's, unless it is the very scene the board booted with.
    assert got["scene_source"] == (boot["scene_source"] if scene_id == boot["scene_id"] else "link")
    assert board.hello()["scene_id"] == scene_id
    # The content in the scene file's keys, against the file as Python's own TOML reader reads it.
    scene = got["scene"]
    regions = file["region"]
    assert [r["kind"] for r in scene["region"]] == [r["kind"] for r in regions]
    assert [r.get("until_mm") for r in scene["region"]] == [r.get("until_mm") for r in regions]
    if "substrate" in file:
        assert scene["substrate"]["length_mm"] == file["substrate"]["length_mm"]
    if "drive" in file:
        assert scene["drive"] == file["drive"]
    if "hysteresis_mm" in file:
        assert scene["hysteresis_mm"] == file["hysteresis_mm"]
    # The id is the file's on every host: the module reads the file as the board compiled it.
    assert sawlink.scene_id_of_file(path) == scene_id

    # The same scene as a dict (tomllib's reading of the file): the same id, the same content.
    other = SCENES[0] if path != SCENES[0] else SCENES[1]
    assert board.push(other) != scene_id, "the next push must change the scene to show anything"
    assert board.push(file) == scene_id
    assert board.get() == got


def test_boundary_drive_and_set_read_back(board):
    board.push(next(p for p in SCENES if p.stem == "grating"))
    moved = board.boundary(0, 30.0)
    got = board.get()
    assert got["scene_id"] == moved
    assert got["scene"]["region"][0]["until_mm"] == 30

    assert board.drive("progressive") == board.get()["scene_id"]
    assert board.get()["scene"]["drive"] == "progressive"

    changed = board.set(1, kind="constant", f_b_hz=150, duty_percent=30)
    region = board.get()["scene"]["region"][1]
    assert board.get()["scene_id"] == changed
    assert (region["kind"], region["f_b_hz"], region["duty_percent"]) == ("constant", 150, 30)
    # A key alone keeps the region's other values (the duty set above).
    board.set(1, f_b_hz=90)
    region = board.get()["scene"]["region"][1]
    assert (region["f_b_hz"], region["duty_percent"]) == (90, 30)
    # What get gives pushes back as the same scene.
    assert board.push(board.get()["scene"]) == board.get()["scene_id"]
    # The command line's spelling gives the same scene.
    board.set(1, "kind=grating", "wavelength_mm=2")
    assert board.set(1, "kind=constant", "f_b_hz=150", "duty_percent=30") == changed


def test_a_refused_scene_raises_with_the_boards_sentence_and_changes_nothing(board):
    before = board.hello()["scene_id"]
    # Reads fine on the host (every value in its range) but f_b is above the board's limit:
    # only the board's dry run refuses it.
    too_fast = {"region": [{"kind": "constant", "until_mm": 20, "f_b_hz": 80},
                           {"kind": "constant", "f_b_hz": 9000}]}
    with pytest.raises(sawlink.Refused) as e:
        board.push(too_fast)
    assert "above this board's limit" in e.value.sentence
    assert "region[1]" in str(e.value)
    assert board.hello()["scene_id"] == before

    with pytest.raises(sawlink.Refused) as e:
        board.set(0, kind="constant", f_b_hz=9000)
    assert "above this board's limit" in e.value.sentence
    with pytest.raises(sawlink.Refused) as e:
        board.boundary(0, 500.0)
    assert e.value.sentence
    assert board.hello()["scene_id"] == before


def test_values_are_checked_at_the_door(board, tmp_path):
    for call, words in [
        (lambda: board.boundary(0, math.nan), "mm = nan"),
        (lambda: board.boundary(0, -1.0), "mm = -1"),
        (lambda: board.boundary(256, 10.0), "index = 256"),
        (lambda: board.hello(timeout_s=0.0), "timeout_s = 0"),
        (lambda: board.hello(timeout_s=math.inf), "timeout_s = inf"),
        (lambda: board.record(seconds=0.0), "seconds = 0"),
        (lambda: board.record(seconds=1.0, every=0), "every = 0"),
        (lambda: board.drive("sideways"), "sideways"),
        (lambda: board.set(0, kind="constant", f_b_hz=math.nan), "f_b_hz = nan"),
        (lambda: board.set(0, kind="constant", f_b_hz=-3), "f_b_hz"),
        (lambda: board.push({"region": [{"kind": "velvet"}]}), "velvet"),
        (lambda: board.push(tmp_path / "none.toml"), "none.toml"),
    ]:
        with pytest.raises(sawlink.InputError) as e:
            call()
        assert words.lower() in str(e.value).lower(), str(e.value)
    with pytest.raises(sawlink.InputError):
        sawlink.Board(board.port, timeout_s=-1)
