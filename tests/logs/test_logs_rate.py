"""Every reader keeps the mapping's clock: a model trained from a 20 Hz mapping of a ROS bag, a
LeRobot dataset or a table is a 20 Hz model (``nasm info``), and the service opens a session
that states 20 Hz on it and refuses one at the 2 Hz a model gets when the clock is lost."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.experiments.robot_logs.write import bag_mapping, lerobot_mapping, write_bag, write_lerobot, write_mapping
from neural_asm.service.app import create_app
from neural_asm.service.settings import Settings
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes and trains networks

PERIOD_S = 0.05  # 20 Hz
STEPS = 40
runner = CliRunner()


def _at_20_hz(doc: dict) -> dict:
    return doc | {"timing": {"period_s": PERIOD_S, "steps": STEPS, "max_gap_s": 0.3}}


def _table(folder: Path) -> tuple[Path, dict]:
    """Four episodes as CSV files sampled at 50 Hz, and their 20 Hz mapping."""
    folder.mkdir()
    t = np.arange(150) / 50.0
    for k in range(4):
        rows = np.column_stack([t, np.sin(t + k), np.cos(2 * t) * k])
        np.savetxt(folder / f"ep{k}.csv", rows, delimiter=",", header="t,a,b", comments="")
    doc = {"table": {"time_column": "t"}, "channels": [{"name": "a", "units": "N", "column": "a"},
                                                       {"name": "b", "units": "1", "column": "b"}]}
    return folder, _at_20_hz(doc)


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> dict[str, tuple[Path, dict]]:
    folder = tmp_path_factory.mktemp("sources")
    episodes = [run_episode(SKILLS[i % 2], 500 + i) for i in range(4)]
    return {"rosbag": (write_bag(episodes, folder / "bag"), _at_20_hz(bag_mapping("marker"))),
            "lerobot": (write_lerobot(episodes, folder / "lerobot"), _at_20_hz(lerobot_mapping())),
            "table": _table(folder / "tables")}


@pytest.mark.parametrize("kind", ["rosbag", "lerobot", "table"])
def test_a_model_trained_from_a_20_hz_mapping_is_a_20_hz_model(kind, sources, tmp_path):
    source, doc = sources[kind]
    mapping = str(write_mapping(doc, tmp_path / "m.yaml"))
    models = tmp_path / "models"
    out = models / f"{kind}.safetensors"
    trained = runner.invoke(app, ["train", str(source), "--mapping", mapping, "--epochs", "2", "--hidden", "8",
                                  "--out", str(out)])
    assert trained.exit_code == 0, trained.output
    assert "at 20 Hz" in trained.output
    calibrated = runner.invoke(app, ["calibrate", str(out), str(source), "--mapping", mapping, "--no-cross-fit"])
    assert calibrated.exit_code == 0, calibrated.output
    info = runner.invoke(app, ["info", str(out)])
    assert info.exit_code == 0, info.output
    assert json.loads(info.output)["rate_hz"] == 20.0
    with TestClient(create_app(Settings(models_dir=models, build_default_model=False, record=False))) as client:
        opened = client.post("/sessions", json={"model": kind, "rate_hz": 20})
        assert opened.status_code == 201, opened.text
        assert opened.json()["rate_hz"] == 20.0
        assert client.post("/sessions", json={"model": kind, "rate_hz": 2}).status_code == 409
