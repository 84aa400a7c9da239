"""The API contract: what the OpenAPI and AsyncAPI documents promise is what the service does.

In-process (TestClient, no recording): quotas per client, 405 Allow headers, path
parameter patterns, the security scheme declared only with a key, the JSON schema's
oneOf and enum, every websocket message checked against ``/asyncapi.json``, and every step
payload one ``StepAnswer``, the type a local ``Monitor`` answers with.
"""

import dataclasses
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from fastapi.testclient import TestClient

from neural_asm.models.answer import API_KEY_HEADER, StepAnswer
from neural_asm.models.config import SCORING
from neural_asm.service.app import create_app
from neural_asm.service.schemas import FAULT, FaultResponse, PredictResponse, StepResult
from neural_asm.service.settings import Settings
from neural_asm.sim.channels import CHANNEL_NAMES


@pytest.fixture(scope="module")
def model_dir(servable_model) -> Path:
    return servable_model(steps=5)


def _app(model_dir: Path, **settings):
    return create_app(Settings(models_dir=model_dir, record=False, build_default_model=False, **settings))


def test_quota_per_client_address(model_dir):
    app = _app(model_dir, max_sessions=10, max_sessions_per_client=2)
    with TestClient(app, client=("10.0.0.1", 5000)) as a, TestClient(app, client=("10.0.0.2", 5000)) as b:
        opened = [a.post("/sessions", json={}).json()["session_id"] for _ in range(2)]
        r = a.post("/sessions", json={})
        assert r.status_code == 429 and "10.0.0.1" in r.json()["detail"] and "quota is 2" in r.json()["detail"]
        assert b.post("/sessions", json={}).status_code == 201  # another client is not locked out
        a.delete(f"/sessions/{opened[0]}")
        assert a.post("/sessions", json={}).status_code == 201


def test_quota_per_api_key_counts_websocket_sessions_too(model_dir):
    app = _app(model_dir, api_key="k", max_sessions_per_client=1)
    with TestClient(app) as c:
        assert c.post("/sessions", json={}, headers={API_KEY_HEADER: "k"}).status_code == 201
        with c.websocket_connect("/stream", headers={API_KEY_HEADER: "k"}) as ws:
            ws.receive_json()
            ws.send_json({"type": "start"})
            answer = ws.receive_json()
        assert answer["type"] == "error" and answer["status"] == 429 and "quota is 1" in answer["detail"]


def test_405_lists_every_method_of_the_path(model_dir):
    with TestClient(_app(model_dir)) as c:
        sid = c.post("/sessions", json={}).json()["session_id"]
        for method in ("PUT", "PATCH", "OPTIONS", "POST"):
            r = c.request(method, f"/sessions/{sid}")
            assert r.status_code == 405 and r.headers["allow"] == "DELETE, GET", (method, r.headers)
        assert c.request("PUT", "/predict").headers["allow"] == "POST"


@pytest.mark.parametrize("sid", ["a!b", "a" * 65, "a.b", "%20"])
def test_path_session_id_follows_the_pattern(model_dir, sid):
    with TestClient(_app(model_dir)) as c:
        for method in ("GET", "DELETE"):
            r = c.request(method, f"/sessions/{sid}")
            assert r.status_code == 422 and "session_id" in r.json()["detail"], r.text


def test_openapi_declares_the_key_only_when_there_is_one(model_dir):
    with TestClient(_app(model_dir)) as c:
        open_spec = c.get("/openapi.json").json()
    with TestClient(_app(model_dir, api_key="k")) as c:
        keyed = c.get("/openapi.json").json()
    assert "securitySchemes" not in open_spec.get("components", {})
    assert all("security" not in op and "401" not in op["responses"]
               for ops in open_spec["paths"].values() for op in ops.values())
    assert keyed["components"]["securitySchemes"]["APIKeyHeader"]["name"] == API_KEY_HEADER
    assert keyed["paths"]["/models"]["get"]["security"] == [{"APIKeyHeader": []}]
    assert "security" not in keyed["paths"]["/healthz"]["get"]


def test_schema_states_the_rules(model_dir):
    with TestClient(_app(model_dir)) as c:
        spec = c.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    assert schemas["StepRequest"]["oneOf"] == [{"required": ["observation"]}, {"required": ["channels"]}]
    fpr = schemas["SessionCreate"]["properties"]["fpr"]
    assert {"type": "number", "enum": list(SCORING.fprs)} in fpr["anyOf"]
    validator = jsonschema.Draft202012Validator({**schemas["StepRequest"], "components": spec["components"]})
    assert validator.is_valid({"session_id": "a", "observation": [1.0]})
    for body in ({"session_id": "a"}, {"session_id": "a", "observation": [1.0], "channels": {"x": 1.0}},
                 {"session_id": "a", "observation": None}):
        assert not validator.is_valid(body), body


def _validator(document: dict, message: str) -> jsonschema.Draft202012Validator:
    """The payload schema of one AsyncAPI message; its refs resolve inside the document."""
    ref = document["channels"]["stream"]["messages"][message]["$ref"]
    name = ref.rsplit("/", 1)[1]
    payload = document["components"]["messages"][name]["payload"]
    return jsonschema.Draft202012Validator({**payload, "components": document["components"]})


def test_asyncapi_document_describes_the_stream(model_dir):
    with TestClient(_app(model_dir)) as c:
        document = c.get("/asyncapi.json").json()
        x = [0.1] * len(CHANNEL_NAMES)
        sent = [{"type": "start", "mode": "offline"}, {"type": "step", "observation": x},
                {"type": "step", "channels": dict(zip(CHANNEL_NAMES, x))}, {"type": "step", "observation": [1.0]},
                {"type": "end"}]
        with c.websocket_connect("/stream") as ws:
            received = [ws.receive_json()]
            for message in sent:
                ws.send_json(message)
                received.append(ws.receive_json())
    assert document["asyncapi"].startswith("3.") and document["channels"]["stream"]["address"] == "/stream"
    operations = document["operations"]
    assert {op["action"] for op in operations.values()} == {"send", "receive"}
    for op in operations.values():  # every reference resolves to a message of the channel
        for ref in op["messages"] + op.get("reply", {}).get("messages", []):
            assert ref["$ref"].rsplit("/", 1)[1] in document["channels"]["stream"]["messages"]
    names = {"start": "start", "step": "step", "end": "end"}
    for message in sent:
        _validator(document, names[message["type"]]).validate(message)
    replies = {"metadata": "metadata", "started": "started", "step": "stepResult", "ended": "ended", "error": "error"}
    assert [r["type"] for r in received] == ["metadata", "started", "step", "step", "error", "ended"]
    for reply in received:
        _validator(document, replies[reply["type"]]).validate(reply)
    for wrong in ({"type": "step"}, {"type": "start", "fpr": 0.5}, {"type": "start", "cue_steps": "1"},
                  {"type": "launch"}):
        kind = wrong["type"] if wrong["type"] in names else "start"
        assert not _validator(document, kind).is_valid(wrong), wrong


def test_every_step_payload_is_one_step_answer_and_a_local_monitor_gives_the_same(model_dir):
    """/predict, /fault and the websocket step each send their declared keys, which are the parts
    of one StepAnswer; /fault and the websocket parse into it and back unchanged, and a local
    Monitor with the same settings answers the same observation with the same values, less the
    service's part."""
    from neural_asm.memory import SkillMemory

    schemas = {"predict": PredictResponse, "fault": FaultResponse, "step": StepResult}
    x = np.load(model_dir / "episodes.npy")[0]
    local = SkillMemory.load(model_dir / "m.safetensors").monitor("offline", 0.05)
    with TestClient(_app(model_dir)) as c:
        sid = c.post("/sessions", json={"mode": "offline", "fpr": 0.05}).json()["session_id"]
        payloads = {route: c.post(f"/{route}", json={"session_id": sid, "observation": x[0].tolist()}).json()
                    for route in ("predict", "fault")}
        with c.websocket_connect("/stream") as ws:
            ws.receive_json()
            ws.send_json({"type": "start", "mode": "offline", "fpr": 0.05})
            ws.receive_json()
            ws.send_json({"type": "step", "observation": x[0].tolist()})
            payloads["step"] = ws.receive_json()
    assert payloads["step"].pop("type") == "step"
    for route, payload in payloads.items():
        assert list(payload) == list(schemas[route].model_fields), route  # the declared keys, in their order
    assert set(payloads["predict"]) | set(payloads["fault"]) == set(payloads["step"])
    fault, step = StepAnswer.from_json(payloads["fault"]), StepAnswer.from_json(payloads["step"])
    assert fault.to_json(FAULT) == payloads["fault"] and fault.prediction is None
    assert step.to_json() == payloads["step"] and step.session_id and step.inference_ms and step.batch_size == 1
    mine = local.step(x[0])
    assert mine.session_id is mine.inference_ms is mine.batch_size is None
    assert dataclasses.replace(step, session_id=None, inference_ms=None, batch_size=None) == mine


def test_a_payload_that_is_no_step_answer_is_refused_naming_what_it_lacks():
    with pytest.raises(ValueError, match="no 'fault', 'threshold'"):
        StepAnswer.from_json({"type": "step", "step": 0, "energy": 1.0, "skill": None})
