"""``GET /metrics`` against a real uvicorn server: scraped after streamed episodes and parsed
with prometheus-client's own parser, its counts must be what was streamed and refused."""

from __future__ import annotations

import json
from pathlib import Path

import httpx
import numpy as np
import pytest
from prometheus_client.parser import text_string_to_metric_families
from websockets.sync.client import connect

from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings

KEY = "metrics-test-key"


@pytest.fixture(scope="module")
def model_dir(servable_model) -> Path:
    return servable_model(n_skills=2, repetitions=4, steps=8, hidden_size=16, epochs=20, name="panda", seed=2)


def scrape(url: str, **headers: str) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    """Every sample of ``/metrics`` by (name, labels)."""
    r = httpx.get(url + "/metrics", headers=headers)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"].startswith("text/plain")
    return {(s.name, tuple(sorted(s.labels.items()))): s.value
            for family in text_string_to_metric_families(r.text) for s in family.samples}


def stream(url: str, episode: np.ndarray, key: str | None = None) -> list[bool]:
    """One episode over the websocket, a malformed step in the middle; the flags answered."""
    flags = []
    with connect(url.replace("http", "ws") + "/stream", additional_headers={"X-API-Key": key} if key else {}) as ws:
        assert json.loads(ws.recv())["type"] == "metadata"
        ws.send(json.dumps({"type": "start", "model": "panda", "mode": "offline"}))
        assert json.loads(ws.recv())["type"] == "started"
        for k, x in enumerate(episode):
            if k == 3:
                ws.send(json.dumps({"type": "step", "observation": [1.0, 2.0]}))  # wrong length: a 422, not a step
                assert json.loads(ws.recv())["status"] == 422
            ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
            reply = json.loads(ws.recv())
            assert reply["type"] == "step", reply
            flags.append(reply["fault"])
        ws.send(json.dumps({"type": "end"}))
        assert json.loads(ws.recv())["type"] == "ended"
    return flags


def test_counts_after_streamed_episodes_equal_what_was_streamed(model_dir, tmp_path):
    episodes = np.load(model_dir / "episodes.npy")
    faulty = episodes[1].copy()
    faulty[4:] += 5.0  # far off every training episode: flagged
    settings = Settings(models_dir=model_dir, recordings_dir=tmp_path, build_default_model=False)
    with start_embedded(settings) as srv:
        flags = stream(srv.url, episodes[0]) + stream(srv.url, faulty)
        assert httpx.post(srv.url + "/fault", json={"session_id": "nope", "observation": [0.0]}).status_code in (404, 422)
        assert httpx.get(srv.url + "/sessions/unknown").status_code == 404
        samples = scrape(srv.url)

    model = (("model", "panda"),)
    assert sum(flags) > 0 and not all(flags)
    assert samples[("nasm_steps_total", model)] == len(flags) == 2 * episodes.shape[1]
    assert samples[("nasm_flags_total", model)] == sum(flags)
    assert samples[("nasm_step_latency_seconds_count", model)] == len(flags)
    assert samples[("nasm_sessions_opened_total", model)] == 2
    assert samples[("nasm_sessions_open", ())] == 0
    assert samples[("nasm_websocket_errors_total", (("status", "422"),))] == 2
    assert samples[("nasm_http_errors_total", (("status", "404"),))] >= 1
    assert samples[("nasm_records_dropped_total", ())] == 0
    assert samples[("nasm_checkpoints_refused", ())] == 0
    assert 0 <= samples[("nasm_recorder_queue_depth", ())] <= 16


def test_metrics_follow_the_api_key_and_name_no_session_or_client(model_dir, tmp_path):
    (model_dir / "broken.safetensors").write_bytes(b"not a checkpoint")
    try:
        settings = Settings(models_dir=model_dir, recordings_dir=tmp_path, build_default_model=False, api_key=KEY,
                            record=False)
        with start_embedded(settings) as srv:
            assert httpx.get(srv.url + "/metrics").status_code == 401
            assert httpx.get(srv.url + "/metrics", headers={"Authorization": "Bearer wrong"}).status_code == 401
            episode = np.load(model_dir / "episodes.npy")[0]
            stream(srv.url, episode, KEY)
            text = httpx.get(srv.url + "/metrics", headers={"X-API-Key": KEY}).text
            samples = scrape(srv.url, Authorization=f"Bearer {KEY}")
    finally:
        (model_dir / "broken.safetensors").unlink()
    assert samples[("nasm_steps_total", (("model", "panda"),))] == len(episode)
    assert samples[("nasm_checkpoints_refused", ())] == 1
    assert samples[("nasm_http_errors_total", (("status", "401"),))] == 2  # the two refused scrapes
    assert KEY not in text and "127.0.0.1" not in text and "session-" not in text
    labels = {name for family in text_string_to_metric_families(text) for s in family.samples for name in s.labels}
    assert labels <= {"model", "status", "le"}


def test_metrics_off_means_no_route(model_dir, tmp_path):
    settings = Settings(models_dir=model_dir, recordings_dir=tmp_path, build_default_model=False, record=False,
                        metrics=False)
    with start_embedded(settings) as srv:
        assert httpx.get(srv.url + "/metrics").status_code == 404
