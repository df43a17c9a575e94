"""The telemetry stream from Python: 10 s at 1 kHz without a drop (every record's time step and
the board's drop count), the live iterator, and set-then-stream trials that never mix scenes."""

import pytest

import sawlink

EVERY = 10                 # 1 kHz on the F446's 10 kHz loop
STEP_US = 1000             # one record per ms at that rate


def test_ten_seconds_at_one_kilohertz_arrive_without_a_drop(board):
    assert board.sample_rate_hz == 10_000
    before = board.counters()["link"]["records_dropped"]
    rec = board.record(seconds=10, every=EVERY)
    after = board.counters()["link"]["records_dropped"]
    print(rec)
    cols = rec.columns()
    t = cols["time_us"]
    steps = {b - a for a, b in zip(t, t[1:])}
    assert steps == {STEP_US}, f"time steps seen: {sorted(steps)[:10]}"
    # 10 s of board time, less what was still in flight when the recording ended (the frames'
    # latency: a few ms; 0.5 s is slack for a loaded machine, not a speed claim).
    assert t[-1] - t[0] >= 9_500_000, f"{len(t)} records over {(t[-1] - t[0]) / 1e6} s"
    assert rec.dropped == 0
    assert rec.frames_lost == 0
    assert after - before == 0
    assert {len(v) for v in cols.values()} == {len(rec)}
    assert rec[0].time_us == t[0] and rec[-1].time_us == t[-1]


def test_a_stream_the_line_cannot_carry_shows_its_drops(board):
    # Every sample (10 000 records/s) is more than the 921 600-baud line carries (docs/link.md,
    # "The line and the stream"), so the drop count and the time steps the 1 kHz check reads do
    # see drops when there are some.
    rec = board.record(seconds=1, every=1)
    t = rec.columns()["time_us"]
    missing = sum((b - a) // 100 - 1 for a, b in zip(t, t[1:]))
    print(rec, f"{missing} samples missing between records")
    assert missing > 0
    # The board's count also holds drops before the first record and after the last.
    assert rec.dropped >= missing


def test_to_pandas_when_pandas_is_there(board):
    rec = board.record(seconds=0.2, every=EVERY)
    try:
        import pandas  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError) as e:
            rec.to_pandas()
        assert "columns()" in str(e.value)
        return
    df = rec.to_pandas()
    assert list(df["time_us"]) == rec.columns()["time_us"]


def test_the_stream_iterator_yields_records_and_stops_on_exit(board):
    with board.stream(every=EVERY) as s:
        with pytest.raises(sawlink.SawError) as e:
            board.hello()
        assert "stream is running" in str(e.value)
        records = []
        for r in s:
            records.append(r)
            if len(records) == 300:
                break
        assert s.dropped == 0 and s.frames_lost == 0
    assert s.dropped == 0
    steps = {b.time_us - a.time_us for a, b in zip(records, records[1:])}
    assert steps == {STEP_US}
    # Stopped: the board answers requests again, and no stream frame is pending.
    assert board.hello()["protocol"] == sawlink.PROTOCOL_VERSION
    rec = board.record(seconds=0.3, every=EVERY)
    assert rec.from_us > records[-1].time_us
    assert rec[0].time_us >= rec.from_us


def test_a_stream_left_by_break_is_stopped_when_dropped(board):
    for _ in board.stream(every=EVERY):
        break
    # The iterator is gone (no `with`): the stream was stopped and the board takes requests.
    assert board.hello()["protocol"] == sawlink.PROTOCOL_VERSION


def test_a_stream_with_seconds_ends_by_itself(board):
    n = sum(1 for _ in board.stream(every=100, seconds=0.5))
    # 100 records/s for 0.5 s, give or take the frames in flight at either end.
    assert 30 <= n <= 70, n
    assert board.hello()["protocol"] == sawlink.PROTOCOL_VERSION


def test_twenty_set_then_stream_trials_never_mix_scenes(board):
    board.push({"region": [{"kind": "constant", "until_mm": 30, "f_b_hz": 80},
                           {"kind": "constant", "f_b_hz": 80}]})
    previous_id, previous_change = None, None
    for trial in range(20):
        # A distinct f_b each trial, so each trial's scene has its own id.
        scene_id = board.set(1, kind="constant", f_b_hz=100 + 10 * trial, duty_percent=40)
        assert scene_id != previous_id
        rec = board.record(seconds=0.2, every=EVERY)
        cols = rec.columns()
        assert len(rec) > 0, f"trial {trial}: no records"
        assert set(cols["scene_id"]) == {scene_id}, f"trial {trial}"
        assert previous_id not in cols["scene_id"]
        # One scene change per trial, and no record from before it.
        changes = set(cols["change"])
        assert len(changes) == 1, f"trial {trial}: changes {changes}"
        if previous_change is not None:
            assert changes == {previous_change + 1}, f"trial {trial}"
        assert min(cols["time_us"]) >= rec.from_us
        previous_id, previous_change = scene_id, changes.pop()
