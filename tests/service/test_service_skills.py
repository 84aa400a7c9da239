"""A skill memory served: sessions told the skill at their start or inferring it answer as the
in-process monitor does, step by step, over HTTP and the websocket; the skills a session cannot be
told are refused in one line, and the session goes on. On the tests' own kitting-shaped courses."""


import numpy as np
import pytest
from fastapi.testclient import TestClient

from kitting_fixtures import SKILL_CHANNELS, SKILL_NAMES as SKILLS, served_models, skill_runs as runs, told_memory
from neural_asm import SkillMemory
from neural_asm.models.answer import StepAnswer
from neural_asm.service.app import create_app
from neural_asm.service.schemas import FAULT, PREDICT
from neural_asm.service.settings import Settings

memory = pytest.fixture(scope="module")(told_memory)


@pytest.fixture(scope="module")
def client(memory: SkillMemory, tmp_path_factory: pytest.TempPathFactory):
    folder = served_models(tmp_path_factory.mktemp("models"), memory)
    settings = Settings(models_dir=folder, record=False, build_default_model=False, default_model="kitting")
    with TestClient(create_app(settings)) as c:
        yield c


SERVICE = ("session_id", "inference_ms", "batch_size")


def served(client: TestClient, run: np.ndarray, skill: str | None, route: str = "/fault") -> list[dict]:
    """A session's payloads of a run, less what only a service knows."""
    opened = client.post("/sessions", json={} if skill is None else {"skill": skill})
    assert opened.status_code == 201 and opened.json()["skill"] == skill, opened.text
    sid = opened.json()["session_id"]
    payloads = [client.post(route, json={"session_id": sid, "observation": v.tolist()}).json() for v in run]
    client.delete(f"/sessions/{sid}")
    return [{k: v for k, v in p.items() if k not in SERVICE} for p in payloads]


def in_process(memory: SkillMemory, run: np.ndarray, skill: str | None) -> list[StepAnswer]:
    monitor = memory.monitor(skill=skill)
    return [monitor.step(v) for v in run]


def local(answer: StepAnswer, parts) -> dict:
    return {k: v for k, v in answer.to_json(parts).items() if k not in SERVICE}


@pytest.mark.parametrize("skill", [None, "4"])
def test_served_answers_are_the_monitors_and_the_scores_step_by_step(client, memory, skill):
    x, y = runs(1, 4)
    off_course = x[list(y).index("3")]  # told 4, it follows skill 3's course
    for run in (x[list(y).index("4")], off_course):
        mine = in_process(memory, run, skill)
        assert served(client, run, skill) == [local(a, FAULT) for a in mine]
        assert served(client, run, skill, "/predict") == [local(a, PREDICT) for a in mine]
        energies, _ = memory.score_skills(run[None], None if skill is None else [skill])
        np.testing.assert_allclose([a.energy for a in mine], energies[0], rtol=1e-3, atol=1e-3)
    assert mine[-1].skill == (skill or "3") and any(a.fault for a in mine) == (skill is not None)
    assert mine[-1].skill_probability == 1.0 if skill else mine[-1].skill_probability > 0.9


def test_the_websocket_tells_the_skill_at_its_start(client, memory):
    x, y = runs(1, 5)
    run = x[list(y).index("5")]
    with client.websocket_connect("/stream") as ws:
        assert ws.receive_json()["type"] == "metadata"
        for skill in (None, "5"):
            ws.send_json({"type": "start"} | ({} if skill is None else {"skill": skill}))
            assert ws.receive_json()["skill"] == skill
            answers = []
            for v in run:
                ws.send_json({"type": "step", "observation": v.tolist()})
                answers.append(StepAnswer.from_json(ws.receive_json()))
            assert [a.energy for a in answers] == [a.energy for a in in_process(memory, run, skill)]
            assert answers[-1].skill == "5"
        ws.send_json({"type": "step", "observation": run[0].tolist(), "skill": "4"})
        refused = ws.receive_json()
        assert refused["type"] == "error" and refused["status"] == 422 and "'4'" in refused["detail"]


def test_a_skill_the_model_does_not_know_is_refused_naming_it_and_the_known_ones(client):
    r = client.post("/sessions", json={"skill": "9"})
    assert r.status_code == 422 and "'9'" in r.json()["detail"] and "3, 4, 5" in r.json()["detail"]
    assert "\n" not in r.json()["detail"]
    listed = {m["name"]: m for m in client.get("/models").json()}
    assert listed["kitting"]["skills"] == list(SKILLS) and listed["kitting"]["channel_names"] == list(SKILL_CHANNELS)
    assert listed["plain"]["skills"] == []


def test_a_skill_for_a_model_trained_without_skills_is_refused(client):
    r = client.post("/sessions", json={"model": "plain", "skill": "3"})
    assert r.status_code == 422 and "without skills" in r.json()["detail"]
    assert client.post("/sessions", json={"model": "plain"}).status_code == 201


def test_a_skill_changed_mid_session_is_refused_and_the_session_goes_on(client, memory):
    x, y = runs(1, 6)
    run = x[list(y).index("4")]
    sid = client.post("/sessions", json={"skill": "4"}).json()["session_id"]
    steps = [client.post("/fault", json={"session_id": sid, "observation": v.tolist(), "skill": "4"}).json()
             for v in run[:3]]
    r = client.post("/fault", json={"session_id": sid, "observation": run[3].tolist(), "skill": "3"})
    assert r.status_code == 422 and "'3'" in r.json()["detail"] and "'4'" in r.json()["detail"]
    assert client.get(f"/sessions/{sid}").json()["steps"] == 3  # its earlier steps kept, the refused one not taken
    rest = [client.post("/fault", json={"session_id": sid, "observation": v.tolist()}).json() for v in run[3:]]
    mine = in_process(memory, run, "4")
    assert [s["energy"] for s in steps + rest] == [a.energy for a in mine]
    other = client.post("/sessions", json={}).json()["session_id"]  # not told: naming a skill later changes it too
    assert client.post("/fault", json={"session_id": other, "observation": run[0].tolist(), "skill": "4"}).status_code == 422
