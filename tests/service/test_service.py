"""The service end to end, against a real uvicorn server on loopback.

A small model is trained on synthetic Panda-shaped data (25 named channels), saved as
a checkpoint and served; answers are compared with the model's own ``SkillStream``.
"""

import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
import websockets
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from neural_asm.models.answer import API_KEY_HEADER
from neural_asm.recordings.blueprint import ENERGY
from neural_asm.recordings.readers import read_mcap, read_rrd_series
from neural_asm.service.app import create_app
from neural_asm.service.cli import app as cli_app
from neural_asm.service.embedded import start_embedded
from neural_asm.service.errors import TooManySessions
from neural_asm.service.sessions import Session, SessionStore
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import CHANNEL_NAMES

MAX_SESSIONS = 12


@pytest.fixture(scope="module")
def server(model_dir: Path, tmp_path_factory: pytest.TempPathFactory):
    settings = Settings(models_dir=model_dir, recordings_dir=tmp_path_factory.mktemp("recordings"),
                        max_sessions=MAX_SESSIONS, max_body_bytes=16 * 1024)
    with start_embedded(settings) as srv:
        yield srv


@pytest.fixture
def client(server):
    with httpx.Client(base_url=server.url, timeout=10) as c:
        yield c


def open_session(client: httpx.Client, **params) -> dict:
    r = client.post("/sessions", json=params)
    assert r.status_code == 201, r.text
    return r.json()


def test_health_and_models(client):
    assert client.get("/healthz").json()["status"] == "ok"
    (model,) = client.get("/models").json()
    assert model["name"] == "panda" and model["channel_names"] == list(CHANNEL_NAMES)
    assert {(c["mode"], c["cue_steps"]) for c in model["calibrations"]} == {("offline", 1), ("online", 1)}
    assert 0.01 in model["calibrations"][0]["fprs"]
    assert all(c["whitened"] for c in model["calibrations"])  # the default scoring
    assert model["rate_hz"] == 2.0  # trained on 2 Hz sequences


def test_a_client_at_another_rate_is_refused_and_the_server_serves_on(client, episodes):
    """A 40 Hz client on a 2 Hz model gets a 409 naming both rates; its own rate opens a session that steps."""
    r = client.post("/sessions", json={"rate_hz": 40})
    assert r.status_code == 409, r.text
    detail = r.json()["detail"]
    assert "'panda'" in detail and "500 ms (2 Hz)" in detail and "25 ms (40 Hz)" in detail
    assert client.post("/sessions", json={"rate_hz": -2}).status_code == 422
    info = open_session(client, rate_hz=2.0)
    assert info["rate_hz"] == 2.0
    step = client.post("/predict", json={"session_id": info["session_id"], "observation": episodes[0, 0].tolist()})
    assert step.status_code == 200, step.text
    assert client.delete(f"/sessions/{info['session_id']}").status_code == 200


def test_a_session_naming_no_mode_gets_the_models_served_mode(client, servable_model, tmp_path):
    assert open_session(client)["mode"] == "offline"  # the 2 Hz model: the paper's setting
    fast = servable_model(modes=("offline", "online"), name="fast", rate_hz=20.0)
    with start_embedded(Settings(models_dir=fast, recordings_dir=tmp_path)) as srv, \
            httpx.Client(base_url=srv.url, timeout=10) as c:
        assert open_session(c)["mode"] == "online"  # a 20 Hz model: online, where it wins
        assert open_session(c, mode="offline")["mode"] == "offline"  # a session may still ask


def test_session_lifecycle(client):
    info = open_session(client, mode="offline", fpr=0.05, threshold="per_step")
    sid = info["session_id"]
    assert (info["model"], info["mode"], info["fpr"], info["threshold"], info["steps"]) == (
        "panda", "offline", 0.05, "per_step", 0)
    assert client.get(f"/sessions/{sid}").json()["session_id"] == sid
    assert client.delete(f"/sessions/{sid}").status_code == 200
    for r in (client.get(f"/sessions/{sid}"), client.delete(f"/sessions/{sid}")):
        assert r.status_code == 404 and sid in r.json()["detail"]


def test_predict_and_fault_match_the_model(client, episodes, reference):
    """Alternating /predict and /fault steps equal SkillStream.step, in both input forms."""
    sid = open_session(client, mode="online")["session_id"]
    stream = reference.stream("online", 1)
    calibration = reference.calibration("online", 1)
    for k, x in enumerate(episodes[0]):
        expected = stream.step(x)
        body = {"session_id": sid, "observation": x.tolist()} if k % 2 else \
            {"session_id": sid, "channels": dict(zip(CHANNEL_NAMES, x.tolist()))}
        if k % 3:
            r = client.post("/predict", json=body).json()
            assert list(r["prediction"]) == list(CHANNEL_NAMES)
            np.testing.assert_allclose(list(r["prediction"].values()), expected.prediction, rtol=1e-4, atol=1e-5)
            np.testing.assert_allclose(list(r["errors"].values()), expected.weighted_errors, rtol=1e-4, atol=1e-4)
        else:
            r = client.post("/fault", json=body).json()
            assert r["threshold"] == pytest.approx(calibration.episode_thresholds[0.01])  # the default kind
            assert r["fault"] == (r["energy"] > r["threshold"])
            assert r["isolated_joint"].startswith("joint")
            errors = [c["error"] for c in r["ranked_channels"]]
            assert errors == sorted(errors, reverse=True) and len(errors) == 25
        assert r["step"] == k and r["inference_ms"] > 0 and r["batch_size"] >= 1 and r["skill"] == expected.skill
        assert r["energy"] == pytest.approx(expected.energy, rel=1e-4)
    client.delete(f"/sessions/{sid}")


def test_websocket_episode_and_its_recordings(server, episodes):
    async def episode() -> tuple[dict, list[dict], dict]:
        url = server.url.replace("http", "ws") + "/stream"
        async with websockets.connect(url) as ws:
            meta = json.loads(await ws.recv())
            await ws.send(json.dumps({"type": "start", "recording_id": "client-run-1"}))
            started = json.loads(await ws.recv())
            assert meta["type"] == "metadata" and meta["models"] == ["panda"] and started["type"] == "started"
            steps = []
            for x in episodes[1]:
                await ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
                steps.append(json.loads(await ws.recv()))
            await ws.send(json.dumps({"type": "end"}))
            ended = json.loads(await ws.recv())
            assert ended["type"] == "ended" and ended["steps"] == len(episodes[1])
            return started, steps, ended

    started, steps, _ = asyncio.run(episode())
    assert [s["step"] for s in steps] == list(range(len(episodes[1])))
    for s in steps:
        assert s["type"] == "step" and {"fault", "threshold", "isolated_joint", "ranked_channels", "prediction",
                                        "errors", "energy", "inference_ms"} <= set(s)
    assert started["recording_id"] == "client-run-1"
    rrd, mcap = Path(started["recordings"]["rrd"]), Path(started["recordings"]["mcap"])
    verify = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(rrd)], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    energies = [s["energy"] for s in steps]
    times, values = read_rrd_series(rrd, ENERGY)
    assert times.tolist() == list(range(len(steps)))
    np.testing.assert_array_equal(values[:, 0], energies)
    np.testing.assert_array_equal(values[:, 1], [s["threshold"] for s in steps])
    messages = read_mcap(mcap)
    assert messages["/metadata"][0]["recording_id"] == "client-run-1"
    assert [m["energy"] for m in messages["/fault"]] == energies
    assert [m["fault"] for m in messages["/fault"]] == [s["fault"] for s in steps]
    assert [m["joint1"] for m in messages["/prediction"]] == [s["prediction"]["joint1"] for s in steps]
    np.testing.assert_array_equal([m["ee_x"] for m in messages["/observation"]], episodes[1][:, 7])


def test_concurrent_websocket_sessions(server, episodes, reference):
    """Eight episodes at once over eight connections: each scored as if alone."""
    async def run(i: int) -> list[float]:
        async with websockets.connect(server.url.replace("http", "ws") + "/stream") as ws:
            await ws.recv()
            await ws.send(json.dumps({"type": "start"}))
            await ws.recv()
            out = []
            for x in episodes[i]:
                await ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
                out.append(json.loads(await ws.recv()))
            return out

    async def all_runs() -> list[list[dict]]:
        return await asyncio.gather(*(run(i) for i in range(8)))

    results = asyncio.run(all_runs())
    for i, steps in enumerate(results):
        stream = reference.stream("offline", 1)  # the server's default mode
        np.testing.assert_allclose([s["energy"] for s in steps], [stream.step(x).energy for x in episodes[i]], rtol=1e-4)


def test_websocket_mistakes_keep_the_connection(server, episodes):
    async def talk() -> list[dict]:
        async with websockets.connect(server.url.replace("http", "ws") + "/stream") as ws:
            await ws.recv()
            answers = []
            for text in ['{"type": "step", "observation": [1.0]}', "not json", '{"type": "start", "model": "nope"}',
                         '{"type": "start", "rate_hz": 40}', '{"type": "start"}', '{"type": "step", "observation": [NaN]}',
                         json.dumps({"type": "step", "observation": episodes[0, 0].tolist()})]:
                await ws.send(text)
                answers.append(json.loads(await ws.recv()))
            return answers

    answers = asyncio.run(talk())
    assert [a.get("status") for a in answers] == [409, 400, 404, 409, None, 422, None]
    assert "start" in answers[0]["detail"] and "nope" in answers[2]["detail"] and "finite" in answers[5]["detail"]
    assert "(40 Hz)" in answers[3]["detail"]
    assert answers[4]["type"] == "started" and answers[6]["type"] == "step"


def _post(client: httpx.Client, path: str, body: bytes) -> httpx.Response:
    return client.post(path, content=body, headers={"content-type": "application/json"})


@pytest.mark.parametrize(
    "make_body, status, words",
    [
        (lambda sid, x: {"session_id": sid, "observation": x[:24]}, 422, ["observation", "24", "25"]),
        (lambda sid, x: {"session_id": sid, "observation": x + [0.0]}, 422, ["observation", "26"]),
        (lambda sid, x: {"session_id": sid, "observation": [np.nan] + x[1:]}, 422, ["observation.0", "finite"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:3] + [np.inf] + x[4:]}, 422, ["observation.3", "finite"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:5] + [1e7] + x[6:]}, 422, ["observation.5", "1000000"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:5] + [1e39] + x[6:]}, 422, ["observation.5"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:5] + ["a"] + x[6:]}, 422, ["observation.5"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:5] + ["1.5"] + x[6:]}, 422, ["observation.5"]),
        (lambda sid, x: {"session_id": sid, "observation": x[:5] + [True] + x[6:]}, 422, ["observation.5"]),
        (lambda sid, x: {"session_id": sid, "observation": x, "channels": None}, 422, ["channels"]),
        (lambda sid, x: {"session_id": sid, "channels": dict(zip(CHANNEL_NAMES[:-1], x))}, 422, ["missing", "right_tz"]),
        (lambda sid, x: {"session_id": sid, "channels": {**dict(zip(CHANNEL_NAMES, x)), "elbow": 1.0}}, 422, ["unknown", "elbow"]),
        (lambda sid, x: {"session_id": sid, "observation": x, "channels": {}}, 422, ["exactly one"]),
        (lambda sid, x: {"session_id": sid}, 422, ["exactly one"]),
        (lambda sid, x: {"observation": x}, 422, ["session_id", "required"]),
        (lambda sid, x: {"session_id": sid, "observation": x, "extra": 1}, 422, ["extra"]),
        (lambda sid, x: {"session_id": "0" * 32, "observation": x}, 404, ["session", "0" * 32]),
        (lambda sid, x: {"session_id": "../etc", "observation": x}, 422, ["session_id"]),
    ],
)
@pytest.mark.parametrize("path", ["/predict", "/fault"])
def test_bad_steps_get_4xx_naming_the_problem(client, episodes, path, make_body, status, words):
    sid = open_session(client)["session_id"]
    body = make_body(sid, episodes[0, 0].tolist())
    r = _post(client, path, json.dumps(body).encode())  # json.dumps writes NaN and Infinity literals
    assert r.status_code == status, r.text
    for word in words:
        assert word in r.json()["detail"], r.json()["detail"]
    ok = client.post(path, json={"session_id": sid, "observation": episodes[0, 0].tolist()})
    assert ok.status_code == 200 and ok.json()["step"] == 0  # the bad request did not advance the session
    client.delete(f"/sessions/{sid}")


@pytest.mark.parametrize(
    "body, status, word",
    [
        (b'{"session_id": "x", "observation": [1.0,', 400, "JSON"),
        (b"\xff\xfe\x00{", 400, "not valid JSON"),
        (b"[1, 2, 3]", 422, "valid dictionary"),
        (b'{"session_id": "x", "observation": [' + b"1.0," * 8000 + b"1.0]}", 413, "larger than"),
    ],
)
def test_undecodable_and_oversize_bodies(client, body, status, word):
    r = _post(client, "/fault", body)
    assert r.status_code == status and word in r.json()["detail"], r.text
    assert client.get("/healthz").status_code == 200


@pytest.mark.parametrize(
    "params, status, word",
    [
        ({"model": "nope"}, 404, "nope"),
        ({"fpr": 0.5}, 422, "0.5"),
        ({"cue_steps": 3}, 409, "cued from 3"),
        ({"cue_steps": True}, 422, "cue_steps"),
        ({"fpr": "0.01"}, 422, "fpr"),
        ({"fpr": True}, 422, "fpr"),
        ({"cue_steps": 0}, 422, "cue_steps"),
        ({"mode": "sideways"}, 422, "mode"),
        ({"recording_id": "../../x"}, 422, "recording_id"),
    ],
)
def test_bad_sessions(client, params, status, word):
    r = client.post("/sessions", json=params)
    assert r.status_code == status and word in r.json()["detail"], r.text


def test_session_cap(client):
    already = client.get("/healthz").json()["sessions"]
    opened = [open_session(client)["session_id"] for _ in range(MAX_SESSIONS - already)]
    r = client.post("/sessions", json={})
    assert r.status_code == 429 and "cap" in r.json()["detail"]
    for sid in opened:
        client.delete(f"/sessions/{sid}")
    assert client.post("/sessions", json={}).status_code == 201


def test_idle_sessions_expire():
    store = SessionStore(cap=2, per_client=2, idle_s=10)
    session = Session("a", "m", None, "r")  # type: ignore[arg-type]
    store.add(session)
    assert store.pop_idle(now=session.last_used + 5) == []
    assert store.pop_idle(now=session.last_used + 11) == [session] and "a" not in store
    for sid in "bc":  # the expired session no longer counts against its client's quota
        store.add(Session(sid, "m", None, "r"))  # type: ignore[arg-type]
    with pytest.raises(TooManySessions, match="quota is 2"):
        store.add(Session("d", "m", None, "r"))  # type: ignore[arg-type]


def test_api_key_enforced_and_expiry_on_a_keyed_server(model_dir, tmp_path, episodes):
    settings = Settings(models_dir=model_dir, api_key="s3cret", record=False, session_idle_s=0.4,
                        recordings_dir=tmp_path)
    with start_embedded(settings) as srv, httpx.Client(base_url=srv.url) as c:
        assert c.get("/healthz").status_code == 200
        for headers in ({}, {API_KEY_HEADER: "wrong"}):
            r = c.get("/models", headers=headers)
            assert r.status_code == 401 and API_KEY_HEADER in r.json()["detail"]
            assert c.post("/sessions", json={}, headers=headers).status_code == 401
        key = {API_KEY_HEADER: "s3cret"}
        info = c.post("/sessions", json={}, headers=key).json()
        assert info["recordings"] == {} and not list(tmp_path.iterdir())

        async def ws(headers: dict) -> str:
            async with websockets.connect(srv.url.replace("http", "ws") + "/stream", additional_headers=headers) as w:
                return json.loads(await w.recv())["type"]

        for headers in ({}, {API_KEY_HEADER: "wrong"}):  # as the stream's docstring and the AsyncAPI document say
            with pytest.raises(websockets.exceptions.ConnectionClosedError) as closed:
                asyncio.run(ws(headers))
            assert closed.value.rcvd.code == 1008 and API_KEY_HEADER in closed.value.rcvd.reason
        assert asyncio.run(ws(key)) == "metadata"
        time.sleep(1.0)
        assert c.get(f"/sessions/{info['session_id']}", headers=key).status_code == 404


def test_refuses_to_expose_without_a_key(tmp_path):
    with pytest.raises(ValueError, match="API key"):
        create_app(Settings(host="0.0.0.0", models_dir=tmp_path))
    result = CliRunner().invoke(cli_app, ["serve", "--host", "0.0.0.0", "--models-dir", str(tmp_path)])
    assert result.exit_code == 2 and "API key" in result.output
    create_app(Settings(host="0.0.0.0", api_key="k", models_dir=tmp_path))  # with a key it may


def test_no_models_is_a_clear_404(tmp_path):
    with TestClient(create_app(Settings(models_dir=tmp_path, build_default_model=False, record=False))) as c:
        assert c.get("/models").json() == []
        r = c.post("/sessions", json={})
        assert r.status_code == 404 and "no models loaded" in r.json()["detail"]


def test_step_payloads_match_their_declared_schemas(client, episodes, server):
    from neural_asm.service.schemas import FaultResponse, PredictResponse, StepResult

    sid = open_session(client)["session_id"]
    x = episodes[0, 0].tolist()
    PredictResponse.model_validate(client.post("/predict", json={"session_id": sid, "observation": x}).json())
    FaultResponse.model_validate(client.post("/fault", json={"session_id": sid, "observation": x}).json())

    async def one_step() -> dict:
        async with websockets.connect(server.url.replace("http", "ws") + "/stream") as ws:
            await ws.recv()
            await ws.send('{"type": "start"}')
            await ws.recv()
            await ws.send(json.dumps({"type": "step", "observation": x}))
            return json.loads(await ws.recv())

    step = asyncio.run(one_step())
    assert step.pop("type") == "step"
    StepResult.model_validate(step)
