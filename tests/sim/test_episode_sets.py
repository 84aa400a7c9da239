"""The paper task's episode sets in a data folder: what is there is checked before anything is
simulated, so that a folder of another rate or another normal-set size is refused, naming it."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from neural_asm.cli import app
from neural_asm.pipelines.episodes import SetMismatch, paper_sets
from neural_asm.sim.dataset import write_mcap
from neural_asm.sim.paper import run_episode
from neural_asm.sim.skills import SKILLS

pytestmark = pytest.mark.slow  # simulates episodes


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A data folder whose normal set holds three 2 Hz episodes."""
    path = tmp_path_factory.mktemp("data")
    write_mcap([run_episode(SKILLS[i % 2], 90_000 + i) for i in range(3)], path / "normal.mcap")
    return path


def test_a_normal_set_is_used_as_it_is_unless_a_size_is_asked(folder):
    assert len(paper_sets(folder, ("normal",))["normal"]) == 3
    assert len(paper_sets(folder, ("normal",), n_normal=3)["normal"]) == 3
    with pytest.raises(SetMismatch, match=r"holds 3 held-out normal episodes, not the 400 asked for"):
        paper_sets(folder, ("normal",), n_normal=400)


def test_a_set_at_another_rate_is_refused(folder):
    with pytest.raises(SetMismatch, match="at 2 Hz, not 40 Hz"):
        paper_sets(folder, ("normal",), rate=40)


def test_faults_stops_before_simulating_and_names_the_mismatch(folder, tmp_path):
    """Before the minutes of simulation the missing sets would take: nothing new in the folder."""
    before = sorted(p.name for p in folder.iterdir())
    result = CliRunner().invoke(app, ["faults", "--data", str(folder), "--out", str(tmp_path), "--n-normal", "400"])
    assert result.exit_code == 2, result.output
    assert "holds 3 held-out normal episodes, not the 400 asked for" in " ".join(result.output.split())
    assert sorted(p.name for p in folder.iterdir()) == before
