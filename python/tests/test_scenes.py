"""Scenes through the module: every file in scenes/ pushed (as a file and as a dict) and read
back equal; live edits (boundary, set, drive) read back; refusals carry the board's sentence."""

import math
import tomllib

import pytest

import sawlink
from conftest import SCENES


def texture_kind(texture):
    """The scene-file kind of a texture as `get` returns it (serde: "Off" or {"Grating": …})."""
    name = texture if isinstance(texture, str) else next(iter(texture))
    return name.lower()


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_every_scene_round_trips_by_id_and_content(board, path):
    with open(path, "rb") as f:
        file = tomllib.load(f)
    boot = board.hello()
    scene_id = board.push(path)
    got = board.get()
    assert got["scene_id"] == scene_id
    # A pushed scene is the link's, unless it is the very scene the board booted with.
    assert got["source"] == (boot["scene_source"] if scene_id == boot["scene_id"] else "Link")
    assert board.hello()["scene_id"] == scene_id
    # The content, against the file as Python's own TOML reader reads it.
    scene = got["config"]["scene"]
    regions = file["region"]
    assert [texture_kind(t) for t in scene["textures"]] == [r["kind"] for r in regions]
    assert scene["boundaries_um"] == [round(r["until_mm"] * 1000) for r in regions if "until_mm" in r]
    if "substrate" in file:
        assert got["config"]["calibration"]["length_um"] == round(file["substrate"]["length_mm"] * 1000)
    if "drive" in file:
        assert scene["drive"] == file["drive"].capitalize()
    if "hysteresis_mm" in file:
        assert scene["hysteresis_um"] == round(file["hysteresis_mm"] * 1000)
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
    assert got["config"]["scene"]["boundaries_um"][0] == 30_000

    assert board.drive("progressive") == board.get()["scene_id"]
    assert board.get()["config"]["scene"]["drive"] == "Progressive"

    changed = board.set(1, kind="constant", f_b_hz=150, duty_percent=30)
    texture = board.get()["config"]["scene"]["textures"][1]
    assert board.get()["scene_id"] == changed
    assert texture == {"Constant": {"burst_millihz": 150_000, "duty_permille": 300}}
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
