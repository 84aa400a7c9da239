"""Trusted checkpoints: a corrupted one is refused and listed as broken, never the default.

Three checkpoints of one small model, the newest with a flipped byte in its weights.
"""

import json
import os
import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.models.synthetic import make_skills
from neural_asm.service.app import create_app
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import CHANNEL_NAMES


def corrupt_weights(path: Path) -> None:
    """Flip the exponent byte of the first float of W_H, as a bad disk or copy would."""
    data = bytearray(path.read_bytes())
    n = int.from_bytes(data[:8], "little")
    start = json.loads(data[8 : 8 + n])["W_H"]["data_offsets"][0]
    data[8 + n + start + 3] ^= 0x7F
    path.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = make_skills(n_skills=1, repetitions=4, steps=5, channels=25)
    model = NeuralASM.fit(data.data, CHANNEL_NAMES, FAST.with_(hidden_size=16, epochs=5), progress=False)
    model.calibrate(data.data, data.data, "offline", 1)
    return checkpoint.save(model, tmp_path_factory.mktemp("source") / "m.safetensors")


@pytest.fixture
def model_dir(tmp_path: Path, source: Path) -> Path:
    """old.safetensors < new.safetensors < corrupt.safetensors in modification time."""
    for age, name in ((300, "old"), (200, "new"), (100, "corrupt")):
        path = shutil.copy(source, tmp_path / f"{name}.safetensors")
        os.utime(path, (os.path.getmtime(source) - age,) * 2)
    corrupt_weights(tmp_path / "corrupt.safetensors")
    os.utime(tmp_path / "corrupt.safetensors", (os.path.getmtime(source) - 100,) * 2)
    return tmp_path


def _client(model_dir: Path, **settings) -> TestClient:
    return TestClient(create_app(Settings(models_dir=model_dir, record=False, build_default_model=False, **settings)))


def test_corrupted_checkpoint_is_refused_listed_and_never_the_default(model_dir, source):
    with _client(model_dir) as c:
        listed = {m["name"]: m for m in c.get("/models").json()}
        assert listed["corrupt"]["status"] == "broken" and not listed["corrupt"]["default"]
        assert "digest" in listed["corrupt"]["error"] and "corrupt.safetensors" in listed["corrupt"]["error"]
        assert listed["corrupt"]["channel_names"] == []
        assert [m["name"] for m in listed.values() if m["default"]] == ["new"]  # the newest valid one
        digest = checkpoint.read_header(source.read_bytes(), "source")["tensor_sha256"]
        for name in ("old", "new"):
            assert listed[name]["status"] == "ok" and listed[name]["digest"] == digest
            assert listed[name]["origin"] == "loaded" and listed[name]["path"] == str(model_dir / f"{name}.safetensors")
        assert c.post("/sessions", json={}).json()["model"] == "new"
        r = c.post("/sessions", json={"model": "corrupt"})
        assert r.status_code == 404 and "refused" in r.json()["detail"] and "digest" in r.json()["detail"]
        assert c.get("/healthz").json()["models"] == 2


def test_configured_default_wins_and_a_broken_one_is_no_default(model_dir):
    with _client(model_dir, default_model="old") as c:
        assert [m["name"] for m in c.get("/models").json() if m["default"]] == ["old"]
        assert c.post("/sessions", json={}).json()["model"] == "old"
    with _client(model_dir, default_model="corrupt") as c:
        assert not any(m["default"] for m in c.get("/models").json())
        r = c.post("/sessions", json={})
        assert r.status_code == 404 and "'corrupt' was refused" in r.json()["detail"]
        assert c.post("/sessions", json={"model": "new"}).status_code == 201
