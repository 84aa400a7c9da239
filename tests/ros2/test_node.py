"""``nasm ros2``'s node against a simulated Panda's driver in another process on loopback: a
normal episode gives no ERROR on /diagnostics, the same episode with joint 4 locked gives ERROR
with joint 4 isolated at the step the in-process monitor flags it, every step decided alike; the
episode is recorded; input the mapping cannot read is a WARN naming it, and the node goes on."""

from __future__ import annotations

import contextlib
import os
import random
import subprocess
import sys
import threading
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
from neural_asm.ros2.bus import DEFAULT, Bus, Received  # noqa: E402
from neural_asm.ros2.judge import LocalJudge, RemoteJudge, judge_together, load_judge  # noqa: E402
from neural_asm.ros2.node import Fleet, MonitorNode  # noqa: E402
from neural_asm.ros2.verdict import ERROR, OK, WARN  # noqa: E402
from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_NAMES  # noqa: E402

PUBLISHER = Path(__file__).with_name("panda_publisher.py")
DOMAIN = str(100 + random.randrange(100))
LOOPBACK = {"ROS_DOMAIN_ID": DOMAIN, "ROS_LOCALHOST_ONLY": "1"}
NAMESPACE = "/robot1"
FPR = 0.01
STEPS = 15


def channel(name: str) -> dict:
    if name.startswith(("left_", "right_")):
        side, axis = name.split("_")
        kind = {"f": "force", "t": "torque"}[axis[0]]
        return {"name": name, "topic": f"/{side}_pad/wrench", "field": f"wrench.{kind}.{axis[1]}", "units": "1"}
    return {"name": name, "topic": "/joint_states", "field": "position", "key": name, "units": "rad",
            "joint": name in JOINT_NAMES}


def mapping(label_topic: str | None = None):
    source = {"kind": "rosbag", "split": "gap", "gap_s": 2.0, "stamp": "header",
              **({"label_topic": label_topic} if label_topic else {})}
    return parse_mapping({"timing": {"period_s": 0.5, "steps": STEPS, "max_gap_s": 0.3}, "source": source,
                          "channels": [channel(n) for n in CHANNEL_NAMES]}, "the test's mapping")


@pytest.fixture(scope="module")
def memory(small_panda_model) -> SkillMemory:
    return SkillMemory(small_panda_model)


def statuses(reader) -> list:
    return [s for r in reader.take() for s in r.message.status]


def values(status) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


class Running:
    """A node spinning in a thread on the loopback domain, and a listener of /diagnostics."""

    def __init__(self, found, judge, out: Path | None) -> None:
        self.listener = Bus(env=LOOPBACK)
        self.diagnostics = self.listener.reader("/diagnostics", m.DIAGNOSTIC_ARRAY, qos=DEFAULT)
        self.node = MonitorNode(Bus(NAMESPACE, env=LOOPBACK), found, judge, out)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.node.spin, args=(self.stop,))
        self.thread.start()
        self.said: list = []

    def until(self, done, timeout_s: float = 60) -> None:
        """Collect the statuses until one makes ``done`` true (or ``timeout_s``)."""
        deadline = time.monotonic() + timeout_s
        while not any(done(s) for s in self.said) and time.monotonic() < deadline:
            self.listener.wait(deadline - time.monotonic())
            self.said += statuses(self.diagnostics)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()


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


@pytest.fixture(scope="module")
def skill_memory() -> SkillMemory:
    """A memory with a skill cue, trained on both simulated skills: it can be told one."""
    from neural_asm.models.config import FAST
    from neural_asm.sim.paper import run_episode
    from neural_asm.sim.skills import SKILLS

    def episodes(seeds: range) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack([run_episode(s, seed).observations for s in SKILLS for seed in seeds])
        return x, np.repeat(list(SKILLS), len(seeds))

    memory = SkillMemory.fit(*episodes(range(4))[:1], CHANNEL_NAMES, episodes(range(4))[1],
                             preset=FAST.with_(hidden_size=32, epochs=40), progress=False, skill_cue=True)
    x, y = episodes(range(10, 14))
    memory.calibrate(x, skills=list(y), progress=False)
    return memory


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


class Judged:
    """A judge that answers nothing: the bad input never reaches it."""

    def open(self, skill):
        raise AssertionError("no step of bad input is judged")


def joint_state(names: list[str], sec: int, nanosec: int):
    T = m.STORE.types
    header = T[m.HEADER](stamp=T[m.TIME](sec=sec, nanosec=nanosec), frame_id="")
    return T[m.JOINT_STATE](header=header, name=names, position=np.zeros(len(names)), velocity=np.zeros(0),
                            effort=np.zeros(0))


def wrench(sec: int, nanosec: int):
    T = m.STORE.types
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T[m.WRENCH_STAMPED](header=T[m.HEADER](stamp=T[m.TIME](sec=sec, nanosec=nanosec), frame_id=""),
                              wrench=T["geometry_msgs/msg/Wrench"](force=zero, torque=zero))


def writers(running: Running) -> dict:
    bus = Bus(NAMESPACE, env=LOOPBACK)
    found = {t: bus.writer(t, k) for t, k in (("joint_states", m.JOINT_STATE), ("left_pad/wrench", m.WRENCH_STAMPED),
                                               ("right_pad/wrench", m.WRENCH_STAMPED))}
    assert all(w.wait_for_subscribers(1, timeout_s=30) for w in found.values())
    assert all(r.wait_for_publishers(1, timeout_s=30) for r in running.node.readers)
    return found


STATE = [n for n in CHANNEL_NAMES if not n.startswith(("left_", "right_"))]


def test_a_message_missing_a_mapped_joint_is_a_warn_naming_it_and_the_node_goes_on():
    running = Running(mapping(), Judged(), None)
    try:
        out = writers(running)
        out["joint_states"].write(joint_state([n for n in STATE if n != "joint4"], 1, 0))
        running.until(lambda s: s.level == WARN)
        out["joint_states"].write(joint_state([n for n in STATE if n != "joint6"], 2, 0))
        running.until(lambda s: s.level == WARN and "named 'joint6'" in s.message)
        assert running.thread.is_alive()
    finally:
        running.close()
    warned = [s.message for s in running.said if s.level == WARN]
    assert "no element named 'joint4'" in warned[0] and "/joint_states" in warned[0]
    assert "no element named 'joint6'" in warned[-1]


def test_a_topic_silent_longer_than_max_gap_s_inside_an_episode_is_a_warn_naming_it():
    running = Running(mapping(), Judged(), None)
    try:
        out = writers(running)
        out["right_pad/wrench"].write(wrench(1, 0))
        for nanosec in (0, 100_000_000, 200_000_000, 350_000_000):
            out["joint_states"].write(joint_state(STATE, 1, nanosec))
            out["left_pad/wrench"].write(wrench(1, nanosec))
        running.until(lambda s: s.level == WARN)
        assert running.thread.is_alive()
    finally:
        running.close()
    (warned,) = [s.message for s in running.said if s.level == WARN]
    assert "/right_pad/wrench" in warned and "silent for 0.350 s" in warned and "max_gap_s is 0.3 s" in warned


class Scripted:
    """A reader whose takes hand over the given batches of (stamp s, message), one a take, as DDS
    would have received them by then; ``lost``: the messages DDS had lost by each take."""

    def __init__(self, reader, batches: list[list[tuple[float, object]]], lost: list[int] | None = None) -> None:
        self.topic, self.msgtype, self.batches, self.losses, self.taken = reader.topic, reader.msgtype, batches, lost, 0

    def take(self) -> list[Received]:
        self.taken += 1
        return [Received(message, round(t * 1e9)) for t, message in (self.batches.pop(0) if self.batches else [])]

    def lost(self) -> int:
        return 0 if not self.losses else self.losses[min(self.taken, len(self.losses)) - 1]


class Noted(MonitorNode):
    """A node that keeps what it warned of."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.warned: list[str] = []

    def _warn(self, why, ep) -> None:
        self.warned.append(why)
        super()._warn(why, ep)


def ticks(lo: float, hi: float, make) -> list[tuple[float, object]]:
    """A topic's messages every 0.1 s from ``lo`` to ``hi`` s, stamped so."""
    return [(t / 10, make(int(t // 10), (t % 10) * 100_000_000)) for t in range(round(lo * 10), round(hi * 10) + 1)]


def fed(memory, batches: dict[str, list], lost: dict[str, list[int]] | None = None) -> Noted:
    """A node whose readers of /joint_states, /left_pad/wrench and /right_pad/wrench (taken in that
    order, after the label's on /skill when ``batches`` has one) hand over ``batches``, spun until
    they are all taken; ``lost``: a topic's messages DDS had lost by each take."""
    node = Noted(Bus(NAMESPACE, env=LOOPBACK), mapping("skill" if "skill" in batches else None),
                 LocalJudge(memory, FPR), None)
    fleet = Fleet(node.bus, [node])
    name = lambda r: r.topic.removeprefix(NAMESPACE + "/")  # noqa: E731
    node.readers = [Scripted(r, batches[name(r)], (lost or {}).get(name(r))) for r in node.readers]
    if node.label is not None:
        node.label = Scripted(node.label, batches["skill"])
    for _ in range(max(len(b) for b in batches.values()) + 1):
        fleet.spin_once(0)
    return node


def test_a_backlog_is_not_silence(memory):
    """The node, far behind, takes /joint_states' one message, then the wrenches' that came in
    meanwhile, 1 s newer: /joint_states' backlog, taken next, was not silent."""
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    node = fed(memory, {"joint_states": [ticks(1.0, 1.0, state), ticks(1.1, 2.0, state)],
                        "left_pad/wrench": [ticks(1.0, 2.0, wrench), ticks(2.1, 2.1, wrench)],
                        "right_pad/wrench": [ticks(1.0, 2.0, wrench), ticks(2.1, 2.1, wrench)]})
    assert node.warned == [] and node.current is not None and node.number == 1  # episode 0 goes on
    assert [(e, a.step) for e, a in node.answers] == [(0, 0), (0, 1)]  # steps at 1.0 and 1.5 s


def test_messages_dds_lost_are_a_warn_naming_their_topic_and_the_episode_goes_on(memory):
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    node = fed(memory, {"joint_states": [ticks(1.0, 1.5, state), ticks(1.6, 2.1, state)],
                        "left_pad/wrench": [ticks(1.0, 1.5, wrench), ticks(1.6, 2.1, wrench)],
                        "right_pad/wrench": [ticks(1.0, 1.5, wrench), ticks(1.6, 2.1, wrench)]},
               lost={"left_pad/wrench": [0, 2, 2]})
    assert node.warned == [f"{NAMESPACE}/left_pad/wrench: 2 message(s) lost on their way (2 since the node started): "
                           "the steps around them are interpolated"]
    assert node.current is not None and [a.step for _, a in node.answers] == [0, 1, 2]


def test_a_silence_inside_what_is_taken_at_once_is_a_warn_naming_it(memory):
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    node = fed(memory, {"joint_states": [ticks(1.0, 2.0, state)], "left_pad/wrench": [ticks(1.0, 2.0, wrench)],
                        "right_pad/wrench": [ticks(1.0, 1.0, wrench) + ticks(1.5, 2.0, wrench)]})
    assert len(node.warned) == 1
    assert "/right_pad/wrench" in node.warned[0] and "silent for 0.400 s" in node.warned[0]


def test_the_first_step_waits_for_a_label_taken_after_it_up_to_the_tolerance(skill_memory):
    """DDS delivers each topic on its own: a label taken after the episode's first samples (0.2 s
    of them) is told, one taken after its topics ran past label_tolerance_s (0.5 s) is not."""
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    skill = skill_memory.skills[1]
    label = [(1.0, m.STORE.types[m.STRING](data=skill))]
    for first, told in ((1.2, skill), (1.6, None)):
        node = fed(skill_memory, {"skill": [[], label],
                                  **{t: [ticks(1.0, first, make), ticks(first + 0.1, 2.0, make)]
                                     for t, make in (("joint_states", state), ("left_pad/wrench", wrench),
                                                     ("right_pad/wrench", wrench))}})
        assert node.warned == [] and node.current.label == told
        assert [a.step for _, a in node.answers] == [0, 1]  # at 1.0 and 1.5 s
        if told:
            assert all(a.skill == skill and a.skill_probability == 1 for _, a in node.answers)


def test_the_command_refuses_a_mapping_of_another_source_in_one_line(tmp_path, small_panda_model):
    from typer.testing import CliRunner

    from neural_asm.cli import app

    SkillMemory(small_panda_model).save(tmp_path / "panda.safetensors")
    table = tmp_path / "table.toml"
    table.write_text('[timing]\nperiod_s = 0.5\nsteps = 15\n[source]\nkind = "table"\ntime_column = "t"\n'
                     + "".join(f'[[channels]]\nname = "{n}"\ncolumn = "{n}"\nunits = "1"\njoint = {str(n in JOINT_NAMES).lower()}\n'
                             for n in CHANNEL_NAMES))
    result = CliRunner().invoke(app, ["ros2", "--mapping", str(table), "--model", str(tmp_path / "panda.safetensors")],
                                env=LOOPBACK)
    assert result.exit_code == 2
    assert "the node reads topics: the mapping's source is table" in result.output
    result = CliRunner().invoke(app, ["ros2", "--mapping", str(table), "--model", "no-such-model",
                                      "--models-dir", str(tmp_path)], env=LOOPBACK)
    assert result.exit_code == 2 and "no-such-model" in result.output


def test_a_topic_published_with_another_type_is_a_warn_naming_it():
    running = Running(mapping(), Judged(), None)
    try:
        wrong = Bus(NAMESPACE, env=LOOPBACK).writer("left_pad/wrench", m.STRING)
        running.until(lambda s: s.level == WARN)
        assert running.thread.is_alive() and wrong.subscribers() == 0  # DDS alone would say nothing
    finally:
        running.close()
    (warned,) = [s.message for s in running.said if s.level == WARN]
    assert warned == ("topic /robot1/left_pad/wrench is published as std_msgs::msg::dds_::String_, but the mapping "
                      "reads it as geometry_msgs::msg::dds_::WrenchStamped_ (geometry_msgs/msg/WrenchStamped)")


class Refusing:
    """A judge refusing the episode's skill, as a skill memory refuses one it does not know."""

    def open(self, skill):
        raise ValueError(f"no skill {skill!r} in this memory")


def test_a_monitor_refusing_the_episode_is_a_warn_and_the_node_goes_on():
    running = Running(mapping(), Refusing(), None)
    try:
        out = writers(running)
        for nanosec in (0, 100_000_000):
            for topic, message in (("joint_states", joint_state(STATE, 1, nanosec)),
                                   ("left_pad/wrench", wrench(1, nanosec)), ("right_pad/wrench", wrench(1, nanosec))):
                out[topic].write(message)
        running.until(lambda s: s.level == WARN)
        assert running.thread.is_alive()
    finally:
        running.close()
    (warned,) = [s.message for s in running.said if s.level == WARN]
    assert warned == "episode 0: the monitor cannot judge it: no skill None in this memory"


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


def test_the_node_says_it_is_waiting_before_any_message():
    running = Running(mapping(), Judged(), None)
    try:
        running.until(lambda s: True)
    finally:
        running.close()
    assert running.said[0].level == OK and running.said[0].message == "waiting for the mapped topics"
    assert running.said[0].hardware_id == "robot1"


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
