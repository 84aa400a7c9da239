"""``nasm ros2``'s node on input the mapping cannot read, or that comes late or not at all: each is a
WARN naming it and the node goes on; a label taken after the first samples is still told, DDS's
lost messages are said, a backlog is not silence (scripted readers hand over what DDS would have)."""

from __future__ import annotations

import pytest

pytest.importorskip("cyclonedds")

from neural_asm.memory import SkillMemory  # noqa: E402
from neural_asm.ros2 import messages as m  # noqa: E402
from neural_asm.ros2.bus import Bus, Received  # noqa: E402
from neural_asm.ros2.judge import LocalJudge  # noqa: E402
from neural_asm.ros2.node import Fleet, MonitorNode  # noqa: E402
from neural_asm.ros2.verdict import OK, WARN  # noqa: E402
from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_NAMES  # noqa: E402
from panda_bus import (FPR, LOOPBACK, NAMESPACE, STATE, Running, joint_state, mapping, wrench,  # noqa: E402
                       writers)


class Judged:
    """A judge that answers nothing: the bad input never reaches it."""

    def open(self, skill):
        raise AssertionError("no step of bad input is judged")


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
    """A node that keeps what it warned of, and the skill each episode's monitor was told."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.warned: list[str] = []
        self.told: list[str | None] = []

    def _start(self, ep) -> None:
        self.told.append(ep.label)
        super()._start(ep)

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
    node.fleet = fleet = Fleet(node.bus, [node])  # to spin it again
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
        assert node.warned == [] and node.told == [told]
        assert [a.step for _, a in node.answers] == [0, 1]  # at 1.0 and 1.5 s
        if told:
            assert all(a.skill == skill and a.skill_probability == 1 for _, a in node.answers)


def test_an_episode_whose_topics_fall_silent_waits_no_longer_for_its_label(skill_memory):
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    node = fed(skill_memory, {"skill": [[]], **{t: [ticks(1.0, 1.2, make)] for t, make in (
        ("joint_states", state), ("left_pad/wrench", wrench), ("right_pad/wrench", wrench))}})
    assert node.told == [] and node.current is not None  # step 0 complete, waiting
    node.current.last_rx -= 0.6  # its topics silent for longer than label_tolerance_s (0.5 s) since
    node.fleet.spin_once(0)
    assert node.told == [None] and [a.step for _, a in node.answers] == [0]


def test_a_label_for_the_next_episode_is_not_told_to_the_one_before(skill_memory):
    """An unlabelled episode (1.0-1.2 s) still waiting for its label is not told the next one's,
    stamped at 5.0 s and taken before the sample that ends it on the gap (gap_s 2 s)."""
    state = lambda sec, ns: joint_state(STATE, sec, ns)  # noqa: E731
    skill = skill_memory.skills[1]
    node = fed(skill_memory, {"skill": [[], [(5.0, m.STORE.types[m.STRING](data=skill))]],
                              **{t: [ticks(1.0, 1.2, make), ticks(5.0, 6.0, make)]
                                 for t, make in (("joint_states", state), ("left_pad/wrench", wrench),
                                                 ("right_pad/wrench", wrench))}})
    assert node.warned == [] and node.told == [None, skill]
    assert [(e, a.step) for e, a in node.answers] == [(0, 0), (1, 0), (1, 1)]


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


def test_the_node_says_it_is_waiting_before_any_message():
    running = Running(mapping(), Judged(), None)
    try:
        running.until(lambda s: True)
    finally:
        running.close()
    assert running.said[0].level == OK and running.said[0].message == "waiting for the mapped topics"
    assert running.said[0].hardware_id == "robot1"


