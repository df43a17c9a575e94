"""Opening the port: a missing one, one another process holds, and a port nobody answers on each
raise their own exception type with one sentence."""

import os
import time

import pytest

import sawlink
from conftest import hold_port


def test_a_missing_port_raises_port_missing(tmp_path):
    path = tmp_path / "no-board"
    with pytest.raises(sawlink.PortMissing) as e:
        sawlink.Board(path)
    assert str(path) in str(e.value)
    assert isinstance(e.value, sawlink.PortError)
    assert isinstance(e.value, sawlink.SawError)


def test_a_port_held_by_another_process_raises_port_busy(vboard):
    holder = hold_port(vboard.port)
    try:
        with pytest.raises(sawlink.PortBusy) as e:
            sawlink.Board(vboard.port)
        assert "busy" in str(e.value)
    finally:
        holder.stdin.close()
        holder.wait(timeout=10)
    # Once the other process let go, the port opens.
    with sawlink.Board(vboard.port) as b:
        assert b.hello()["protocol"] == sawlink.PROTOCOL_VERSION


def test_a_port_nobody_answers_raises_no_answer_within_the_timeout():
    # A pty with no board behind it: the hello is written and never answered.
    master, slave = os.openpty()
    try:
        started = time.monotonic()
        with pytest.raises(sawlink.NoAnswer) as e:
            sawlink.Board(os.ttyname(slave), timeout_s=0.2)
        waited_s = time.monotonic() - started
        assert "200 ms" in str(e.value)
        print(f"no answer raised after {waited_s:.3f} s (timeout 0.2 s)")
    finally:
        os.close(master)
        os.close(slave)


def test_a_closed_board_refuses_calls(vboard):
    b = sawlink.Board(vboard.port)
    with b:
        b.hello()
    with pytest.raises(sawlink.SawError) as e:
        b.hello()
    assert "closed" in str(e.value)
    # And its port is free again.
    sawlink.Board(vboard.port).close()
