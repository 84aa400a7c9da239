import copy
import json

import numpy as np
import pytest

from neural_asm.models import checkpoint
from neural_asm.models.checkpoint import CheckpointError


def test_round_trip_gives_identical_predictions(trained, skills, tmp_path):
    _, test = skills
    train, _ = skills
    trained.calibrate(train.data, test.data, "online", 1, source="test")
    path = checkpoint.save(trained, tmp_path / "m.safetensors")
    loaded = checkpoint.load(path)
    assert loaded.channel_names == trained.channel_names and loaded.config == trained.config
    for mode in ("offline", "online"):
        a, b = trained.score(test.data, mode), loaded.score(test.data, mode)
        assert np.array_equal(a.energy, b.energy) and np.array_equal(a.expected, b.expected)
    cal_a, cal_b = trained.calibration("online", 1), loaded.calibration("online", 1)
    assert cal_a.thresholds == cal_b.thresholds and cal_b.source == "test"
    assert np.array_equal(cal_a.step_thresholds[0.01], cal_b.step_thresholds[0.01])
    assert cal_a.error_precision is not None and np.array_equal(cal_a.error_precision, cal_b.error_precision)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_truncated_checkpoint_is_rejected(trained, tmp_path):
    path = checkpoint.save(trained, tmp_path / "m.safetensors")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        checkpoint.load(path)


def test_flipped_weight_bytes_are_refused(trained, tmp_path):
    path = checkpoint.save(trained, tmp_path / "m.safetensors")
    data = bytearray(path.read_bytes())
    n = int.from_bytes(data[:8], "little")
    offsets = json.loads(data[8 : 8 + n])["W_H"]["data_offsets"]
    data[8 + n + offsets[0] + 3] ^= 0x7F  # the exponent byte of the first float32 of W_H
    path.write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match="digest"):
        checkpoint.load(path)


def test_insane_weights_are_refused_even_with_a_matching_digest(trained, tmp_path):
    import torch

    saved = trained.net.W_H.clone()
    try:
        trained.net.W_H[0, 0] = 3.5e28
        path = checkpoint.save(trained, tmp_path / "m.safetensors")
    finally:
        trained.net.W_H.copy_(saved)
    with pytest.raises(CheckpointError, match="W_H holds values beyond"):
        checkpoint.load(path)
    assert torch.equal(trained.net.W_H, saved)


def test_garbage_and_missing_files_are_rejected(tmp_path):
    bad = tmp_path / "bad.safetensors"
    bad.write_bytes(b"\x00" * 64)
    with pytest.raises(CheckpointError, match="not a Neural ASM checkpoint"):
        checkpoint.load(bad)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        checkpoint.load(tmp_path / "absent.safetensors")


def _rewrite_header(data: bytes, edit) -> bytes:
    n = int.from_bytes(data[:8], "little")
    header = json.loads(data[8 : 8 + n])
    meta = json.loads(header["__metadata__"]["neural_asm"])
    edit(meta)
    header["__metadata__"]["neural_asm"] = json.dumps(meta)
    raw = json.dumps(header).encode()
    raw += b" " * (-len(raw) % 8)
    return len(raw).to_bytes(8, "little") + raw + data[8 + n :]


def test_mismatched_metadata_is_rejected(trained, tmp_path):
    path = checkpoint.save(trained, tmp_path / "m.safetensors")
    data = path.read_bytes()
    fewer = _rewrite_header(data, lambda m: m.__setitem__("channel_names", m["channel_names"][:-1]))
    with pytest.raises(CheckpointError, match="does not match"):
        checkpoint.from_bytes(fewer)
    newer = _rewrite_header(data, lambda m: m.__setitem__("format_version", 99))
    with pytest.raises(CheckpointError, match="format version 99"):
        checkpoint.from_bytes(newer)


def test_checkpoint_from_before_the_solver_setting_keeps_gradient_descent(trained, tmp_path):
    """A network trained by gradient descent must not be served with another solver."""
    data = checkpoint.save(trained, tmp_path / "m.safetensors").read_bytes()
    assert checkpoint.from_bytes(data).config.solver == "gauss_newton"

    def as_version_4(meta):
        meta["format_version"] = 4
        del meta["config"]["solver"], meta["config"]["solver_iterations"]

    old = checkpoint.from_bytes(_rewrite_header(data, as_version_4))
    assert old.config.solver == "gradient" and old.config.inference_steps == trained.config.inference_steps


def test_the_rate_is_stored_and_older_checkpoints_are_2_hz(trained, tmp_path):
    """A 40 Hz model loads as 40 Hz; a file from before models carried their rate loads as 2 Hz."""
    model = copy.deepcopy(trained)
    model.rate_hz = 40.0
    data = checkpoint.save(model, tmp_path / "m.safetensors").read_bytes()
    assert checkpoint.from_bytes(data).rate_hz == 40.0

    def as_version_5(meta):
        meta["format_version"] = 5
        del meta["rate_hz"]

    assert checkpoint.from_bytes(_rewrite_header(data, as_version_5)).rate_hz == 2.0
    with pytest.raises(CheckpointError, match="rate_hz"):
        checkpoint.from_bytes(_rewrite_header(data, lambda m: m.__setitem__("rate_hz", -1)))


def test_each_steps_mean_error_is_stored_and_checked(trained, skills, tmp_path):
    """A 40 Hz calibration's mean errors per skill survive the round trip; a table of the wrong shape is refused."""
    train, test = skills
    model = copy.deepcopy(trained)
    model.rate_hz = 40.0
    cal = model.calibrate(train.data, test.data, "online", 1, labels=train.labels)
    loaded = checkpoint.load(checkpoint.save(model, tmp_path / "m.safetensors"))
    assert np.array_equal(loaded.calibration("online", 1).error_mean, cal.error_mean)
    assert loaded.calibration("online", 1).skills == cal.skills and len(cal.skills) == 3
    assert np.array_equal(loaded.score(test.data, "online").energy, model.score(test.data, "online").energy)
    cal.error_mean = cal.error_mean[:2]
    with pytest.raises(CheckpointError, match="mean errors"):
        checkpoint.from_bytes(checkpoint.to_bytes(model))


def test_failed_write_leaves_previous_checkpoint_intact(trained, tmp_path, monkeypatch):
    path = checkpoint.save(trained, tmp_path / "m.safetensors")
    before = path.read_bytes()

    def boom(*_):
        raise OSError("disk full")

    monkeypatch.setattr(checkpoint.os, "fsync", boom)
    with pytest.raises(OSError, match="disk full"):
        checkpoint.save(trained, path)
    assert path.read_bytes() == before
    assert list(tmp_path.iterdir()) == [path]


@pytest.fixture(scope="module")
def skill_memory(skills):
    from neural_asm.models.config import FAST
    from neural_asm.models.skill_context import SkillMemory

    train, test = skills
    memory = SkillMemory.fit(train.data, train.channel_names, train.labels, FAST.with_(hidden_size=8, epochs=3))
    memory.calibrate(test.data[0::2], test.labels[0::2], test.data[1::2], test.labels[1::2])
    return memory


def test_a_skill_memory_round_trips_with_its_courses_and_calibration(skill_memory, skills, tmp_path):
    _, test = skills
    path = checkpoint.save(skill_memory, tmp_path / "s.safetensors")
    network, loaded = checkpoint.load_memory(path)
    assert loaded is not None and loaded.model is network and loaded.skills == skill_memory.skills
    assert checkpoint.load_memory(checkpoint.save(network, tmp_path / "n.safetensors"))[1] is None  # the network alone
    for told in (None, test.labels.tolist()):
        for a, b in zip(skill_memory.score(test.data, told), loaded.score(test.data, told)):
            assert np.array_equal(a, b)
    assert checkpoint.read_header(path.read_bytes(), "s")["format_version"] == checkpoint.FORMAT_VERSION


def test_a_skill_memory_whose_header_does_not_fit_its_tensors_is_refused(skill_memory, tmp_path):
    data = checkpoint.save(skill_memory, tmp_path / "s.safetensors").read_bytes()
    more = _rewrite_header(data, lambda m: m["skill_memory"]["calibration"]["spreads"].append("elsewhere"))
    with pytest.raises(CheckpointError, match="elsewhere"):
        checkpoint.decode(more)


def test_a_checkpoint_of_version_8_still_loads(trained, tmp_path):
    data = checkpoint.save(trained, tmp_path / "m.safetensors").read_bytes()
    old = _rewrite_header(data, lambda m: (m.__setitem__("format_version", 8), m.pop("skill_memory")))
    model, skills = checkpoint.decode(old)
    assert skills is None and model.channel_names == trained.channel_names
