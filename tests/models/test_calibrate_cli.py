"""``nasm calibrate`` with few held-out episodes: below 99 threshold episodes it cross-fits by
default (with ``--cross-fit DEMOS``, else the training data the checkpoint records), a skill memory
too; ``--no-cross-fit`` keeps the held-out episodes alone; with 99 or more nothing changes; and what
cannot be done is refused in one line. On the tests' own kitting-shaped skill courses."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from kitting_fixtures import SKILL_CHANNELS, skill_runs, told_memory
from neural_asm import CrossFit, SkillMemory
from neural_asm.cli import app
from neural_asm.models.config import FAST

runner = CliRunner()
TINY = ("--epochs", "3", "--hidden", "8")


def _nasm(*args: object):
    return runner.invoke(app, [str(a) for a in args])


def _npz(path: Path, runs: tuple[np.ndarray, np.ndarray]) -> Path:
    np.savez(path, sequences=runs[0], channel_names=np.array(SKILL_CHANNELS), skills=runs[1])
    return path


@pytest.fixture(scope="module")
def sets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("sets")
    return {"demos": _npz(folder / "demos.npz", skill_runs(4, 0)),  # 12 demonstrations
            "normal": _npz(folder / "normal.npz", skill_runs(2, 1)),  # 3 precision, 3 threshold episodes
            "precision": _npz(folder / "precision.npz", skill_runs(2, 2)),
            "many": _npz(folder / "many.npz", skill_runs(33, 3))}  # 99 threshold episodes with --precision


def _trained(sets: dict[str, Path], out: Path, *args: str) -> Path:
    result = _nasm("train", sets["demos"], "--out", out, *TINY, *args)
    assert result.exit_code == 0, result.output
    return out


def _one_line_refusal(result) -> str:
    assert result.exit_code == 2 and len(result.output.strip().splitlines()) == 1, result.output
    return result.output


def test_no_cross_fit_is_refused_beside_cross_fit_or_its_folds(tmp_path):
    model = tmp_path / "never-read.safetensors"
    output = _one_line_refusal(_nasm("calibrate", model, "n.npz", "--cross-fit", "d.npz", "--no-cross-fit"))
    assert "--cross-fit DEMOS and --no-cross-fit contradict each other" in output
    output = _one_line_refusal(_nasm("calibrate", model, "n.npz", "--no-cross-fit", "--folds", 3))
    assert "--no-cross-fit does not cross-fit" in output


def test_without_the_training_data_few_threshold_episodes_are_refused_naming_both_ways_on(sets, tmp_path):
    x, y = skill_runs(4, 0)
    unrecorded = SkillMemory.fit(x, SKILL_CHANNELS, y, preset=FAST.with_(hidden_size=8, epochs=3), progress=False)
    moved = tmp_path / "moved.npz"
    moved.write_bytes(sets["demos"].read_bytes())
    gone = _trained({"demos": moved}, tmp_path / "gone.safetensors")
    moved.unlink()
    for model, why in ((unrecorded.save(tmp_path / "arrays.safetensors"), "does not record where its training data"),
                       (gone, f"its training data ({moved}) cannot be read again")):
        out = tmp_path / "calibrated.safetensors"
        output = _one_line_refusal(_nasm("calibrate", model, sets["normal"], "--out", out))
        assert "3 threshold episodes are fewer than the 99" in output and why in output
        assert "--cross-fit DEMOS" in output and "--no-cross-fit" in output and not out.exists()


def test_no_cross_fit_keeps_the_held_out_rule(sets, tmp_path):
    model, report = _trained(sets, tmp_path / "m.safetensors"), tmp_path / "report.json"
    result = _nasm("calibrate", model, sets["normal"], "--no-cross-fit", "--json", report)
    assert result.exit_code == 0, result.output
    doc = json.loads(report.read_text())
    assert doc["threshold_episodes"] == 3 and "out_of_fold_episodes" not in doc
    assert "3 for the thresholds (held out, not cross-fitted: --no-cross-fit)" in result.output
    assert "(or cross-fit them: without --no-cross-fit" in result.output  # 1 %: the highest of 3 peaks


def test_with_99_threshold_episodes_nothing_is_cross_fitted(sets, tmp_path):
    model = _trained(sets, tmp_path / "m.safetensors")
    docs, outputs = [], []
    for rule in ((), ("--no-cross-fit",)):
        report = tmp_path / f"report{len(rule)}.json"
        result = _nasm("calibrate", model, sets["many"], "--precision", sets["precision"], "--out",
                       tmp_path / f"c{len(rule)}.safetensors", "--json", report, *rule)
        assert result.exit_code == 0, result.output
        docs.append(json.loads(report.read_text()))
        outputs.append(result.output)
    assert "99 for the thresholds (held out; 99 >= 99 need no cross-fitting)" in outputs[0]
    assert "warning" not in outputs[0]  # 99 peaks: a 1 % split-conformal threshold holds
    default, held_out = docs
    assert default["threshold_episodes"] == 99 and "out_of_fold_episodes" not in default
    assert default["modes"] == held_out["modes"]


def test_a_skill_memory_refuses_demonstrations_it_did_not_learn_before_training_any():
    memory = told_memory()
    normal, skills = skill_runs(2, 1)
    other, labels = skill_runs(10, 9)  # as many as it learnt, but not those
    before = memory.told.calibration
    with pytest.raises(ValueError, match=r"needs the demonstrations the memory learnt \(30 sequences"):
        memory.calibrate(normal, skills=skills, cross_fit=CrossFit(other, labels, folds=2), progress=False)
    with pytest.raises(ValueError, match="cross-fitting needs each demonstration's skill"):
        memory.calibrate(normal, skills=skills, cross_fit=CrossFit(other, None, folds=2), progress=False)
    assert memory.told.calibration is before


@pytest.mark.slow  # trains a network per fold
def test_by_default_few_threshold_episodes_are_cross_fitted_with_the_recorded_training_data(sets, tmp_path):
    model, report = _trained(sets, tmp_path / "m.safetensors"), tmp_path / "report.json"
    result = _nasm("calibrate", model, sets["normal"], "--json", report)
    assert result.exit_code == 0, result.output
    doc = json.loads(report.read_text())
    assert doc["out_of_fold_episodes"] == 12 and doc["folds"] == 5 and doc["threshold_episodes"] == 3
    assert "15 for the thresholds (12 of them out-of-fold, 5 folds: cross-fitted)" in result.output
    assert SkillMemory.load(model).model.calibration("offline", 1).source.endswith("(5 folds)")


@pytest.mark.slow  # trains a network per fold
def test_a_skill_memory_is_cross_fitted_by_default(sets, tmp_path):
    model, report = _trained(sets, tmp_path / "skills.safetensors", "--skill-cue"), tmp_path / "report.json"
    result = _nasm("calibrate", model, sets["normal"], "--json", report, "--folds", 3)
    assert result.exit_code == 0, result.output
    doc = json.loads(report.read_text())
    assert doc["out_of_fold_episodes"] == 12 and doc["folds"] == 3 and "skills" in doc
    calibrated = SkillMemory.load(model).told
    assert calibrated.calibration.out_of_fold_episodes == 12
    assert calibrated.calibration.inferred[0.01] == pytest.approx(doc["skills"]["inferred"]["0.01"])
    held_out = tmp_path / "held_out.json"
    assert _nasm("calibrate", model, sets["normal"], "--no-cross-fit", "--json", held_out).exit_code == 0
    assert "out_of_fold_episodes" not in json.loads(held_out.read_text())
    assert SkillMemory.load(model).told.calibration.out_of_fold_episodes == 0
