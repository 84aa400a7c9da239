"""The reader registry: a format added as one module and one registration is read, trained
from and listed in every help text naming the formats; ``nasm logs inspect`` says what would be
read without training; mappings and checkpoints written before ``[source]`` read as before."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.robot_logs.write import write_mapping
from neural_asm.logs import formats
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import check_checkpoint, parse_mapping
from neural_asm.logs.sources import read_mapped
from toy_format import ToyReader  # tests/logs/toy_format.py, beside this file

runner = CliRunner()
NAMED = "a toy file (.toy)"
TIMING = {"period_s": 0.05, "steps": 40}


@pytest.fixture
def toy(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(formats, "_READERS", dict(formats._READERS))  # the registration ends with the test
    formats.register(ToyReader())


def _toy_file(path: Path, n: int = 6, broken: int | None = None) -> Path:
    """``n`` episodes of 3 s sampled at 50 Hz, two skills; episode ``broken`` lacks column b."""
    t = np.arange(150) / 50.0
    episodes = [{"skill": f"s{k % 2}", "t": (t + 10 * k).tolist(),
                 "columns": {"a": np.sin(t + k).tolist(), **({} if k == broken else {"b": (t * k).tolist()})}}
                for k in range(n)]
    path.write_text(json.dumps(episodes))
    return path


def _toy_mapping(path: Path) -> Path:
    return write_mapping({"timing": TIMING, "source": {"kind": "toy"},
                          "channels": [{"name": "a", "units": "N", "column": "a"},
                                       {"name": "b", "units": "1", "column": "b"}]}, path)


@pytest.mark.parametrize("command", [["train"], ["score"], ["recall"], ["calibrate"], ["evaluate"], ["replay"],
                                     ["logs", "inspect"]])
def test_every_help_naming_the_formats_lists_a_registered_one(toy, command):
    result = runner.invoke(app, [*command, "--help"], terminal_width=400)
    assert result.exit_code == 0, result.output
    text = " ".join(result.output.replace("│", " ").split())  # the help's panels, unwrapped
    assert NAMED in text and "a LeRobot dataset" in text and "{formats}" not in text


def test_without_the_registration_the_help_does_not_list_it():
    result = runner.invoke(app, ["train", "--help"], terminal_width=400)
    assert result.exit_code == 0 and NAMED not in " ".join(result.output.replace("│", " ").split())


def test_a_registered_format_is_read_with_its_facts_on_the_mapping_s_clock(toy, tmp_path):
    from neural_asm.logs.mapping import load_mapping

    seqs = read_mapped(_toy_file(tmp_path / "runs.toy"), load_mapping(_toy_mapping(tmp_path / "m.yaml")))
    assert seqs.data.shape == (6, 40, 2) and seqs.rate_hz == 20.0 and seqs.provenance["format"] == "toy"
    assert [e.number for e in seqs.episodes] == list(range(6)) and seqs.labels.tolist()[:2] == ["s0", "s1"]
    np.testing.assert_allclose(seqs.data[1, :, 1], (np.arange(40) * 0.05) * 1, atol=1e-9)


def test_an_unknown_kind_is_refused_naming_the_registered_ones(toy):
    with pytest.raises(LogError, match=r"source: .*'toyy'.* 'rosbag', 'lerobot', 'table', 'toy'"):
        parse_mapping({"timing": TIMING, "source": {"kind": "toyy"}, "channels": [{"name": "a", "units": "1",
                                                                                     "column": "a"}]}, "m")


def test_a_channel_of_another_address_is_refused(toy):
    with pytest.raises(LogError, match="a toy source's channels each name a column; channel 'a' names a topic"):
        parse_mapping({"timing": TIMING, "source": {"kind": "toy"},
                       "channels": [{"name": "a", "units": "1", "topic": "/a", "field": "data"}]}, "m")


def test_inspect_says_what_would_be_read_and_what_skipped(toy, tmp_path):
    source, mapping = _toy_file(tmp_path / "runs.toy", broken=2), _toy_mapping(tmp_path / "m.yaml")
    result = runner.invoke(app, ["logs", "inspect", str(source), "--mapping", str(mapping)])
    assert result.exit_code == 0, result.output
    assert "5 episodes of 40 steps at 20 Hz (a step every 0.05 s), 2 channels: a, b" in result.output
    assert "episode    3:    40 steps, skill s1, normal, runs.toy episode 3" in result.output
    assert "skipped runs.toy episode 2: 'b'" in result.output and "1 skipped" in result.output
    doc = json.loads(runner.invoke(app, ["logs", "inspect", str(source), "--mapping", str(mapping), "--json"]).stdout)
    assert doc["rate_hz"] == 20.0 and [e["number"] for e in doc["episodes"]] == [0, 1, 3, 4, 5]
    assert doc["skipped"] == ["skipped runs.toy episode 2: 'b'"] and doc["format"] == "toy"


def test_inspect_reads_what_the_commands_read_without_a_mapping(tmp_path):
    data = tmp_path / "set.npz"
    np.savez(data, sequences=np.zeros((3, 5, 2)), channel_names=np.array(["x", "y"]), skills=np.array(["a", "b", "a"]))
    result = runner.invoke(app, ["logs", "inspect", str(data)])
    assert result.exit_code == 0, result.output
    assert "3 episodes of 5 steps at 2 Hz" in result.output and "skill b, normal" in result.output


@pytest.mark.parametrize("args, message", [
    (["nowhere.toy"], "no data at nowhere.toy"),
    (["{source}", "--mapping", "missing.yaml"], "cannot read the mapping missing.yaml"),
    (["{source}", "--mapping", "{lerobot}"], "runs.toy is a toy file (.toy), but the mapping reads a LeRobot dataset"),
])
def test_inspect_refuses_bad_input_in_one_line(toy, tmp_path, args, message):
    source = _toy_file(tmp_path / "runs.toy")
    lerobot = write_mapping({"timing": TIMING, "channels": [{"name": "a", "units": "1", "feature": "a"}]},
                            tmp_path / "lerobot.yaml")
    result = runner.invoke(app, ["logs", "inspect", *(a.format(source=source, lerobot=lerobot) for a in args)])
    assert result.exit_code == 2
    assert len(result.output.strip().splitlines()) == 1 and message in result.output, result.output


def test_a_mapping_written_before_source_sections_checks_as_its_rewrite():
    """A checkpoint trained before ``[source]`` keeps its mapping with ``[table]`` and the per-episode
    keys its provenance had then; later data mapped the same way is accepted, other clocks are not."""
    old = {"timing": TIMING, "table": {"time_column": "t"}, "channels": [{"name": "a", "units": "N", "column": "a"}]}
    provenance = {"mapping": old, "episode_numbers": [0, 1], "lengths_s": [1.0, 2.0], "format": "table"}
    new = parse_mapping(old, "m")
    assert new.to_dict()["source"] == {"kind": "table", "time_column": "t", "files": "**/*", "format": "auto",
                                       "time_unit": "s", "normal": ["normal"], "header": True, "blank": "refuse",
                                       "split": "file"}
    check_checkpoint(parse_mapping(new.to_dict(), "m"), ("a",), provenance)
    slower = {**new.to_dict(), "timing": {"period_s": 0.1, "steps": 40}}
    with pytest.raises(LogError, match="the model was trained on 40 steps of 0.05 s"):
        check_checkpoint(parse_mapping(slower, "m"), ("a",), provenance)


@pytest.mark.slow
def test_a_model_trains_from_a_registered_format(toy, tmp_path):
    out = tmp_path / "toy.safetensors"
    result = runner.invoke(app, ["train", str(_toy_file(tmp_path / "runs.toy")), "--mapping",
                                 str(_toy_mapping(tmp_path / "m.yaml")), "--epochs", "2", "--hidden", "8",
                                 "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "trained on 6 sequences at 20 Hz" in result.output and out.exists()


def test_taking_sequences_takes_their_facts():
    from neural_asm.models.sequences import EpisodeFacts, Sequences

    facts = tuple(EpisodeFacts(n, f"e{n}", 3, 0.0) for n in (4, 7, 9))
    seqs = Sequences(np.zeros((3, 3, 1)), np.array(["a", "b", "a"]), ("x",), episodes=facts)
    assert [e.number for e in seqs.take(np.array([True, False, True])).episodes] == [4, 9]
    assert [e.number for e in seqs.take(np.array([1])).episodes] == [7]
    assert Sequences(np.zeros((3, 3, 1)), np.zeros(3), ("x",)).take(np.array([True, False, True])).episodes == ()
