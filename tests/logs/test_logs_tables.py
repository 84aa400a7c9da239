"""A lab's tables through the mapping: Baxter-shaped CSV folders with label pickles, a voraus-shaped
parquet, a TSV and a whitespace text with an episode column; the pickle guard; every bad input
refused with one line naming the file (or skipped with --skip-bad)."""

from __future__ import annotations

import collections
import pickle
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from kitting_fixtures import COLUMNS, label_pickle, write_kitting, write_voraus
from neural_asm.cli import app
from neural_asm.logs.errors import LogError
from neural_asm.logs.label_pickle import read_anomaly
from neural_asm.logs.mapping import load_mapping, parse_mapping
from neural_asm.logs.sources import read_mapped

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
BAXTER = EXAMPLES / "baxter_kitting.toml"
VORAUS = EXAMPLES / "voraus_ad.toml"


@pytest.fixture(scope="module")
def kitting(tmp_path_factory):
    return write_kitting(tmp_path_factory.mktemp("kitting"), runs=6)


def _mapping(**table):
    doc = {"timing": {"period_s": 0.05, "steps": 20},
           "table": {"time_column": "t", **table},
           "channels": [{"name": "a", "units": "N", "column": "a"}, {"name": "b", "units": "1", "column": "b"}]}
    return parse_mapping(doc, "test mapping")


def test_baxter_folders_give_skills_labels_and_onsets(kitting):
    seqs = read_mapped(kitting / "unsuccessful_skills", load_mapping(BAXTER))
    assert seqs.data.shape == (2, 120, 6)
    assert set(seqs.labels) == {"5"}
    assert [e.anomaly for e in seqs.episodes] == ["no_object", "no_object"]
    # the onset is half-way through each synthetic segment (60-90 steps of 0.05 s)
    assert all(1.4 < o < 2.3 for o in [e.onset_s for e in seqs.episodes])
    normal = read_mapped(kitting / "successful_skills", load_mapping(BAXTER))
    assert sorted(set(normal.labels)) == ["3", "4", "5"] and {e.anomaly for e in normal.episodes} == {None}
    assert all(e.steps < normal.data.shape[1] for e in normal.episodes)  # shorter than 6 s: padded


def test_the_csv_values_arrive_on_the_model_clock(kitting):
    seqs = read_mapped(kitting / "successful_skills", load_mapping(BAXTER))
    first = sorted((kitting / "successful_skills").glob("**/*.csv"))[0]
    raw = np.loadtxt(first, delimiter=",", skiprows=1)
    n = len(raw)
    np.testing.assert_allclose(seqs.data[0, :n], raw[:, 1:], rtol=1e-5)
    np.testing.assert_allclose(seqs.data[0, n:], np.repeat(raw[-1:, 1:], 120 - n, axis=0), rtol=1e-5)  # held


def test_voraus_parquet_with_an_episode_column(tmp_path):
    path = write_voraus(tmp_path / "v.parquet", samples=8, row_group=300)
    seqs = read_mapped(path, load_mapping(VORAUS))
    assert seqs.data.shape == (8, 100, 26)
    assert [e.anomaly for e in seqs.episodes] == [None, None, None, "0", None, None, None, "1"]
    assert seqs.episodes[3].origin.endswith("episode 3")


@pytest.mark.parametrize("fmt,sep", [("tsv", "\t"), ("whitespace", "   ")])
def test_tsv_and_whitespace_text_with_an_episode_column(tmp_path, fmt, sep):
    rows = ["t", "a", "b", "ep", "skill"]
    lines = [sep.join(rows)]
    for ep in range(3):
        for k in range(25):
            lines.append(sep.join(map(str, [k * 0.05, ep + k, 2 * k, ep, f"s{ep % 2}"])))
    path = tmp_path / ("x.tsv" if fmt == "tsv" else "x.txt")
    path.write_text("\n".join(lines) + "\n")
    seqs = read_mapped(path, _mapping(episode_column="ep", skill={"column": "skill"}))
    assert seqs.data.shape == (3, 20, 2) and list(seqs.labels) == ["s0", "s1", "s0"]
    np.testing.assert_allclose(seqs.data[2, :, 0], 2 + np.arange(20))


def test_the_pickle_guard_refuses_code(tmp_path):
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    path = tmp_path / "anomaly_label_and_signal_time.pkl"
    path.write_bytes(pickle.dumps(("object_slip", Evil()), protocol=0))
    with pytest.raises(LogError, match=r"refused (__builtin__|builtins)\.print.*labels and ROS times only"):
        read_anomaly(path)
    path.write_bytes(label_pickle("wall_collision", 1526716010.25))
    got = read_anomaly(path)
    assert got.label == "wall_collision" and got.time_s == pytest.approx(1526716010.25)
    path.write_bytes(pickle.dumps((collections.OrderedDict(a=1), 2), protocol=0))
    with pytest.raises(LogError, match="refused collections.OrderedDict"):
        read_anomaly(path)
    path.write_bytes(pickle.dumps(("object_slip", 2.5), protocol=0))
    with pytest.raises(LogError, match="expected a ROS time"):
        read_anomaly(path)


def _bad_csv(folder: Path, what: str) -> Path:
    """One episode's CSV (in the Baxter layout) broken in one way."""
    path = sorted(folder.glob("successful_skills/**/*.csv"))[0]
    lines = path.read_text().splitlines()
    if what == "malformed":
        lines[5] += ",7"
    elif what == "missing":
        lines = [",".join(line.split(",")[:-1]) for line in lines]
    elif what == "backwards":
        lines[6], lines[7] = lines[7], lines[6]
    elif what == "nan":
        lines[4] = lines[4].rsplit(",", 1)[0] + ",nan"
    elif what == "empty":
        lines = []
    elif what == "pickle":
        (path.parent / "anomaly_label_and_signal_time.pkl").write_bytes(pickle.dumps(("x", {1: 2}, 3), protocol=0))
    path.write_text("\n".join(lines) + ("\n" if lines else ""))
    return path


@pytest.mark.parametrize("what,message", [
    ("malformed", "Expected 7 columns"), ("missing", "no column"), ("backwards", r"row 7: time does not increase"),
    ("nan", r"row 4, column .*: a blank cell"), ("empty", "empty file"), ("pickle", "expected \\(label, time\\)"),
])
def test_bad_tables_are_one_line_exit_2_and_skippable(tmp_path, what, message):
    root = write_kitting(tmp_path / "k", runs=3)
    bad = _bad_csv(root, what)
    out = tmp_path / "model.safetensors"
    runner = CliRunner()
    result = runner.invoke(app, ["train", str(root / "successful_skills"), "--mapping", str(BAXTER), "--out", str(out)])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.startswith("error")]
    named = "anomaly_label_and_signal_time.pkl" if what == "pickle" else bad.name
    assert len(lines) == 1 and named in lines[0] and re.search(message, lines[0]), result.output
    assert not out.exists()
    seqs = read_mapped(root / "successful_skills", load_mapping(BAXTER), skip_bad=True)
    assert len(seqs.provenance["warnings"]) == 1 and len(seqs) == 7


def test_mapping_refuses_mixed_kinds_and_missing_table():
    with pytest.raises(LogError, match=r"source: give time_column \(one table per episode"):
        parse_mapping({"timing": {"period_s": 1, "steps": 2}, "channels": [{"name": "a", "units": "1", "column": "a"}]}, "m")
    with pytest.raises(LogError, match="give one of column, folder, sidecar, value or flag"):
        _mapping(skill={"column": "x", "folder": 1})
