"""The experiment runner from Python (`sawlink.Experiment`), as a PsychoPy script drives it:
a tiny paired protocol run trial by trial on the virtual board (next_trial → present each
interval → respond), the CSV it writes, a refused response that changes nothing, a session
stopped halfway and resumed in the same order, and the analysis of the CSV (`sawlink.analyze`)."""

import csv
import json

import pytest

import sawlink

# Three virtual objects (f_b 20, 40 and 80 Hz), every ordered pair once (Ura's variant: six
# trials), short windows so a session takes a few seconds.
PROTOCOL = """
[experiment]
name = "tiny roughness"
seed = 7

[timing]
explore_s = 0.2
pause_s = 0.05

[[stimulus]]
name = "20 Hz"
region = { kind = "constant", f_b_hz = 20, duty_percent = 40 }

[[stimulus]]
name = "40 Hz"
region = { kind = "constant", f_b_hz = 40, duty_percent = 40 }

[[stimulus]]
name = "80 Hz"
region = { kind = "constant", f_b_hz = 80, duty_percent = 40 }

[[block]]
name = "virtual"
design = "paired"
variant = "ura"
stimuli = ["20 Hz", "40 Hz", "80 Hz"]
"""

TRIALS = 6


@pytest.fixture
def protocol(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(PROTOCOL)
    return path


def hz(name):
    return float(name.split()[0])


def grade(first_hz, second_hz):
    """The participant: a lower f_b feels rougher (the seed paper's finding); positive grades
    say the first was rougher, two grades when the f_b differ fourfold."""
    if first_hz == second_hz:
        return 0
    ratio = max(first_hz, second_hz) / min(first_hz, second_hz)
    g = 2 if ratio >= 4 else 1
    return g if first_hz < second_hz else -g


def rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def answer_without_presenting(exp, n):
    """Answers `n` trials as a script that presents them itself would; returns their stimuli."""
    order = []
    for _ in range(n):
        t = exp.next_trial()
        first, second = (iv["stimulus"] for iv in t["intervals"])
        exp.respond(grade(hz(first), hz(second)))
        order.append((t["number"], first, second))
    return order


def test_a_script_runs_a_paired_protocol_on_the_board(board, protocol, tmp_path):
    out = tmp_path / "sessions"
    exp = sawlink.Experiment(protocol, "s01", out, board=board)
    assert (exp.answered, exp.planned_trials, exp.finished) == (0, TRIALS, False)
    assert exp.timing == {"explore_s": 0.2, "pause_s": 0.05, "rf_off_between": True}
    presented = []
    while (trial := exp.next_trial()) is not None:
        assert trial["design"] == "paired" and trial["block"] == "virtual"
        assert trial["values"] == [-2, -1, 0, 1, 2] and len(trial["words"]) == 5
        assert [iv["prompt"] for iv in trial["intervals"]] == [None, None]
        shown = [exp.present(k) for k in range(len(trial["intervals"]))]
        for k, e in enumerate(shown):
            assert e["interval"] == k
            assert e["stimulus"] == trial["intervals"][k]["stimulus"]
            # The board's own f_b while the finger (60 mm/s, back and forth) explored it.
            assert e["f_b_hz"] == hz(e["stimulus"]), e
            assert e["explored_s"] > 0.1 and e["records"] > 100 and e["faults"] == 0, e
            assert e["board_to_us"] > e["board_from_us"], e
        # The RF-off scene between stimuli (rf_off_between, the default).
        assert [r["kind"] for r in board.get()["scene"]["region"]] == ["off"]
        value = grade(shown[0]["f_b_hz"], shown[1]["f_b_hz"])
        outcome = exp.respond(value, response_ms=812.5)
        assert outcome["response"] == value
        assert outcome["word"] == trial["words"][trial["values"].index(value)]
        assert outcome["trial"]["number"] == trial["number"]
        presented.append((trial, shown, value))
    assert (exp.answered, exp.finished) == (TRIALS, True)
    with pytest.raises(sawlink.ExperimentError) as e:
        exp.respond(0)
    assert "the session is over" in str(e.value)
    with pytest.raises(sawlink.ExperimentError):
        exp.present(0)

    # The CSV: a row per trial, as presented and answered, synced before each respond returned.
    assert exp.csv_path == out / "s01.csv"
    got = rows(exp.csv_path)
    assert len(got) == TRIALS
    for row, (trial, shown, value) in zip(got, presented):
        assert row["subject"] == "s01" and row["subject_index"] == "0"
        assert int(row["trial"]) == trial["number"]
        assert (row["first"], row["second"]) == (shown[0]["stimulus"], shown[1]["stimulus"])
        assert int(row["response"]) == value and int(row["score"]) == value
        assert row["design"] == "paired" and row["block"] == "virtual"
        assert float(row["response_ms"]) == 812.5
        for k, side in enumerate(["first", "second"]):
            assert row[f"{side}_scene_id"] == f"{shown[k]['scene_id']:#010x}"
            assert float(row[f"{side}_f_b_hz"]) == shown[k]["f_b_hz"]
            assert int(row[f"{side}_strokes"]) == shown[k]["strokes"]
    # Every ordered pair once: Ura's variant.
    assert len({(r["first"], r["second"]) for r in got}) == TRIALS
    # The same stimulus ran as the same scene every time it was shown.
    ids = {}
    for _, shown, _ in presented:
        for e in shown:
            assert ids.setdefault(e["stimulus"], e["scene_id"]) == e["scene_id"]
    sidecar = json.loads(exp.sidecar_path.read_text())
    assert sidecar["trials"] == TRIALS
    assert sidecar["session"]["runner"] == f"sawlink {sawlink.__version__}"
    assert sidecar["session"]["board"]["board"] == board.hello()["board"]
    assert sidecar["scene_ids"] == {k: f"{v:#010x}" for k, v in ids.items()}
    assert len(exp.log_path.read_text().splitlines()) == 1 + TRIALS
    # Graded from the f_b the board produced, the scale comes out in the f_b's order.
    scale = sawlink.analyze(exp.csv_path)["paired"][0]["scale"]
    assert scale["20 Hz"] > scale["40 Hz"] > scale["80 Hz"], scale


def test_a_bad_response_is_refused_and_changes_nothing(protocol, tmp_path):
    # No board: the script presents the stimuli itself and only hands back the responses.
    exp = sawlink.Experiment(protocol, "s02", tmp_path / "sessions")
    trial = exp.next_trial()
    for bad, words in [(7, "response 7 is not one this trial allows (it takes -2, -1, 0, 1, 2)"),
                       (-3, "response -3 is not one"),
                       (2**40, "is not one this trial allows"),
                       ("1", "'1' (a str, not an int)"),
                       (1.0, "(a float, not an int)"),
                       (True, "(a bool, not an int)")]:
        with pytest.raises(ValueError) as e:
            exp.respond(bad)
        assert words in str(e.value), str(e.value)
    assert exp.answered == 0
    assert exp.next_trial() == trial
    assert rows(exp.csv_path) == []
    assert len(exp.log_path.read_text().splitlines()) == 1, "only the session header"
    with pytest.raises(sawlink.InputError) as e:
        exp.respond(1, response_ms=-1)
    assert "response_ms = -1" in str(e.value)
    # A scene to present and no board to present it on.
    with pytest.raises(sawlink.ExperimentError) as e:
        exp.present(0)
    assert "board=sawlink.Board" in str(e.value)
    with pytest.raises(sawlink.InputError) as e:
        exp.present(2)
    assert "k = 2" in str(e.value)

    with pytest.raises(sawlink.InputError) as e:
        sawlink.Experiment(protocol, "../s02", tmp_path / "sessions")
    assert str(e.value).startswith('subject "../s02" must be 1 to 64 letters'), str(e.value)
    with pytest.raises(sawlink.InputError) as e:
        sawlink.Experiment(protocol, "s09", tmp_path / "sessions", subject_index=-1)
    assert "subject_index = -1" in str(e.value)
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.Experiment(tmp_path / "none.toml", "s09", tmp_path / "sessions")
    assert "none.toml: (file): cannot be read" in str(e.value), str(e.value)

    outcome = exp.respond(1)
    assert outcome["response"] == 1 and exp.answered == 1
    [row] = rows(exp.csv_path)
    # Presented by the script: the stimuli named, nothing measured.
    assert (row["first"], row["second"]) == tuple(iv["stimulus"] for iv in trial["intervals"])
    assert row["response"] == "1" and row["first_scene_id"] == "" and row["first_explored_s"] == ""
    assert float(row["response_ms"]) >= 0


def test_a_session_stopped_halfway_resumes_at_its_trial_in_the_same_order(protocol, tmp_path):
    # The uninterrupted order, for reference.
    whole = sawlink.Experiment(protocol, "s03", tmp_path / "whole", subject_index=0)
    reference = answer_without_presenting(whole, TRIALS)
    assert whole.finished

    out = tmp_path / "stopped"
    exp = sawlink.Experiment(protocol, "s03", out, subject_index=0)
    first_half = answer_without_presenting(exp, 3)
    in_progress = exp.next_trial()          # handed out, never answered: the script stopped
    assert in_progress["number"] == 3
    del exp

    # Without resume a second session of the subject is refused, and nothing changes.
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.Experiment(protocol, "s03", out, subject_index=0)
    assert "resume=True continues it" in str(e.value)
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.Experiment(protocol, "nobody", out, resume=True)
    assert "no session of subject nobody" in str(e.value) and "--" not in str(e.value)
    # A changed protocol cannot continue the session.
    changed = tmp_path / "changed.toml"
    changed.write_text(PROTOCOL.replace("seed = 7", "seed = 8"))
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.Experiment(changed, "s03", out, resume=True)
    assert "differs from the one this session began with" in str(e.value)
    assert len(rows(out / "s03.csv")) == 3

    resumed = sawlink.Experiment(protocol, "s03", out, resume=True)
    assert resumed.answered == 3 and resumed.subject_index == 0
    assert resumed.next_trial() == in_progress
    second_half = answer_without_presenting(resumed, TRIALS - 3)
    assert resumed.finished
    assert first_half + second_half == reference
    got = [(int(r["trial"]), r["first"], r["second"]) for r in rows(resumed.csv_path)]
    assert got == reference, "no trial lost, none repeated, the order unchanged"


def test_external_objects_are_timed_without_a_board(tmp_path):
    path = tmp_path / "sandpaper.toml"
    path.write_text("""
[experiment]
name = "sandpapers"
seed = 1
[timing]
explore_s = 0.05
pause_s = 0
[[stimulus]]
name = "#60"
external = "Place sandpaper #60."
[[stimulus]]
name = "#320"
external = "Place sandpaper #320."
[[block]]
name = "real"
design = "paired"
variant = "nakaya"
stimuli = ["#60", "#320"]
""")
    exp = sawlink.Experiment(path, "s04", tmp_path / "sessions")
    trial = exp.next_trial()
    assert {iv["prompt"] for iv in trial["intervals"]} == {"Place sandpaper #60.", "Place sandpaper #320."}
    e = exp.present(0)
    assert e["stimulus"] == trial["intervals"][0]["stimulus"]
    assert e["scene_id"] is None and e["explored_s"] is None
    exp.respond(-1)
    assert exp.finished
    [row] = rows(exp.csv_path)
    assert row["first_scene_id"] == "" and row["response"] == "-1"


def test_the_sessions_csvs_are_analysed_and_the_scale_keyed_by_stimulus(protocol, tmp_path):
    out = tmp_path / "sessions"
    for s in range(3):
        # Subject indices from the sessions already in `out`: 0, 1, 2.
        exp = sawlink.Experiment(protocol, f"s{s}", out)
        assert exp.subject_index == s
        answer_without_presenting(exp, TRIALS)
    csvs = [out / f"s{s}.csv" for s in range(3)]
    r = sawlink.analyze(csvs)
    [block] = r["paired"]
    assert (block["block"], block["subjects"], block["judgments"]) == ("virtual", 3, 18)
    assert block["scheffe"]["variant"] == "ura"
    scale = block["scale"]
    assert set(scale) == {"20 Hz", "40 Hz", "80 Hz"}
    # A lower f_b judged rougher: the participant's order.
    assert scale["20 Hz"] > scale["40 Hz"] > scale["80 Hz"], scale
    assert abs(sum(scale.values())) < 1e-9
    assert set(block["thurstone"]) == set(scale)
    # Every choice went one way (20 Hz always won): Bradley–Terry has no finite fit then.
    assert block["bradley_terry"] is None
    assert r["tracks"] == [] and r["constant"] == []
    # The same as `saw experiment analyze` reads them: a single path works too.
    assert sawlink.analyze(str(csvs[0]), method="ura")["paired"][0]["judgments"] == 6

    # A lab's own CSV: the block is the file.
    lab = tmp_path / "lab.csv"
    lines = ["subject,first,second,score"]
    for row in csvs:
        for t in rows(row):
            lines.append(f"{t['subject']},{t['first']},{t['second']},{t['score']}")
    lab.write_text("\n".join(lines) + "\n")
    [lab_block] = sawlink.analyze([lab])["paired"]
    assert lab_block["block"] == str(lab)
    assert lab_block["scale"] == pytest.approx(scale)

    # Refusals carry the crate's sentences.
    bad = tmp_path / "bad.csv"
    bad.write_text("subject,first,score\ns1,a,1\n")
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.analyze([bad])
    assert "has no column second" in str(e.value)
    with pytest.raises(sawlink.ExperimentError) as e:
        sawlink.analyze([tmp_path / "none.csv"])
    assert "none.csv" in str(e.value)
    with pytest.raises(sawlink.InputError) as e:
        sawlink.analyze(csvs, method="velvet")
    assert 'method = "velvet"' in str(e.value)
    with pytest.raises(sawlink.InputError) as e:
        sawlink.analyze(csvs, bootstrap=-1)
    assert "bootstrap = -1" in str(e.value)
    with pytest.raises(sawlink.InputError):
        sawlink.analyze([])
