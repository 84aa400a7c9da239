"""A lab's files as they come: per-sensor trial folders joined on the model's clock, headerless
whitespace text, ISO-8601 time with a zone, flag columns, a BOM and untidy header names, blank
cells under each policy and a table split at its pauses; each bad input one line naming the file
and row (exit 2), or skipped with --skip-bad and counted. Every expected value is computed here
by hand from the signals the fixtures write."""

from __future__ import annotations

import datetime as dt
import json
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.robot_logs.write import write_mapping
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import parse_mapping
from neural_asm.logs.sources import read_mapped
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings

T0 = 1_700_000_000.0  # the trials' clock: seconds since the epoch
PERIOD_S, STEPS = 0.1, 10
runner = CliRunner()


def _iso(seconds: float, hours: int) -> str:
    """``seconds`` since the epoch as ISO-8601 text in a zone ``hours`` east of UTC."""
    zone = dt.timezone(dt.timedelta(hours=hours))
    return dt.datetime.fromtimestamp(seconds, zone).isoformat(timespec="milliseconds")


def write_trial(folder: Path, offset: float = 0.0, swap_joint_rows: bool = False, lost_from: float = 0.8) -> Path:
    """A trial's folder, one file per sensor, each on its own clock and rate, 1.2 s long:
    wrench.csv (200 Hz, time in ms, fx = 2 t + 1), joints.txt (30 Hz, headerless whitespace
    with mixed tabs, spaces and trailing tabs, seconds, q = t^2) and pose.csv (20 Hz, ISO-8601
    time at UTC+02:00, x = 3 - t, and a grip_lost flag true from ``lost_from``); t is seconds after T0."""
    folder.mkdir(parents=True)
    wrench = 0.013 + np.arange(240) / 200
    lines = ["t_ms,fx"] + [f"{(T0 + s) * 1000:.3f},{2 * s + 1 + offset:.9f}" for s in wrench]
    (folder / "wrench.csv").write_text("\n".join(lines) + "\n")
    joints = 0.02 + np.arange(36) / 30
    rows = [f"{T0 + s:.6f} \t {s * s + offset:.9f}\t\t" for s in joints]
    if swap_joint_rows:
        rows[6], rows[7] = rows[7], rows[6]
    (folder / "joints.txt").write_text("\n".join(rows) + "\n")
    pose = 0.05 + np.arange(24) / 20
    lines = ["Timestamp,x,grip_lost"] + [f"{_iso(T0 + s, 2)},{3 - s + offset:.9f},{'TRUE' if s >= lost_from else 'FALSE'}"
                                         for s in pose]
    (folder / "pose.csv").write_text("\n".join(lines) + "\n")
    return folder


def trial_mapping(**table) -> dict:
    return {"timing": {"period_s": PERIOD_S, "steps": STEPS},
            "table": {"parts": [
                {"files": "wrench*.csv", "time_column": "t_ms", "time_unit": "ms", "columns": ["fx"]},
                {"files": "joints*.txt", "time_column": 0, "header": False, "names": ["t", "q"], "columns": ["q"]},
                {"files": "pose*.csv", "time_column": "Timestamp", "time_unit": "iso", "columns": ["x", "grip_lost"]},
            ], "skill": {"value": "reach"}, "label": {"flag": "grip_lost"}, **table},
            "channels": [{"name": "fx", "units": "N", "column": "fx"},
                         {"name": "joint1", "units": "rad", "column": "q", "joint": True},
                         {"name": "x", "units": "m", "column": "x"}]}


def test_a_trial_folder_of_three_parts_is_one_episode_on_the_model_clock(tmp_path):
    write_trial(tmp_path / "trials" / "trial_0")
    write_trial(tmp_path / "trials" / "trial_1", offset=10.0)
    seqs = read_mapped(tmp_path / "trials", parse_mapping(trial_mapping(), "m"))
    assert seqs.data.shape == (2, STEPS, 3) and list(seqs.labels) == ["reach", "reach"]
    assert [e.origin for e in seqs.episodes] == ["trial_0", "trial_1"]
    # the clock starts at the part that starts last (pose, 0.05 s) and steps 0.1 s
    g = 0.05 + 0.1 * np.arange(STEPS)
    assert seqs.episodes[0].start_s == pytest.approx(T0 + 0.05, abs=1e-6)
    np.testing.assert_allclose(seqs.data[0, :, 0], 2 * g + 1, atol=1e-6)  # linear between wrench samples: exact
    np.testing.assert_allclose(seqs.data[0, :, 2], 3 - g, atol=1e-6)
    # q = t^2 at 30 Hz from 0.02 s, interpolated linearly between the samples around each step
    q = []
    for t in g:
        j = int(np.floor((t - 0.02) * 30 + 1e-9))
        before, after = 0.02 + j / 30, 0.02 + (j + 1) / 30
        w = (t - before) / (after - before)
        q.append(before ** 2 + w * (after ** 2 - before ** 2))
    np.testing.assert_allclose(seqs.data[0, :, 1], q, atol=1e-6)
    assert not np.allclose(seqs.data[0, :, 1], g ** 2, rtol=0, atol=1e-5)  # the resampling shows, not the signal itself
    np.testing.assert_allclose(seqs.data[1] - seqs.data[0], 10.0, atol=1e-6)
    # grip_lost is true from 0.8 s: the first pose row at or after it is at 0.8 s, 0.75 s after the start
    assert [e.anomaly for e in seqs.episodes] == ["grip_lost", "grip_lost"]
    assert seqs.episodes[0].onset_s == pytest.approx(0.75, abs=1e-6)
    one = read_mapped(tmp_path / "trials" / "trial_1", parse_mapping(trial_mapping(), "m"))
    np.testing.assert_allclose(one.data[0], seqs.data[1])


def _table(path: Path, text: str, **table) -> tuple[Path, dict]:
    path.write_text(text)
    doc = {"timing": {"period_s": PERIOD_S, "steps": 4}, "table": {"time_column": "t", **table},
           "channels": [{"name": "a", "units": "N", "column": "a"}, {"name": "b", "units": "1", "column": "b"}]}
    return path, doc


def _read(path: Path, doc: dict):
    return read_mapped(path, parse_mapping(doc, "m"))


@pytest.mark.parametrize("names", [["t", "a", "b"], None])
def test_headerless_whitespace_with_mixed_tabs_spaces_and_trailing_tabs(tmp_path, names):
    rows = [f"{0.1 * k:.1f} \t{2 * k + 1}\t  {k * k}\t\t" for k in range(6)]
    table = {"header": False, "names": names} if names else {"header": False, "time_column": 0}
    path, doc = _table(tmp_path / "x.dat", "\n".join(rows) + "\n", **table)
    if names is None:  # columns by their positions
        doc["channels"][0]["column"], doc["channels"][1]["column"] = "1", "2"
    seqs = _read(path, doc)
    np.testing.assert_allclose(seqs.data[0], [[1, 0], [3, 1], [5, 4], [7, 9]])


def test_iso_time_with_a_zone_and_a_datetime_column_keep_the_instant(tmp_path):
    """The same instants written at UTC+01:00, at UTC (Z) and as a date-time column read as one clock."""
    start = 1_700_000_000.0
    rows = [(start + 0.1 * k, float(k), float(-k)) for k in range(5)]
    east = "\n".join(["Timestamp,a,b"] + [f"{_iso(t, 1)},{a},{b}" for t, a, b in rows]) + "\n"
    utc = east.replace("+01:00", "Z")
    for k, (t, _, _) in enumerate(rows):
        utc = utc.replace(_iso(t, 1)[:-6], _iso(t, 0)[:-6], 1)
    stamps = pa.array([int(round(t * 1000)) for t, _, _ in rows], pa.timestamp("ms", tz="Europe/Berlin"))
    pq.write_table(pa.table({"Timestamp": stamps, "a": [r[1] for r in rows], "b": [r[2] for r in rows]}),
                   tmp_path / "c.parquet")
    starts = []
    for name, text in (("a.csv", east), ("b.csv", utc)):
        path, doc = _table(tmp_path / name, text, time_unit="iso")
        doc["table"]["time_column"] = "Timestamp"
        seqs = _read(path, doc)
        np.testing.assert_allclose(seqs.data[0, :, 0], [0, 1, 2, 3])
        starts.append(seqs.episodes[0].start_s)
    _, doc = _table(tmp_path / "unused.csv", "", time_unit="iso")
    doc["table"]["time_column"] = "Timestamp"
    starts.append(_read(tmp_path / "c.parquet", doc).episodes[0].start_s)
    assert starts == pytest.approx([start] * 3, abs=1e-6)
    path, doc = _table(tmp_path / "mixed.csv", east.replace("+01:00", "", 1), time_unit="iso")
    doc["table"]["time_column"] = "Timestamp"
    with pytest.raises(LogError, match=r"mixed.csv: row 2, column 'Timestamp': .* has a zone offset, row 1's has none"):
        _read(path, doc)
    path, doc = _table(tmp_path / "text.csv", east)
    doc["table"]["time_column"] = "Timestamp"
    with pytest.raises(LogError, match='text.csv: time column .Timestamp. holds timestamp.*set time_unit = "iso"'):
        _read(path, doc)


@pytest.mark.parametrize("true,false", [("TRUE", "FALSE"), ("1", "0"), ("yes", "no")])
def test_flags_give_the_label_of_the_first_raised_and_its_onset(tmp_path, true, false):
    def text(slip_from: int | None, hit_from: int | None) -> str:
        rows = ["t,a,b,slip,hit"]
        for k in range(8):
            slip = true if slip_from is not None and k >= slip_from else false
            hit = true if hit_from is not None and k >= hit_from else false
            rows.append(f"{0.1 * k:.1f},{k},{k},{slip},{hit}")
        return "\n".join(rows) + "\n"

    folder = tmp_path / "runs"
    folder.mkdir()
    (folder / "a.csv").write_text(text(5, 3))
    (folder / "b.csv").write_text(text(2, None))
    (folder / "c.csv").write_text(text(None, None))
    (folder / "d.csv").write_text(text(4, 4))  # both at once: the first named wins
    _, doc = _table(folder / "a.csv", text(5, 3), label={"flag": ["slip", "hit"]})
    seqs = _read(folder, doc)
    assert [e.anomaly for e in seqs.episodes] == ["hit", "slip", None, "slip"]
    assert [e.onset_s for e in seqs.episodes] == pytest.approx([0.3, 0.2, None, 0.4])


def test_a_bom_and_spaces_around_header_names_are_ignored(tmp_path):
    text = "\ufefft ,a , b\n" + "".join(f"{0.1 * k:.1f},{k},{2 * k}\n" for k in range(5))
    for column in ("a", "a "):
        path, doc = _table(tmp_path / "bom.csv", text)
        doc["channels"][0]["column"] = column
        np.testing.assert_allclose(_read(path, doc).data[0, :, 0], [0, 1, 2, 3])
    path, doc = _table(tmp_path / "bom.txt", text.replace(",", "\t"))
    np.testing.assert_allclose(_read(path, doc).data[0, :, 1], [0, 2, 4, 6])


def test_blank_cells_under_each_policy(tmp_path):
    """Row 3 (t = 0.2 s) has no a: a = 2 t + 1 with the row dropped, or the previous row's 1.2 held."""
    rows = ["t,a,b"] + [f"{0.1 * k:.1f},{'' if k == 2 else 2 * (0.1 * k) + 1:},{k}" for k in range(6)]
    path, doc = _table(tmp_path / "blank.csv", "\n".join(rows) + "\n")
    doc["timing"]["max_gap_s"] = 0.25  # a dropped row leaves 0.2 s between samples
    with pytest.raises(LogError, match=r"blank.csv: row 3, column 'a': a blank cell"):
        _read(path, doc)
    doc["table"]["blank"] = "drop_row"
    dropped = _read(path, doc).data[0]
    np.testing.assert_allclose(dropped[:, 0], [1.0, 1.2, 1.4, 1.6])  # interpolated over the dropped row
    np.testing.assert_allclose(dropped[:, 1], [0, 1, 2, 3])  # b at 0.2 s between rows 2 and 4 (1 and 3)
    doc["table"]["blank"] = "hold"
    held = _read(path, doc).data[0]
    np.testing.assert_allclose(held[:, 0], [1.0, 1.2, 1.2, 1.6])
    first = ["t,a,b", "0.0,,0"] + rows[2:]
    path, doc = _table(tmp_path / "first.csv", "\n".join(first) + "\n", blank="hold")
    with pytest.raises(LogError, match=r"first.csv: row 1, column 'a': a blank cell with no value before it"):
        _read(path, doc)


def test_a_pause_splits_a_table_and_an_episode_column_too(tmp_path):
    """Three runs of 0.5 s, 2 s apart; the third is episode B, the first two A."""
    rows = ["t,a,b,ep"]
    for run in range(3):
        for k in range(6):
            rows.append(f"{run * 2.5 + 0.1 * k:.1f},{10 * run + k},{k},{'B' if run == 2 else 'A'}")
    path, doc = _table(tmp_path / "runs.csv", "\n".join(rows) + "\n", split="gap", gap_s=1.0)
    seqs = _read(path, doc)
    assert [e.origin for e in seqs.episodes] == ["runs.csv segment 0", "runs.csv segment 1", "runs.csv segment 2"]
    assert [e.start_s for e in seqs.episodes] == pytest.approx([0.0, 2.5, 5.0])
    np.testing.assert_allclose(seqs.data[:, 0, 0], [0, 10, 20])
    doc["table"]["episode_column"] = "ep"
    both = _read(path, doc)
    assert [e.origin for e in both.episodes] == ["runs.csv episode A segment 0", "runs.csv episode A segment 1",
                                                 "runs.csv episode B segment 0"]
    doc["table"]["split"] = "file"
    with pytest.raises(LogError, match="no sample between 0.500 s and 2.500 s"):
        _read(path, doc)


def _broken(root: Path, what: str) -> tuple[Path, str]:
    """Three trials, the second broken in one way; what the error must name."""
    for k in range(3):
        write_trial(root / f"trial_{k}", swap_joint_rows=what == "backwards" and k == 1)
    bad = root / "trial_1"
    if what == "missing":
        (bad / "pose.csv").unlink()
        return bad, r"trial_1: no file matches part 'pose\*.csv'"
    if what == "flag":
        text = (bad / "pose.csv").read_text().splitlines()
        text[9] = text[9].rsplit(",", 1)[0] + ",maybe"
        (bad / "pose.csv").write_text("\n".join(text) + "\n")
        return bad, r"pose.csv: row 9, column 'grip_lost': flag 'maybe' is not TRUE/FALSE, 1/0 or yes/no"
    return bad, r"joints.txt: row 8: time does not increase"  # rows 7 and 8 swapped


@pytest.mark.parametrize("what", ["missing", "backwards", "flag"])
def test_a_bad_trial_is_one_line_exit_2_or_skipped_and_counted(tmp_path, what):
    root = tmp_path / "trials"
    _, message = _broken(root, what)
    mapping = write_mapping(trial_mapping(), tmp_path / "m.yaml")
    out = tmp_path / "model.safetensors"
    result = runner.invoke(app, ["train", str(root), "--mapping", str(mapping), "--out", str(out)])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error")]
    assert len(errors) == 1 and re.search(message, errors[0]), result.output
    assert not out.exists()
    seqs = read_mapped(root, parse_mapping(trial_mapping(), "m"), skip_bad=True)
    assert [e.number for e in seqs.episodes] == [0, 2] and len(seqs.provenance["warnings"]) == 1
    shown = runner.invoke(app, ["logs", "inspect", str(root), "--mapping", str(mapping)])
    assert shown.exit_code == 0, shown.output
    assert "2 episodes" in shown.output and "1 skipped" in shown.output


def test_inspect_says_how_each_layout_is_read(tmp_path):
    write_trial(tmp_path / "trials" / "trial_0")
    mapping = write_mapping(trial_mapping(), tmp_path / "m.yaml")
    shown = runner.invoke(app, ["logs", "inspect", str(tmp_path / "trials"), "--mapping", str(mapping)])
    assert shown.exit_code == 0, shown.output
    assert "a folder per episode, 3 files each" in shown.output
    assert "'joints*.txt' -> q (auto, no header, columns ['t', 'q']), time in column 0 (s)" in shown.output
    assert "episode    0:    10 steps, skill reach, anomaly grip_lost from 0.75 s, trial_0" in shown.output
    path, doc = _table(tmp_path / "runs.csv", "t,a,b\n0,1,2\n0.1,1,2\n0.2,1,2\n0.3,1,2\n", split="gap", gap_s=1.0,
                       blank="drop_row")
    shown = runner.invoke(app, ["logs", "inspect", str(path), "--mapping", str(write_mapping(doc, tmp_path / "t.yaml"))])
    assert shown.exit_code == 0, shown.output
    assert "an episode per file, a new one after each pause over 1 s" in shown.output and "blank cells: drop_row" in shown.output


@pytest.mark.slow  # trains a network and serves it
def test_a_model_trained_from_trial_folders_serves_a_replay_equal_to_score(tmp_path):
    trials = tmp_path / "trials"
    for k in range(6):
        write_trial(trials / f"trial_{k}", offset=0.1 * k, lost_from=np.inf)  # normal trials: no grip lost
    mapping = write_mapping(trial_mapping(), tmp_path / "m.yaml")
    models = tmp_path / "models"
    model = models / "trials.safetensors"
    trained = runner.invoke(app, ["train", str(trials), "--mapping", str(mapping), "--epochs", "5", "--hidden", "8",
                                  "--out", str(model)])
    assert trained.exit_code == 0, trained.output
    calibrated = runner.invoke(app, ["calibrate", str(model), str(trials), "--mapping", str(mapping),
                                         "--no-cross-fit"])
    assert calibrated.exit_code == 0, calibrated.output
    one = trials / "trial_3"
    scored = runner.invoke(app, ["score", str(model), str(one), "--mapping", str(mapping), "--json"])
    assert scored.exit_code == 0, scored.output
    energy = json.loads(scored.output.strip().splitlines()[-1])["energy"]
    assert len(energy) == 1 and len(energy[0]) == STEPS and min(energy[0]) > 0.01, energy
    summaries = tmp_path / "replay.json"
    settings = Settings(models_dir=models, recordings_dir=tmp_path / "service-recordings", build_default_model=False)
    with start_embedded(settings) as server:
        replayed = runner.invoke(app, ["replay", str(one), "--mapping", str(mapping), "--url", server.url,
                                       "--model", "trials", "--out", str(tmp_path / "rec"), "--json", str(summaries)])
    assert replayed.exit_code == 0, replayed.output
    summary = json.loads(summaries.read_text())
    assert len(summary) == 1 and summary[0]["steps_scored"] == STEPS and summary[0]["completed"]
    np.testing.assert_allclose([step["energy"] for step in summary[0]["steps"]], energy[0], rtol=1e-5, atol=1e-6)
