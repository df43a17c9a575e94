"""Saving: the board boots into the saved scene; a board without a store says so."""

import time

import pytest

import sawlink
from conftest import SCENES, VirtualBoard


def test_a_saved_scene_survives_a_restart(tmp_path, start_board):
    flash = tmp_path / "flash.bin"
    vb = start_board("--flash", str(flash))
    grating = next(p for p in SCENES if p.stem == "grating")
    with sawlink.Board(vb.port) as b:
        assert b.hello()["scene_source"] == "default"
        scene_id = b.push(grating)
        saved = b.save()
        assert saved["scene_id"] == scene_id
        assert saved["seconds"] >= 0
    vb.close()
    vb = start_board("--flash", str(flash))
    with sawlink.Board(vb.port) as b:
        hello = b.hello()
        assert (hello["scene_id"], hello["scene_source"]) == (scene_id, "saved")


def test_a_board_without_a_store_raises_save_failed(board):
    with pytest.raises(sawlink.SaveFailed) as e:
        board.save()
    assert e.value.sentence == "this board has no scene store"


def test_counters_count_and_reset(board):
    time.sleep(0.3)
    c = board.counters()
    assert c["core"]["samples"] > 0
    assert c["link"]["frames_ok"] >= 2
    board.counters(reset=True)
    after = board.counters()
    # Counting starts again from the reset: this read's frame, and the samples of a round trip
    # (without the reset: every sample since boot, more than the first read's 0.3 s).
    assert after["link"]["frames_ok"] <= 2
    assert after["core"]["samples"] < c["core"]["samples"]
