"""ROS bags (``logs.bagfiles``) cut into episodes and resampled as they are read.

Messages go one by one into the open episode's resampler (``logs.resample``): memory holds the
samples around the next step of each topic, not the bag. Episodes are numbered in reading order
across the bags of a source, bad ones included, so a number always means the same episode.
A bad episode (a dropout, too short, a field that cannot be read) is an error, or, with
``skip_bad``, a warning naming it; the last episode of a damaged bag, which the damage may have
cut, is dropped with a warning. Skill names come from the label topic: its last message inside
the episode, or one published up to ``label_tolerance_s`` before the episode's first sample.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from neural_asm.logs.bagfiles import Bag, BagRead, Decode, find_bags, read_messages
from neural_asm.logs.errors import LogError
from neural_asm.logs.fields import NS, extractor, header_stamp
from neural_asm.logs.mapping import Episodes, Mapping
from neural_asm.logs.recorded import Recorded
from neural_asm.logs.resample import EpisodeResampler, Group


def topic_groups(mapping: Mapping) -> list[Group]:
    """The mapping's channels grouped by topic, topics in order of their first channel."""
    topics = list(dict.fromkeys(c.topic for c in mapping.channels))
    return [Group(f"topic {t}", tuple(c for c in mapping.channels if c.topic == t),
                  tuple(i for i, c in enumerate(mapping.channels) if c.topic == t)) for t in topics]


BLOCK = 4096  # samples of a topic handed to the resampler at once


@dataclass
class _Open:
    """The episode being read, with each topic's samples not yet handed to its resampler."""

    number: int
    lo: int  # ns: its window's start; samples before it are not its own
    resampler: EpisodeResampler
    label: str | None
    times: list[list[int]]
    payloads: list[list[Any]]
    failed: str | None = None

    def flush(self, g: int) -> None:
        """Hand topic ``g``'s held samples to the resampler (a bad one marks the episode failed)."""
        times, payloads = self.times[g], self.payloads[g]
        self.times[g], self.payloads[g] = [], []
        if self.failed is None:
            try:
                self.resampler.add(g, (np.array(times, np.int64) - self.lo) / NS, payloads)
            except LogError as exc:
                self.failed = str(exc)


class _BagEpisodes:
    """One bag's messages in, its episodes (Recorded) and warnings (str) out."""

    def __init__(self, bag: Bag, mapping: Mapping, first_number: int, skip_bad: bool) -> None:
        assert isinstance(mapping.source, Episodes)
        self.bag, self.mapping, self.split, self.skip_bad = bag, mapping, mapping.source, skip_bad
        self.groups = topic_groups(mapping)
        self.group_of = {g.source.removeprefix("topic "): i for i, g in enumerate(self.groups)}
        self.number = first_number
        self.read = BagRead()
        self.current: _Open | None = None
        self.recent_label: tuple[int, str] | None = None
        self.last_seen: int | None = None
        self.extract: dict[int, Callable[[Any], np.ndarray]] = {}
        self.out: list[Recorded | str] = []

    def _decode(self, g: int, payload: tuple[Any, Decode | None]) -> np.ndarray:
        body, decode = payload
        try:
            message = body if decode is None else decode(body)
        except Exception as exc:  # noqa: BLE001  (a message the bag's own definition cannot decode)
            raise LogError(f"bag {self.bag.name}: a message on {self.groups[g].source} cannot be decoded "
                           f"({type(exc).__name__}: {exc})") from None
        if g not in self.extract:
            topic = self.groups[g].source.removeprefix("topic ")
            self.extract[g] = extractor(list(self.groups[g].channels), topic, self.read.types.get(topic, "?"))
        return self.extract[g](message)

    def _open(self, lo: int) -> None:
        what = f"bag {self.bag.name}, episode {self.number}"
        label = None
        if self.recent_label is not None and self.recent_label[0] >= lo - self.split.label_tolerance_s * NS:
            label = self.recent_label[1]
        resampler = EpisodeResampler(self.groups, self.mapping.timing, what, self._decode)  # type: ignore[arg-type]
        n = len(self.groups)
        self.current = _Open(self.number, lo, resampler, label, [[] for _ in range(n)], [[] for _ in range(n)])
        self.number += 1

    def close(self, last: bool = False) -> None:
        ep, self.current = self.current, None
        if ep is None:
            return
        for g in range(len(self.groups)):
            ep.flush(g)
        why = ep.failed
        if why is None:
            try:
                data = ep.resampler.finish()
            except LogError as exc:
                why = str(exc)
        if why is not None:
            if last and self.read.damage:
                self.out.append(f"dropped the last episode ({ep.number}) of the damaged bag {self.bag.name}: {why}")
            elif self.skip_bad:
                self.out.append(f"skipped episode {ep.number}: {why}")
            else:
                raise LogError(f"{why} (--skip-bad skips this episode)")
            return
        label = ep.label
        if label is None:
            label = self.bag.name
            if self.split.label_topic:
                self.out.append(f"bag {self.bag.name}, episode {ep.number}: no message on {self.split.label_topic} "
                                f"in it or up to {self.split.label_tolerance_s:g} s before it; named {label!r}")
        self.out.append(Recorded(data, label, ep.resampler.what, ep.lo / NS, ep.number))

    def sample(self, topic: str, t: int, payload: tuple[Any, Decode | None]) -> None:
        """A message of a mapped topic at ``t`` ns (after any marker or label at that time)."""
        split = self.split
        if split.split == "gap":
            if self._after_gap(t):
                self.close()
            self.last_seen = t if self.last_seen is None else max(self.last_seen, t)
        if self.current is None:
            if split.split == "marker":
                return  # before the first marker
            self._open(t)
        ep = self.current
        assert ep is not None
        if t < ep.lo or ep.failed:
            return  # stamped before its window (clock jitter), or already refused
        g = self.group_of[topic]
        if g not in self.extract:
            self._decode(g, payload)  # the first message of a topic: a wrong field is refused at once
        times = ep.times[g]
        times.append(t)
        ep.payloads[g].append(payload)
        if len(times) >= BLOCK:
            ep.flush(g)

    def run(self) -> Iterator[Recorded | str]:
        split, header = self.split, self.split.stamp == "header"
        topics = {c.topic for c in self.mapping.channels if c.topic}
        checked = False
        fast = split.split != "gap" and not header
        hold, lo = self._hold(fast)
        for topic, log_time, raw, decode in read_messages(
                self.bag, topics | {t for t in (split.marker_topic, split.label_topic) if t}, self.read):
            if not checked and self.read.indexed:
                self._check_topics(topics)  # an indexed file names its topics before its messages
                checked = True
            held = hold.get(topic)
            if held is not None and log_time >= lo:  # the common case, kept short: held for the topic's next block
                held[0].append(log_time)
                held[1].append((raw, decode))
                if len(held[0]) >= BLOCK:
                    held[2].flush(held[3])
                    hold, lo = self._hold(fast)
                continue
            if header or topic not in topics:
                body: Any = self._message(topic, raw, decode)
                t = header_stamp(body, log_time) if header else log_time
                payload: tuple[Any, Decode | None] = (body, None)
            else:
                t, payload = log_time, (raw, decode)
            if topic == split.marker_topic:
                self.close()
                self._open(t)
            if topic == split.label_topic:
                text = str(getattr(payload[0], "data", ""))
                self.recent_label = (t, text)
                if self.current is not None and t >= self.current.lo and not self._after_gap(t):
                    self.current.label = text
            if topic in topics:
                self.sample(topic, t, payload)
            hold, lo = self._hold(fast)
            if self.out:
                yield from self._flush()
        self._check_topics(topics)
        if self.read.damage:
            yield self.read.damage
        self.close(last=True)
        yield from self._flush()
        if self.read.missing:
            missing = f"bag {self.bag.name} is missing messages: {'; '.join(self.read.missing)}"
            if not self.skip_bad:
                raise LogError(f"{missing} (--skip-bad keeps what was read)")
            yield missing

    def _hold(self, fast: bool) -> tuple[dict[str, tuple[list[int], list[Any], _Open, int]], int]:
        """Where a sample of each checked topic goes while nothing else can happen to it (no gap split,
        header stamps or failure): the open episode's lists, and its window's start."""
        ep = self.current
        if not fast or ep is None or ep.failed is not None:
            return {}, 0
        return {topic: (ep.times[g], ep.payloads[g], ep, g) for topic, g in self.group_of.items()
                if g in self.extract}, ep.lo

    def _after_gap(self, t: int) -> bool:
        """A gap split's silence lies between the last sample and ``t``: ``t`` belongs to the next episode."""
        gap = self.split.gap_s
        return self.split.split == "gap" and self.last_seen is not None and t - self.last_seen > (gap or 0) * NS

    def _message(self, topic: str, raw: bytes, decode: Decode) -> Any:
        try:
            return decode(raw)
        except Exception as exc:  # noqa: BLE001
            raise LogError(f"bag {self.bag.name}: a message on {topic} cannot be decoded "
                           f"({type(exc).__name__}: {exc})") from None

    def _flush(self) -> Iterator[Recorded | str]:
        out, self.out = self.out, []
        yield from out

    def _check_topics(self, topics: set[str]) -> None:
        """Refuse a bag without a mapped topic (the label topic may be absent)."""
        needed = topics | ({self.split.marker_topic} if self.split.marker_topic else set())
        absent = sorted(needed - set(self.read.types))
        if absent and self.read.damage is None:
            known = ", ".join(f"{t} ({ty})" for t, ty in sorted(self.read.types.items())) or "none"
            raise LogError(f"bag {self.bag.name} has no topic {', '.join(absent)}; its topics: {known}")


def read_episodes(source: Path, mapping: Mapping, skip_bad: bool = False) -> Iterator[Recorded | str]:
    """Each episode of every bag of ``source``, resampled; strings are warnings to pass on."""
    number = 0
    for bag in find_bags(source):
        reader = _BagEpisodes(bag, mapping, number, skip_bad)
        yield from reader.run()
        number = reader.number
