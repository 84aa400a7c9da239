"""What a load balancer needs to route a session's HTTP requests (docker/haproxy.cfg): every
answer about a session names it in the ``X-Session-Id`` header, and the HTTP client sends the
header back with each step."""

import httpx
import pytest

from neural_asm.client.transport import HttpTransport
from neural_asm.models.answer import SESSION_ID_HEADER
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings


@pytest.fixture(scope="module")
def server(servable_model, tmp_path_factory):
    folder = servable_model(name="panda")
    settings = Settings(models_dir=folder, recordings_dir=tmp_path_factory.mktemp("recordings"), record=False)
    with start_embedded(settings) as srv:
        yield srv


def test_answers_name_their_session(server):
    with httpx.Client(base_url=server.url, timeout=10) as c:
        created = c.post("/sessions", json={"mode": "offline"})
        sid = created.json()["session_id"]
        assert created.headers[SESSION_ID_HEADER] == sid
        step = c.post("/fault", json={"session_id": sid, "observation": [0.0] * 25})
        assert step.status_code == 200 and step.headers[SESSION_ID_HEADER] == sid
        assert c.post("/predict", json={"session_id": sid, "observation": [0.0] * 25}).headers[SESSION_ID_HEADER] == sid
        assert SESSION_ID_HEADER not in c.get("/healthz").headers


def test_http_client_sends_the_session_header(server):
    seen: list[tuple[str, str | None]] = []
    t = HttpTransport(server.url, None)
    t.client.event_hooks["request"] = [lambda r: seen.append((r.url.path, r.headers.get(SESSION_ID_HEADER)))]
    try:
        sid = t.start({"mode": "offline"})["session_id"]
        t.step([0.0] * 25)
        t.end()
    finally:
        t.close()
    assert seen == [("/sessions", None), ("/fault", sid), (f"/sessions/{sid}", None)]
