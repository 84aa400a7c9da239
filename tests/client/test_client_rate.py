"""The client at the controller's 40 Hz, end to end through the service it starts in-process.

Small networks stand in for the defaults: a 40 Hz one trained on a few simulated episodes
observed at every tick (saved as ``panda-40hz``, the name the client's session asks for) and
the 2 Hz ``small_panda_model``, which plans the compliant arm's motion while the 40 Hz one
monitors it (``pipelines.compliant``).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from neural_asm.client import run_client
from neural_asm.client.run import SimulatedRun
from neural_asm.client.stream import Connection, StreamOptions
from neural_asm.client.cli import app
from neural_asm.client.run import falling_object
from neural_asm.client.transport import ServiceError
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.pipelines.compliant import MonitorSeeds, compliant_name, ensure_compliant_model
from neural_asm.pipelines.default_model import model_name
from neural_asm.recordings.readers import read_mcap, read_rrd_series
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import CHANNEL_NAMES
from neural_asm.sim.config import SIM
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes and trains networks

RATE, TICKS = 40, 300
TICK_NS = 25_000_000
SKILL, SEED = SKILLS[0], 50_000


@pytest.fixture(scope="module")
def model_dir(tmp_path_factory: pytest.TempPathFactory, small_panda_model: NeuralASM) -> Path:
    def episodes(seeds: range) -> np.ndarray:
        return np.stack([run_episode(s, seed, rate=RATE).observations for s in SKILLS for seed in seeds])

    demos, precision, thresholds = episodes(range(4)), episodes(range(10, 14)), episodes(range(20, 24))
    model = NeuralASM.fit(demos, CHANNEL_NAMES, FAST.with_(hidden_size=64, epochs=30, learning_rate=2e-4),
                          progress=False, rate_hz=RATE)
    for mode in ("offline", "online"):
        model.calibrate(precision, thresholds, mode, 1)
    folder = tmp_path_factory.mktemp("models")
    checkpoint.save(model, folder / f"{model_name(RATE)}.safetensors")
    checkpoint.save(small_panda_model, folder / f"{model_name()}.safetensors")
    ensure_compliant_model(folder, MonitorSeeds(per_split=6), progress=False, rate=RATE)
    return folder


def _log_times_ns(path: str, topic: str) -> np.ndarray:
    with open(path, "rb") as f:
        return np.array([m.log_time for _, _, m in make_reader(f).iter_messages(topics=[topic])])


def _rrd_times_ns(path: str, entity: str) -> np.ndarray:
    times, _ = read_rrd_series(path, entity, timeline="time")
    return np.array([np.timedelta64(t, "ns").astype(np.int64) for t in times])


def test_every_tick_is_streamed_paced_answered_and_recorded_25_ms_apart(model_dir, tmp_path):
    started = time.monotonic()
    [s] = run_client(SimulatedRun(SKILL, SEED, falling_object=falling_object(True), rate=RATE), Connection(),
                     StreamOptions(out=tmp_path, quiet=True, realtime=True), model_dir)
    elapsed = time.monotonic() - started

    assert s.completed and s.mode == "online"  # a 40 Hz session monitors online by default
    assert s.steps_total == s.steps_scored == TICKS and [line.step for line in s.steps] == list(range(TICKS))
    np.testing.assert_allclose([line.time_s for line in s.steps], np.arange(TICKS) / RATE)
    assert elapsed >= (TICKS - 1) / RATE  # paced: the last tick sent no sooner than 7.475 s in

    service_mcap = read_mcap(s.service_recordings["mcap"])
    assert service_mcap["/metadata"][0]["rate_hz"] == RATE  # the session ran the 40 Hz model
    for side in (s.recordings, s.service_recordings):
        faults = read_mcap(side["mcap"])["/fault"]
        assert [m["step"] for m in faults] == list(range(TICKS))
        assert [m["energy"] for m in faults] == s.energies
        for ticks in (np.diff(_log_times_ns(side["mcap"], "/fault")),
                      np.diff(_rrd_times_ns(side["rrd"], "/fault/energy"))):
            assert len(ticks) == TICKS - 1 and np.all(np.abs(ticks - TICK_NS) <= 1_000)  # one tick apart


def test_the_correction_engages_on_the_first_confirmed_flag_at_40_hz(model_dir, tmp_path):
    [s] = run_client(SimulatedRun(SKILL, SEED, falling_object=falling_object(True), rate=RATE, controller="compliant",
                                  correct=True), Connection(), StreamOptions(out=tmp_path, quiet=True), model_dir)
    flags = [m["fault"] for m in read_mcap(s.service_recordings["mcap"])["/fault"]]
    assert len(flags) == TICKS and s.detected
    # confirmed: the first flag that ends SIM.correction.confirm_at(RATE) of flags each within that of the last
    window = round(SIM.correction.confirm_at(RATE) * RATE)
    ticks = np.flatnonzero(flags)
    runs = np.split(ticks, np.flatnonzero(np.diff(ticks) >= window) + 1)
    confirmed = min(int(run[np.searchsorted(run - run[0], window)]) for run in runs if run[-1] - run[0] >= window)
    assert s.correction == {"engaged_step": confirmed, "yielded_step": None}
    assert 160 < s.first_flag_step < 200  # flagged within a second of the release at 4 s (tick 160)
    assert confirmed >= s.first_flag_step + window  # engaged no sooner than that after the first flag
    assert read_mcap(s.recordings["mcap"])["/metadata"][0]["correction"]["engaged_step"] == confirmed


def test_a_service_without_a_40_hz_model_is_refused_by_name(small_panda_model, tmp_path):
    only_2hz = tmp_path / "models"
    only_2hz.mkdir()
    checkpoint.save(small_panda_model, only_2hz / f"{model_name()}.safetensors")
    settings = Settings(models_dir=only_2hz, recordings_dir=tmp_path / "rec", build_default_model=False)
    with start_embedded(settings) as srv, pytest.raises(ServiceError, match=model_name(RATE)):
        run_client(SimulatedRun(SKILL, SEED, rate=RATE), Connection(srv.url),
                   StreamOptions(out=tmp_path / "rec", quiet=True))
    assert compliant_name(RATE) == "panda-40hz-compliant"


def test_cli_passes_the_rate_and_pacing_on_and_refuses_other_rates(monkeypatch, tmp_path):
    seen = {}
    monkeypatch.setattr("neural_asm.client.cli.run_client", lambda *a, **kw: seen.update(args=a, kwargs=kw) or [])
    result = CliRunner().invoke(app, ["--rate", "40", "--realtime", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    run, _, options, _ = seen["args"]
    assert run.rate == RATE and options.realtime is True
    assert options.mode is None  # the mode: the rate's default (online at 40 Hz)
    refused = CliRunner().invoke(app, ["--rate", "10", "--out", str(tmp_path)])
    assert refused.exit_code == 2 and "2, 40" in refused.output
