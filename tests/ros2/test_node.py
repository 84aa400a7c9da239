"""``nasm ros2``'s node against a simulated Panda's driver in another process on loopback: a
normal episode gives no ERROR on /diagnostics, the same episode with joint 4 locked gives ERROR
with joint 4 isolated at the step the in-process monitor flags it, every step decided alike; the
episode is recorded; a skill named on the label topic is told; what `nasm replay --ros2` plays is
judged as the service judges it; one process watches every namespace given."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("cyclonedds")

from neural_asm.client.session import ServiceClient  # noqa: E402
from neural_asm.logs.mapping import parse_mapping  # noqa: E402
from neural_asm.memory import SkillMemory  # noqa: E402
from neural_asm.ros2 import messages as m  # noqa: E402
from neural_asm.ros2.bus import DEFAULT, Bus  # noqa: E402
from neural_asm.ros2.judge import LocalJudge, RemoteJudge, judge_together, load_judge  # noqa: E402
from neural_asm.ros2.verdict import ERROR, OK, WARN  # noqa: E402
from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_NAMES  # noqa: E402
from panda_bus import FPR, LOOPBACK, NAMESPACE, PUBLISHER, STEPS, Running, channel, mapping, statuses, values  # noqa: E402


def monitored(judge, observations: np.ndarray, out: Path, skill: str | None = None):
    """The node's answers and statuses on one episode published by the driver in another process."""
    np.save(out / "observations.npy", observations)
    child = subprocess.Popen([sys.executable, str(PUBLISHER), NAMESPACE, str(out / "observations.npy"),
                              *([skill] if skill else [])], env={**os.environ, **LOOPBACK}, text=True,
                             stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    running = Running(mapping("skill" if skill else None), judge, out / "recordings")
    try:
        node = running.node
        for reader in [*node.readers, *([node.label] if node.label else [])]:
            assert reader.wait_for_publishers(1, timeout_s=60), f"no publisher of {reader.topic}"
        child.stdin.write("go\n")
        child.stdin.flush()
        running.until(lambda s: values(s).get("step") == str(STEPS - 1))
    finally:
        running.close()
        child.kill()
        _, errors = child.communicate()
    assert len(node.answers) == STEPS, (errors, [s.message for s in running.said if s.level == WARN])
    return [a for _, a in node.answers], running.said


def in_process(memory: SkillMemory, observations: np.ndarray, skill: str | None = None):
    monitor = memory.monitor(fpr=FPR, skill=skill)
    return [monitor.step(x) for x in observations]


def decisions(answers) -> list[tuple]:
    return [(a.step, a.fault, a.isolated_joint, a.threshold) for a in answers]


@pytest.mark.slow
def test_a_normal_episode_gives_no_error_and_the_monitors_answers(memory, tmp_path):
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    observations = run_episode(SKILLS[0], 31).observations
    answers, said = monitored(LocalJudge(memory, FPR), observations, tmp_path)
    expected = in_process(memory, observations)
    assert decisions(answers) == decisions(expected)
    assert [a.energy for a in answers] == pytest.approx([a.energy for a in expected], rel=1e-9)
    assert said and all(s.level == OK for s in said)
    assert len(list((tmp_path / "recordings").rglob("*.rrd"))) == 1
    assert len(list((tmp_path / "recordings").rglob("*.mcap"))) == 1


def locked() -> np.ndarray:
    """A normal episode's seed with joint 4 locked 15 degrees past its goal at 3 s."""
    from neural_asm.sim.faults import FaultSpec
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    return run_episode(SKILLS[0], 31, FaultSpec(joint=4, time_s=3.0, overshoot_deg=15.0)).observations


@pytest.mark.slow
@pytest.mark.parametrize("where", ["in-process", "service"])
def test_joint_4_locked_gives_error_with_joint_4_isolated_where_the_monitor_flags_it(memory, tmp_path, where):
    observations = locked()
    if where == "in-process":
        answers, said = monitored(LocalJudge(memory, FPR), observations, tmp_path)
    else:
        from neural_asm.service.embedded import start_embedded
        from neural_asm.service.settings import Settings

        memory.save(tmp_path / "models" / "panda.safetensors")
        settings = Settings(models_dir=tmp_path / "models", record=False, build_default_model=False)
        with start_embedded(settings) as srv:
            judge, names = load_judge("panda", srv.url, FPR, tmp_path)
            assert isinstance(judge, RemoteJudge) and names == CHANNEL_NAMES
            answers, said = monitored(judge, observations, tmp_path)
    expected = in_process(memory, observations)
    assert decisions(answers) == decisions(expected)
    flagged = [a for a in expected if a.fault]
    assert flagged and flagged[0].isolated_joint == "joint4"
    first = next(s for s in said if s.level == ERROR)
    assert values(first)["step"] == str(flagged[0].step) and values(first)["isolated_joint"] == "joint4"


def test_robots_judged_together_answer_as_each_alone_and_one_robots_bad_step_is_its_own(memory):
    """Three robots' monitors stepped together, as a node process judges its robots' steps, answer
    as each stepped alone; a NaN in one robot's step is refused for it alone."""
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    episodes = [run_episode(SKILLS[0], 31).observations, locked(), run_episode(SKILLS[1], 32).observations]
    bad = episodes[2].copy()
    bad[4, 0] = np.nan
    judge = LocalJudge(memory, FPR)
    with contextlib.ExitStack() as stack:
        monitors = [stack.enter_context(judge.open(None)) for _ in episodes]
        together = [judge_together(list(zip(monitors, rows))) for rows in zip(episodes[0], episodes[1], bad)]
    assert all(len(step) == 3 for step in together)
    for r, observations in enumerate(episodes[:2]):
        answers = [step[r] for step in together]
        assert decisions(answers) == decisions(in_process(memory, observations))
        # to the service's tolerance: a batch's relaxation differs from one robot's in the last digits
        assert [a.energy for a in answers] == pytest.approx([a.energy for a in in_process(memory, observations)],
                                                            rel=1e-5)
    refused = together[4][2]
    assert isinstance(refused, ValueError) and "NaN or inf in channel(s) ['joint1']" in str(refused)
    assert decisions(step[2] for k, step in enumerate(together) if k < 4) == decisions(in_process(memory, bad[:4]))
    assert any(a.fault for a in (step[1] for step in together))  # the locked joint is flagged among them


@pytest.mark.slow
def test_the_skill_named_on_the_label_topic_is_told_to_the_memory(skill_memory, tmp_path):
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    skill = SKILLS[1]
    observations = run_episode(skill, 31).observations
    answers, _ = monitored(LocalJudge(skill_memory, FPR), observations, tmp_path, skill=skill)
    assert [a.skill for a in answers] == [skill] * STEPS
    assert all(a.skill_probability == 1 for a in answers)
    told = in_process(skill_memory, observations, skill=skill)
    assert [a.energy for a in answers] == pytest.approx([a.energy for a in told], rel=1e-9)


NASM = str(Path(sys.executable).with_name("nasm"))


def write_table(observations: np.ndarray, folder: Path) -> tuple[Path, Path]:
    """One episode as a lab's table (a time column and a column per channel) and its mapping."""
    folder.mkdir()
    table = folder / "locked.csv"
    rows = np.column_stack([np.arange(len(observations)) * 0.5, observations])
    np.savetxt(table, rows, delimiter=",", header=",".join(["t", *CHANNEL_NAMES]), comments="")
    doc = {"timing": {"period_s": 0.5, "steps": STEPS}, "source": {"kind": "table", "time_column": "t"},
           "channels": [{"name": n, "column": n, "units": "1", "joint": n in JOINT_NAMES} for n in CHANNEL_NAMES]}
    (folder / "table.yaml").write_text(yaml.safe_dump(doc))
    return table, folder / "table.yaml"


def first_status(said: list, level: int) -> dict[str, str] | None:
    """The values of the first status of ``level`` said about a step, or None."""
    return next((values(s) for s in said if s.level == level and "step" in values(s)), None)


@pytest.mark.slow
def test_a_table_played_by_nasm_replay_ros2_is_judged_by_nasm_ros2_as_the_service_judges_it(memory, tmp_path):
    """``nasm replay --ros2`` in one process plays a table's episode (joint 4 locked) onto the bus;
    ``nasm ros2`` in another judges it; every step's fault and energy (nasm/fault, nasm/energy)
    are those a service session gives for the episode the table reader reads, and /diagnostics
    turns ERROR, joint 4 isolated, at the step the session first flags."""
    from neural_asm.experiments.robot_logs.write import bag_mapping, write_mapping
    from neural_asm.logs.cli import read_logs
    from neural_asm.service.embedded import start_embedded
    from neural_asm.service.settings import Settings

    table, table_mapping = write_table(locked(), tmp_path / "table")
    node_mapping = write_mapping(bag_mapping(split="gap"), tmp_path / "node.yaml")
    memory.save(tmp_path / "models" / "panda.safetensors")
    env = {**os.environ, **LOOPBACK}
    listener = Bus(env=LOOPBACK)
    diagnostics = listener.reader("/diagnostics", m.DIAGNOSTIC_ARRAY, qos=DEFAULT)
    fault = listener.reader(f"{NAMESPACE}/nasm/fault", m.BOOL, qos=DEFAULT)
    energy = listener.reader(f"{NAMESPACE}/nasm/energy", m.FLOAT64, qos=DEFAULT)
    node = subprocess.Popen([NASM, "ros2", "--mapping", str(node_mapping), "--model", "panda", "--models-dir",
                             str(tmp_path / "models"), "--namespace", NAMESPACE, "--out", str(tmp_path / "recordings")],
                            env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    player = None
    said: list = []
    faults: list[bool] = []
    energies: list[float] = []
    try:
        for reader in (diagnostics, fault, energy):
            assert reader.wait_for_publishers(1, timeout_s=120), f"nasm ros2 never published {reader.topic}"
        player = subprocess.Popen([NASM, "replay", str(table), "--mapping", str(table_mapping), "--ros2",
                                   str(node_mapping), "--namespace", NAMESPACE], env=env, text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 120
        while len(energies) < STEPS and time.monotonic() < deadline and player.poll() in (None, 0):
            listener.wait(1.0)
            said += statuses(diagnostics)
            faults += [r.message.data for r in fault.take()]
            energies += [r.message.data for r in energy.take()]
        played, _ = player.communicate(timeout=60)
    finally:
        for child in (node, player):
            if child is not None and child.poll() is None:
                child.terminate()
        monitored_by, _ = node.communicate(timeout=60)
        if player is not None and player.poll() is None:
            player.kill()
    assert player.returncode == 0 and "played episode 0 (locked, 15 steps)" in played, played
    assert len(faults) == len(energies) == STEPS, (monitored_by, [s.message for s in said])
    episode = read_logs(str(table), table_mapping).data[0]
    settings = Settings(models_dir=tmp_path / "models", record=False, build_default_model=False)
    with start_embedded(settings) as srv:
        with RemoteJudge(ServiceClient(srv.url), "panda", FPR).open(None) as session:
            served = [session.step(x) for x in episode]
    assert faults == [a.fault for a in served]
    assert energies == pytest.approx([a.energy for a in served], rel=1e-5)
    flagged = [a for a in served if a.fault]
    assert flagged and flagged[0].isolated_joint == "joint4"
    error = first_status(said, ERROR)
    assert error is not None and error["step"] == str(flagged[0].step) and error["isolated_joint"] == "joint4"
    assert float(error["threshold"]) == pytest.approx(flagged[0].threshold, rel=1e-5)
    assert first_status(said, OK) is not None and all(s.level != WARN for s in said)
    assert len(list((tmp_path / "recordings").rglob("*.rrd"))) == 1


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["rosbag2", "lerobot"])
def test_a_bag_or_a_dataset_played_by_nasm_replay_ros2_is_judged_as_its_reader_reads_it(memory, tmp_path, kind):
    """``nasm replay --ros2`` plays what ``nasm replay`` reads, twice its pace; the node judges each
    step as the in-process monitor judges the episode the source's reader reads."""
    from typer.testing import CliRunner

    from neural_asm.cli import app
    from neural_asm.experiments.robot_logs.write import (bag_mapping, lerobot_mapping, write_bag, write_lerobot,
                                                         write_mapping)
    from neural_asm.logs.cli import read_logs
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    episodes = [run_episode(SKILLS[0], 31)]
    source = write_bag(episodes, tmp_path / "bag") if kind == "rosbag2" else write_lerobot(episodes, tmp_path / "set")
    read_as = write_mapping(bag_mapping(split="gap") if kind == "rosbag2" else lerobot_mapping(), tmp_path / "read.yaml")
    doc = bag_mapping(split="gap")
    node_mapping = write_mapping(doc, tmp_path / "node.yaml")
    running = Running(parse_mapping(doc, "the node's mapping"), LocalJudge(memory, FPR), None)
    try:
        result = CliRunner().invoke(app, ["replay", str(source), "--mapping", str(read_as), "--ros2", str(node_mapping),
                                          "--namespace", NAMESPACE, "--speed", "2"], env=LOOPBACK)
        running.until(lambda s: values(s).get("step") == str(STEPS - 1))
    finally:
        running.close()
    assert result.exit_code == 0, result.output
    expected = in_process(memory, read_logs(str(source), read_as).data[0])
    answers = [a for _, a in running.node.answers]
    assert decisions(answers) == decisions(expected)
    assert [a.energy for a in answers] == pytest.approx([a.energy for a in expected], rel=1e-9)


def test_nasm_replay_ros2_refuses_a_node_mapping_of_other_channels_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from neural_asm.cli import app
    from neural_asm.experiments.robot_logs.write import bag_mapping, write_mapping

    table, table_mapping = write_table(np.zeros((STEPS, len(CHANNEL_NAMES))), tmp_path / "table")
    doc = bag_mapping(split="gap")
    doc["channels"] = [c for c in doc["channels"] if c["name"] != "ee_x"]
    node_mapping = write_mapping(doc, tmp_path / "node.yaml")
    result = CliRunner().invoke(app, ["replay", str(table), "--mapping", str(table_mapping), "--ros2",
                                      str(node_mapping)], env=LOOPBACK)
    assert result.exit_code == 2
    assert "episode 0 has channels the node's mapping does not (missing [], extra ['ee_x'])" in result.output
    result = CliRunner().invoke(app, ["replay", str(table), "--mapping", str(table_mapping)])
    assert result.exit_code == 2 and "give either --url" in result.output


def test_one_nasm_ros2_process_watches_every_namespace_given(tmp_path, small_panda_model):
    SkillMemory(small_panda_model).save(tmp_path / "panda.safetensors")
    doc = {"timing": {"period_s": 0.5, "steps": STEPS, "max_gap_s": 0.3}, "source": {"kind": "rosbag", "split": "gap", "gap_s": 2.0},
           "channels": [channel(n) for n in CHANNEL_NAMES]}
    (tmp_path / "node.yaml").write_text(yaml.safe_dump(doc))
    listener = Bus(env=LOOPBACK)
    diagnostics = listener.reader("/diagnostics", m.DIAGNOSTIC_ARRAY, qos=DEFAULT)
    node = subprocess.Popen([NASM, "ros2", "--mapping", str(tmp_path / "node.yaml"), "--model",
                             str(tmp_path / "panda.safetensors"), "--namespace", "/robot1", "--namespace", "/robot2"],
                            env={**os.environ, **LOOPBACK}, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    said: set[str] = set()
    try:
        deadline = time.monotonic() + 120
        while len(said) < 2 and node.poll() is None and time.monotonic() < deadline:
            listener.wait(1.0)
            said |= {s.hardware_id for s in statuses(diagnostics) if s.message == "waiting for the mapped topics"}
    finally:
        node.terminate()
        output, _ = node.communicate(timeout=60)
    assert said == {"robot1", "robot2"}, output
    assert "under /robot1, /robot2" in output
    refused = subprocess.run([NASM, "ros2", "--mapping", str(tmp_path / "node.yaml"), "--model",
                              str(tmp_path / "panda.safetensors"), "--namespace", "/robot1", "--namespace", "/robot1"],
                             env={**os.environ, **LOOPBACK}, text=True, capture_output=True, timeout=120)
    assert refused.returncode == 2 and "--namespace: each robot once" in refused.stderr + refused.stdout
