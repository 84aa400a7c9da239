"""The client tells a skill memory the skill, or leaves it to infer it, against a real uvicorn
server on loopback: ``ServiceClient.session(skill=)``, ``nasm replay --tell-skill`` and
``nasm client --tell-skill`` (refused, in one line, by a model trained without skills)."""

from __future__ import annotations


import numpy as np
import pytest
from typer.testing import CliRunner

from kitting_fixtures import SKILL_CHANNELS as NAMES, served_models, skill_runs as runs, told_memory
from neural_asm import SkillMemory
from neural_asm.client.session import ServiceClient
from neural_asm.client.cli import app as client_cli
from neural_asm.client.replay import replay_logs
from neural_asm.client.stream import Connection, StreamOptions
from neural_asm.models.sequences import EpisodeFacts, Sequences
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings

memory = pytest.fixture(scope="module")(told_memory)


@pytest.fixture(scope="module")
def server(memory: SkillMemory, tmp_path_factory: pytest.TempPathFactory):
    """The skill memory (``kitting``) beside a network trained without skills, the default."""
    folder = served_models(tmp_path_factory.mktemp("models"), memory)
    settings = Settings(models_dir=folder, record=False, build_default_model=False, default_model="plain")
    with start_embedded(settings) as srv:
        yield srv


def monitored(memory: SkillMemory, run: np.ndarray, skill: str | None) -> list[float]:
    monitor = memory.monitor(skill=skill)
    return [monitor.step(v).energy for v in run]


def test_a_service_session_told_or_not_answers_as_the_monitor(server, memory):
    x, y = runs(1, 4)
    for skill in (None, "3"):
        with ServiceClient(server.url).session(model="kitting", skill=skill) as session:
            assert session.info["skill"] == skill
            answers = [session.step(v) for v in x[1]]  # skill 4's course
        assert [a.energy for a in answers] == monitored(memory, x[1], skill)
        assert answers[-1].skill == (skill or "4") and (skill is None) != any(a.fault for a in answers)


def test_replay_tells_each_episode_its_label_or_leaves_it_to_infer(server, memory, tmp_path):
    x, y = runs(1, 5)
    facts = tuple(EpisodeFacts(i, f"run {i}", x.shape[1], 0.0) for i in range(len(x)))
    seqs = Sequences(x, y, NAMES, episodes=facts)
    for tell in (False, True):
        summaries = replay_logs(seqs, [], Connection(server.url), StreamOptions("online", tmp_path, quiet=True),
                                "kitting", tell)
        assert [s.energies for s in summaries] == [monitored(memory, run, skill if tell else None)
                                                   for run, skill in zip(x, y)]


@pytest.mark.slow  # simulates a Panda episode
def test_the_client_telling_a_model_trained_without_skills_fails_in_one_line(server, tmp_path):
    result = CliRunner().invoke(client_cli, ["--url", server.url, "--out", str(tmp_path), "--episodes", "1",
                                             "--tell-skill"])
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()  # what the episode was, then why it was refused
    assert [line for line in lines if line.startswith("error")] == lines[-1:] and "Traceback" not in result.output
    assert "422" in lines[-1] and "without skills" in lines[-1]
