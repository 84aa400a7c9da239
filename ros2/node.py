"""The monitor node: a mapping's topics read live from the bus, resampled to the model's clock by
the bag reader's own resampler (``logs.resample``), cut into episodes as the mapping cuts a bag
(``gap``, ``marker``; ``label_topic`` names an episode's skill), each step judged by a monitor
(``ros2.judge``: in-process, or a service session), its verdict published (``ros2.verdict``) and
the episode recorded to Rerun and MCAP as a client episode is.

A spin takes every message waiting, then judges the steps they complete; many robots' nodes in
one process share one thread (``Fleet``), so that their steps ready in a spin are judged
together, as the service judges its sessions' steps (``ros2.judge.judge_together``).

Input the mapping cannot read (a publisher of a mapped topic with another type, a message
without a mapped joint, a topic silent for longer than ``timing.max_gap_s`` inside an episode,
time stamps going back) ends the episode with a WARN status naming it; the node keeps running
and the next message opens a new episode. An episode ends, too, after the ``timing.steps``
steps the model was trained on. A mapping's topics are read under the node's namespace
(``/joint_states`` of a bag's mapping is ``/robot1/joint_states`` with ``--namespace /robot1``).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from neural_asm.logs.errors import LogError
from neural_asm.logs.fields import NS, header_stamp
from neural_asm.logs.mapping import Episodes, Mapping
from neural_asm.logs.resample import EpisodeResampler
from neural_asm.logs.rosbag import topic_groups
from neural_asm.models.answer import StepAnswer
from neural_asm.models.fault import joint_channels
from neural_asm.recordings import EpisodeRecorder, new_run_id
from neural_asm.recordings.episode import View
from neural_asm.recordings.records import StepRecord
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import MONITOR, Bus, Reader, Received
from neural_asm.ros2.extract import Extractor
from neural_asm.ros2.judge import JUDGING, Judge, Judging, Stepper, judge_together
from neural_asm.ros2.verdict import WARN, VerdictWriter

# what a mapped topic may carry, told apart by the fields its channels name (``data``: a Bool)
INPUT_TYPES = (m.JOINT_STATE, m.WRENCH_STAMPED, m.POINT_STAMPED, m.BOOL)
ANSWERS_KEPT = 1000


def topic_type(topic: str, fields: list[str]) -> str:
    """The message type a topic's channels are read from: the first of ``INPUT_TYPES`` holding
    every channel's first field (``position`` is a JointState's, ``wrench`` a WrenchStamped's)."""
    firsts = {f.split(".")[0] for f in fields}
    for msgtype in INPUT_TYPES:
        if firsts <= {name for name, _ in m.STORE.fielddefs[msgtype][1]}:
            return msgtype
    raise LogError(f"topic {topic}: no message type the node reads ({', '.join(INPUT_TYPES)}) has the fields "
                   f"{sorted(firsts)}")


@dataclass
class _Episode:
    """The episode being read: its resampler, its steps complete and judged, its monitor and recording."""

    number: int
    lo: int  # ns: its first sample's stamp, time 0 of its clock
    resampler: EpisodeResampler
    label: str | None
    last_ns: list[int | None]  # each topic's last stamp
    last_rx: float  # monotonic time of its last message
    due: int = 0  # steps complete, handed to the judge
    ended: bool = False  # its monitor and recording closed: its steps still due are not judged
    resources: contextlib.ExitStack = field(default_factory=contextlib.ExitStack)
    monitor: Stepper | None = None
    recorder: EpisodeRecorder | None = None


@dataclass(frozen=True)
class Due:
    """A step complete and waiting for its verdict (``row``), or the end of an episode (``row`` None,
    ``why``: the input that ended it, None when it just ended); ``sent_ns``: when the message that
    completed the step was sent."""

    episode: _Episode | None
    k: int = 0
    row: np.ndarray | None = None
    sent_ns: int = 0
    why: str | None = None


def _vector(values: dict[str, float] | None, names: tuple[str, ...]) -> np.ndarray | None:
    return None if values is None else np.array([values[n] for n in names], np.float64)


class MonitorNode:
    """The node on ``bus``: ``spin`` until stopped; the last ``ANSWERS_KEPT`` steps judged are also
    kept in ``answers`` (episode number, answer) for whoever runs it in-process."""

    def __init__(self, bus: Bus, mapping: Mapping, judge: Judge, out: Path | None) -> None:
        if not isinstance(mapping.source, Episodes):
            raise LogError(f"the node reads topics: the mapping's source is {mapping.kind}, not a ROS bag's topics")
        self.mapping, self.split, self.judge, self.out = mapping, mapping.source, judge, out
        self.groups = topic_groups(mapping)
        # each topic's channels' places in a step's observation and their scales
        self.layout = [(np.array(g.columns), np.array([c.scale for c in g.channels])) for g in self.groups]
        self.names = mapping.channel_names
        self.readers: list[Reader] = []
        self.extract = []
        for group in self.groups:
            topic = group.source.removeprefix("topic ")
            msgtype = topic_type(topic, [c.field or "" for c in group.channels])
            self.readers.append(bus.reader(topic.lstrip("/"), msgtype, MONITOR))
            self.extract.append(Extractor(group.channels, topic, msgtype))
        split = self.split
        self.marker = bus.reader(split.marker_topic.lstrip("/"), m.STRING, MONITOR) if split.marker_topic else None
        self.label = bus.reader(split.label_topic.lstrip("/"), m.STRING, MONITOR) if split.label_topic else None
        self.bus, self.verdict = bus, VerdictWriter(bus, bus.namespace.strip("/") or "robot")
        self.current: _Episode | None = None
        self.recent_label: tuple[int, str] | None = None
        self.number = 0
        self.seen_ns: int | None = None  # the newest stamp of a mapped topic's message taken
        self.before: list[int | None] = [None] * len(self.groups)  # ``seen_ns`` before each reader's last take
        self.due: deque[Due] = deque()  # what the judge has to do, in order
        self.answers: deque[tuple[int, StepAnswer]] = deque(maxlen=ANSWERS_KEPT)
        self.lost_said: dict[int, int] = {}  # each reader's messages lost on their way, as last said

    @property
    def all_readers(self) -> list[Reader]:
        """The mapped topics' readers, and the marker's and the skill label's."""
        return [*self.readers, *(r for r in (self.marker, self.label) if r is not None)]

    def spin(self, stop: threading.Event, poll_s: float = 0.1) -> None:
        """Read, judge and publish until ``stop`` is set; the open episode is closed at the end."""
        Fleet(self.bus, [self]).spin(stop, poll_s)

    def lost(self) -> int:
        """Messages of its topics DDS lost on their way (``Reader.lost``)."""
        return sum(reader.lost() for reader in self.all_readers)

    # ------------------------------------------------------------------ reading

    def take(self, publications: Sequence[tuple[str, str]]) -> None:
        """Take every message waiting, in one take a reader; read them in time order, across topics;
        then the silences. What they complete is left in ``due`` for the judge. ``publications``:
        the topics and types of the writers discovered since the last take (``Bus.publications``)."""
        for topic, typename in publications:
            self._check_type(topic, typename)
        for reader, kind in ((self.label, "label"), (self.marker, "marker")):
            for received in reader.take() if reader is not None else ():
                self._control(kind, received)
        waiting = []
        for g, reader in enumerate(self.readers):
            self.before[g] = self.seen_ns
            taken = [(self._stamp(r), g, r) for r in reader.take()]
            if taken:
                newest = max(t for t, _, _ in taken)
                self.seen_ns = newest if self.seen_ns is None else max(self.seen_ns, newest)
            waiting += taken
        for t, g, received in sorted(waiting, key=lambda w: w[0]):  # in time order across topics
            self._sample(g, t, received)
        self._say_lost()
        ep, gap = self.current, self.split.gap_s
        if ep is not None:
            try:
                self._check_silence(ep, None)
            except LogError as exc:
                self.close(str(exc))
        ep = self.current
        if ep is not None and self.split.split == "gap" and gap and time.monotonic() - ep.last_rx > gap:
            self.close(None)  # every topic silent for gap_s: the episode is over

    def _say_lost(self) -> None:
        """A WARN naming each topic DDS has lost messages of since it was last said (best effort
        drops them when the receiving socket overflows): the steps around them are interpolated,
        or, past ``max_gap_s``, the episode ends on the silence."""
        for reader in self.all_readers:
            lost, said = reader.lost(), self.lost_said.get(id(reader), 0)
            if lost > said:
                self.lost_said[id(reader)] = lost
                what = ("the steps around them are interpolated" if reader in self.readers
                        else "an episode's skill or start may have gone with them")
                self._warn(f"{reader.topic}: {lost - said} message(s) lost on their way ({lost} since the node "
                           f"started): {what}", self.current)

    def _check_type(self, topic: str, typename: str) -> None:
        """A publisher of a mapped topic with another type (DDS never matches it: its messages
        would just not arrive) ends the episode with a WARN naming it."""
        for reader in self.readers:
            if reader.topic == topic and typename != m.dds_typename(reader.msgtype):
                self.close(f"topic {topic} is published as {typename}, but the mapping reads it as "
                           f"{m.dds_typename(reader.msgtype)} ({reader.msgtype})")

    def _stamp(self, received: Received) -> int:
        if self.split.stamp == "header":
            return header_stamp(received.message, received.sent_ns)
        return received.sent_ns

    def _control(self, kind: str, received: Received) -> None:
        t = self._stamp(received)
        if kind == "marker":
            self.close(None)
            self._open(t)
            return
        self.recent_label = (t, str(received.message.data))
        ep, tolerance = self.current, self.split.label_tolerance_s * NS
        if ep is not None and ep.monitor is None and ep.lo - tolerance <= t <= ep.lo + tolerance:
            ep.label = self.recent_label[1]  # no step judged yet: the monitor will be told it

    def _open(self, lo: int) -> _Episode:
        label = None
        if self.recent_label is not None and self.recent_label[0] >= lo - self.split.label_tolerance_s * NS:
            label = self.recent_label[1]
        resampler = EpisodeResampler(self.groups, self.mapping.timing, f"episode {self.number}")
        self.current = _Episode(self.number, lo, resampler, label, [None] * len(self.groups), time.monotonic())
        self.number += 1
        return self.current

    def _sample(self, g: int, t: int, received: Received) -> None:
        ep = self.current
        gap = self.split.gap_s
        if ep is not None and self.split.split == "gap" and gap and t - max(n or 0 for n in ep.last_ns) > gap * NS:
            self.close(None)
            ep = None
        if ep is None:
            if self.split.split == "marker":
                return  # before the first marker
            ep = self._open(t)
        if t < ep.lo:
            return  # stamped before its window (clock jitter)
        ep.last_rx = time.monotonic()
        try:
            values = self.extract[g](received.message)
            ep.resampler.add(g, np.array([(t - ep.lo) / NS]), values=values[None])
            ep.last_ns[g] = t
            self._check_silence(ep, t)
        except LogError as exc:
            self.close(str(exc))
            return
        ready = 0 if ep.resampler.grid is None else min(s.k for s in ep.resampler.streams)
        while ep.due < ready:
            self.due.append(Due(ep, ep.due, self._row(ep, ep.due), received.sent_ns))
            ep.due += 1
        if ep.due >= self.mapping.timing.steps:
            self.close(None)

    def _check_silence(self, ep: _Episode, now: int | None) -> None:
        """A topic that has said nothing for longer than ``max_gap_s`` by ``now`` (None: by the
        newest stamp seen), while another spoke. Only messages another topic sent before the
        topic's reader was last taken count against it: those after may be newer than all it
        has sent yet, even if the node is behind (its backlog is not silence)."""
        limit = self.mapping.timing.gap_limit_s
        for group, last, before in zip(self.groups, ep.last_ns, self.before):
            if last is None or before is None:
                continue
            latest = before if now is None else min(now, before)
            if latest - last > limit * NS:
                raise LogError(f"{ep.resampler.what}, {group.source}: silent for {(latest - last) / NS:.3f} s "
                               f"(timing.max_gap_s is {limit:g} s)")

    def _row(self, ep: _Episode, k: int) -> np.ndarray:
        """Step ``k``'s observation in channel order and units, as ``EpisodeResampler.finish`` lays it out."""
        row = np.empty(len(self.names))
        for s, (columns, scales) in zip(ep.resampler.streams, self.layout):
            row[columns] = s.out[k] * scales
        return row

    def close(self, why: str | None) -> None:
        """End the open episode after its steps due; ``why``: the input that ended it, said then as
        a WARN status."""
        ep, self.current = self.current, None
        if ep is not None or why is not None:
            self.due.append(Due(ep, why=why))

    # ------------------------------------------------------------------ judging

    def next_due(self) -> Due | None:
        """The first step due of an episode still judged, its monitor opened (the episodes ended
        before it are closed on the way); None when none is left."""
        while self.due:
            due = self.due[0]
            ep = due.episode
            if due.row is None:
                self.due.popleft()
                self._end(ep, due.why)
            elif ep is None or ep.ended:
                self.due.popleft()
            elif ep.monitor is None:
                if self._awaits_label(ep):
                    return None
                try:
                    self._start(ep)
                except JUDGING as exc:
                    self._end(ep, f"{ep.resampler.what}: the monitor cannot judge it: {exc}")
            else:
                return due
        return None

    def _awaits_label(self, ep: _Episode) -> bool:
        """Whether the episode's first step waits for its skill: the mapping names a label topic,
        none has named the episode yet, and, while it is open, neither have its topics run
        ``label_tolerance_s`` past its first sample nor been silent that long. DDS delivers each
        topic on its own, so the label a robot publishes just before it moves may be taken after
        the first samples."""
        if self.label is None or ep.label is not None or self.current is not ep:
            return False
        tolerance = self.split.label_tolerance_s
        return (self.seen_ns is None or self.seen_ns < ep.lo + tolerance * NS) and \
            time.monotonic() - ep.last_rx <= tolerance

    def deliver(self, due: Due, answer: StepAnswer | Judging) -> None:
        """A step's answer published (and recorded), or what its monitor raised: the episode ended."""
        self.due.popleft()
        ep = due.episode
        assert ep is not None and due.row is not None
        if not isinstance(answer, StepAnswer):
            self._end(ep, f"{ep.resampler.what}: the monitor cannot judge it: {answer}")
            return
        self.answers.append((ep.number, answer))
        self.verdict.step(answer, ep.number)
        if ep.recorder is not None:
            self._record(ep.recorder, due.k, due.row, answer)

    def _start(self, ep: _Episode) -> None:
        """The episode's monitor, told its skill, and its recording."""
        ep.monitor = ep.resources.enter_context(self.judge.open(ep.label))
        if self.out is not None:
            period = self.mapping.timing.period_s
            metadata = {"source": "ros2", "skill": ep.label, "episode": ep.number, "namespace": self.bus.namespace}
            ep.recorder = ep.resources.enter_context(EpisodeRecorder(
                new_run_id("ros2"), self.names, folder=self.out, metadata=metadata,
                view=View(period, tuple(joint_channels(self.names)))))

    def _record(self, rec: EpisodeRecorder, k: int, row: np.ndarray, answer: StepAnswer) -> None:
        rec.log_step(StepRecord(
            step=k, observation=row, expected=_vector(answer.expected, self.names),
            prediction=_vector(answer.prediction, self.names), errors=_vector(answer.errors, self.names),
            energy=answer.energy, threshold=answer.threshold, fault=answer.fault,
            isolated_joint=answer.isolated_joint, time_s=k * self.mapping.timing.period_s))

    def _end(self, ep: _Episode | None, why: str | None) -> None:
        """Close an episode's monitor and recording; ``why`` said as a WARN status."""
        if ep is not None:
            if ep.ended:
                return
            ep.ended = True
            if self.current is ep:
                self.current = None
            try:
                ep.resources.close()
            except JUDGING as exc:  # a service session that cannot be ended
                why = why or f"{ep.resampler.what}: its session did not end: {exc}"
        if why is not None:
            self._warn(why, ep)

    def _warn(self, why: str, ep: _Episode | None) -> None:
        self.verdict.say(WARN, why, {"episode": str(ep.number) if ep is not None else ""})


def judge_due(nodes: Sequence[MonitorNode]) -> None:
    """Judge every step the nodes have due, in rounds: a round takes each node's first (its next
    waits for it) and judges them together (``judge_together``)."""
    while True:
        heads = [(node, due) for node in nodes if (due := node.next_due()) is not None]
        if not heads:
            return
        steps = []
        for _, due in heads:
            assert due.episode is not None and due.episode.monitor is not None and due.row is not None
            steps.append((due.episode.monitor, due.row))
        for (node, due), answer in zip(heads, judge_together(steps)):
            node.deliver(due, answer)


class Fleet:
    """The nodes of many robots, each on its namespace of ``bus`` (``Bus.under``), spun by one
    thread: a spin takes every node's messages, then judges all their steps due together."""

    def __init__(self, bus: Bus, nodes: Sequence[MonitorNode]) -> None:
        self.bus, self.nodes = bus, list(nodes)
        self.wait: Callable[[float], bool] = bus.wait_for(r for node in nodes for r in node.all_readers)

    def spin(self, stop: threading.Event, poll_s: float = 0.1) -> None:
        """Read, judge and publish until ``stop`` is set; the open episodes are closed at the end."""
        try:
            while not stop.is_set():
                self.spin_once(poll_s)
        finally:
            for node in self.nodes:
                node.close("the node stopped in the episode" if node.current is not None else None)
            judge_due(self.nodes)

    def spin_once(self, timeout_s: float) -> None:
        """Handle every message waiting (within ``timeout_s``), judge the steps they complete, then
        each node's heartbeat."""
        self.wait(timeout_s)
        publications = self.bus.publications()  # of the participant the nodes share
        for node in self.nodes:
            node.take(publications)
        judge_due(self.nodes)
        for node in self.nodes:
            node.verdict.heartbeat()
