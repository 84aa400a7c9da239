"""The monitor node: a mapping's topics read live from the bus, resampled to the model's clock by
the bag reader's own resampler (``logs.resample``), cut into episodes as the mapping cuts a bag
(``gap``, ``marker``; ``label_topic`` names an episode's skill), each step judged by a monitor
(in-process, or a service session), its verdict published (``ros2.verdict``) and the episode
recorded to Rerun and MCAP as a client episode is.

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
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from neural_asm.client.replay import served_model
from neural_asm.client.session import ServiceClient
from neural_asm.client.transport import ServiceError, ServiceLost
from neural_asm.logs.errors import LogError
from neural_asm.logs.fields import NS, extractor, header_stamp
from neural_asm.logs.mapping import Episodes, Mapping
from neural_asm.logs.resample import EpisodeResampler
from neural_asm.logs.rosbag import topic_groups
from neural_asm.memory import SkillMemory
from neural_asm.models.answer import StepAnswer
from neural_asm.models.fault import joint_channels
from neural_asm.recordings import EpisodeRecorder, new_run_id
from neural_asm.recordings.episode import View
from neural_asm.recordings.records import StepRecord
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import MONITOR, Bus, Reader, Received
from neural_asm.ros2.verdict import WARN, VerdictWriter

# what a mapped topic may carry, told apart by the fields its channels name (``data``: a Bool)
INPUT_TYPES = (m.JOINT_STATE, m.WRENCH_STAMPED, m.POINT_STAMPED, m.BOOL)
Step = Callable[[np.ndarray], StepAnswer]
# what a monitor raises at an input it cannot judge (a skill it does not know, values not finite)
# and a service session when it refuses or goes away: the episode ends, the node goes on
JUDGING = (ValueError, FloatingPointError, ServiceError, ServiceLost)
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


class Judge(Protocol):
    """Opens one episode's monitor, told its skill (None: not told)."""

    def open(self, skill: str | None) -> contextlib.AbstractContextManager[Step]: ...


@dataclass(frozen=True)
class LocalJudge:
    """The in-process ``Monitor`` of a skill memory (told the skill if it has a skill cue)."""

    memory: SkillMemory
    fpr: float

    @contextlib.contextmanager
    def open(self, skill: str | None) -> Iterator[Step]:
        told = skill if self.memory.told is not None else None
        yield self.memory.monitor(fpr=self.fpr, skill=told).step


@dataclass(frozen=True)
class RemoteJudge:
    """A session of a running service's ``model`` (None: its default) per episode."""

    client: ServiceClient
    model: str | None
    fpr: float

    @contextlib.contextmanager
    def open(self, skill: str | None) -> Iterator[Step]:
        with self.client.session(model=self.model, fpr=self.fpr, skill=skill) as session:
            yield session.step


@dataclass
class _Episode:
    """The episode being read: its resampler, the steps judged so far, its monitor and recording."""

    number: int
    lo: int  # ns: its first sample's stamp, time 0 of its clock
    resampler: EpisodeResampler
    label: str | None
    last_ns: list[int | None]  # each topic's last stamp
    last_rx: float  # monotonic time of its last message
    judged: int = 0
    resources: contextlib.ExitStack = field(default_factory=contextlib.ExitStack)
    step: Step | None = None
    recorder: EpisodeRecorder | None = None


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
        self.names = mapping.channel_names
        self.readers: list[Reader] = []
        self.extract = []
        for group in self.groups:
            topic = group.source.removeprefix("topic ")
            msgtype = topic_type(topic, [c.field or "" for c in group.channels])
            self.readers.append(bus.reader(topic.lstrip("/"), msgtype, MONITOR))
            self.extract.append(extractor(list(group.channels), topic, msgtype))
        split = self.split
        self.marker = bus.reader(split.marker_topic.lstrip("/"), m.STRING, MONITOR) if split.marker_topic else None
        self.label = bus.reader(split.label_topic.lstrip("/"), m.STRING, MONITOR) if split.label_topic else None
        self.bus, self.verdict = bus, VerdictWriter(bus, bus.namespace.strip("/") or "robot")
        self.current: _Episode | None = None
        self.recent_label: tuple[int, str] | None = None
        self.number = 0
        self.answers: deque[tuple[int, StepAnswer]] = deque(maxlen=ANSWERS_KEPT)

    def spin(self, stop: threading.Event, poll_s: float = 0.1) -> None:
        """Read, judge and publish until ``stop`` is set; the open episode is closed at the end."""
        try:
            while not stop.is_set():
                self.spin_once(poll_s)
        finally:
            self.close("the node stopped in the episode" if self.current is not None else None)

    def spin_once(self, timeout_s: float) -> None:
        """Handle every message waiting (within ``timeout_s``), then the silences and the heartbeat."""
        self.bus.wait(timeout_s)
        for topic, typename in self.bus.publications():
            self._check_type(topic, typename)
        for reader, kind in ((self.label, "label"), (self.marker, "marker")):
            for received in reader.take() if reader is not None else ():
                self._control(kind, received)
        waiting = [(self._stamp(r), g, r) for g, reader in enumerate(self.readers) for r in reader.take()]
        for t, g, received in sorted(waiting, key=lambda w: w[0]):  # in time order across topics
            self._sample(g, t, received)
        ep, gap = self.current, self.split.gap_s
        if ep is not None and self.split.split == "gap" and gap and time.monotonic() - ep.last_rx > gap:
            self.close(None)  # every topic silent for gap_s: the episode is over
        self.verdict.heartbeat()

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
        if self.current is not None and self.current.step is None:
            self.current.label = self.recent_label[1]  # not yet judged: the monitor will be told it

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
            self._check_silence(ep)
        except LogError as exc:
            self.close(str(exc))
            return
        try:
            self._judge(ep)
        except JUDGING as exc:
            self.close(f"{ep.resampler.what}: the monitor cannot judge it: {exc}")

    def _check_silence(self, ep: _Episode) -> None:
        """A topic that has said nothing for longer than ``max_gap_s`` while another spoke."""
        latest, limit = max(n for n in ep.last_ns if n is not None), self.mapping.timing.gap_limit_s
        for group, last in zip(self.groups, ep.last_ns):
            if last is not None and latest - last > limit * NS:
                raise LogError(f"{ep.resampler.what}, {group.source}: silent for {(latest - last) / NS:.3f} s "
                               f"(timing.max_gap_s is {limit:g} s)")

    def _ready(self, ep: _Episode) -> int:
        """Steps every topic has reached."""
        return 0 if ep.resampler.grid is None else min(s.k for s in ep.resampler.streams)

    def _row(self, ep: _Episode, k: int) -> np.ndarray:
        """Step ``k``'s observation in channel order and units, as ``EpisodeResampler.finish`` lays it out."""
        row = np.empty(len(self.names))
        for s in ep.resampler.streams:
            row[list(s.group.columns)] = s.out[k] * np.array([c.scale for c in s.group.channels])
        return row

    def _judge(self, ep: _Episode) -> None:
        """Step the monitor through every step now complete; at ``timing.steps``, close the episode."""
        ready = self._ready(ep)
        if ready > ep.judged and ep.step is None:
            self._start(ep)
        while ep.judged < ready:
            k, row = ep.judged, self._row(ep, ep.judged)
            assert ep.step is not None
            answer = ep.step(row)
            self.answers.append((ep.number, answer))
            self.verdict.step(answer, ep.number)
            if ep.recorder is not None:
                self._record(ep.recorder, k, row, answer)
            ep.judged += 1
        if ep.judged >= self.mapping.timing.steps:
            self.close(None)

    def _start(self, ep: _Episode) -> None:
        """The episode's monitor, told its skill, and its recording."""
        ep.step = ep.resources.enter_context(self.judge.open(ep.label))
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

    def close(self, why: str | None) -> None:
        """End the open episode; ``why``: the input that ended it, said as a WARN status."""
        ep, self.current = self.current, None
        if ep is not None:
            try:
                ep.resources.close()
            except JUDGING as exc:  # a service session that cannot be ended
                why = why or f"{ep.resampler.what}: its session did not end: {exc}"
        if why is not None:
            self.verdict.say(WARN, why, {"episode": str(ep.number) if ep is not None else ""})


def load_judge(model: str | None, url: str | None, fpr: float, models_dir: Path,
               api_key: str | None = None) -> tuple[Judge, tuple[str, ...]]:
    """The judge of ``model`` (a checkpoint's path or a name in ``models_dir``; with ``url``, a
    model the service hosts, None: its default) and the channel names it expects."""
    if url is not None:
        served = served_model(url, api_key, model)
        return RemoteJudge(ServiceClient(url, api_key), served["name"], fpr), tuple(served.get("channel_names", ()))
    if model is None:
        raise LogError("give --model: the checkpoint that judges (or --url, a service whose default model does)")
    path = Path(model)
    if not path.exists():
        path = models_dir / f"{model}.safetensors"
    memory = SkillMemory.load(path)
    return LocalJudge(memory, fpr), memory.channel_names
