"""The transports' step answers: parsed once into a ``StepAnswer``; a payload that is none is the
service's error, named."""

import httpx
import pytest

from neural_asm.client.transport import HttpTransport, ServiceError
from neural_asm.models.answer import SESSION_ID_HEADER

ANSWER = {"session_id": "s", "step": 0, "energy": 2.5, "inference_ms": 0.4, "batch_size": 1, "skill": None,
          "fault": True, "threshold": 1.5, "fpr": 0.01, "isolated_joint": "joint2",
          "ranked_channels": [{"channel": "joint2", "error": 1.2}, {"channel": "joint1", "error": 0.3}]}


def _transport(fault_payload: dict) -> HttpTransport:
    """An HTTP transport whose service answers ``/fault`` with ``fault_payload``."""
    def answer(request: httpx.Request) -> httpx.Response:
        if request.url.path == "/sessions":
            return httpx.Response(201, json={"session_id": "s"})
        assert request.headers[SESSION_ID_HEADER] == "s"
        return httpx.Response(200, json=fault_payload)

    t = HttpTransport("http://127.0.0.1:1", None)
    t.client = httpx.Client(base_url="http://127.0.0.1:1", transport=httpx.MockTransport(answer))
    t.start({})
    return t


def test_an_http_step_is_a_typed_answer():
    answer = _transport(ANSWER).step([0.0, 1.0])
    assert (answer.fault, answer.energy, answer.isolated_joint, answer.session_id) == (True, 2.5, "joint2", "s")
    assert answer.ranked_channels[0] == {"channel": "joint2", "error": 1.2}
    assert answer.prediction is answer.expected is answer.errors is None  # /fault sends no forecast


def test_a_step_payload_without_a_decision_is_a_service_error():
    partial = {k: v for k, v in ANSWER.items() if k not in ("fault", "threshold")}
    with pytest.raises(ServiceError, match="no 'fault', 'threshold'"):
        _transport(partial).step([0.0, 1.0])
