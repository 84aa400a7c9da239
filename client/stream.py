"""One episode streamed to the service step by step, recorded on the way, surviving a lost service
with ``reconnect`` (a new session, the steps sent so far replayed)."""

from __future__ import annotations

import contextlib
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from neural_asm.client.source import StreamedEpisode
from neural_asm.client.summary import EpisodeSummary, StepLine, say, step_line
from neural_asm.client.transport import TRANSPORTS, ServiceError, ServiceLost, Transport
from neural_asm.models.answer import StepAnswer
from neural_asm.models.fault import joint_channels
from neural_asm.recordings import DEFAULT_DIR, EpisodeRecorder, new_run_id
from neural_asm.recordings.episode import Live, View
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.live import LiveViewer
from neural_asm.recordings.records import StepRecord

RECONNECT_ATTEMPTS = 5
RECONNECT_BACKOFF_S = (0.5, 1.0, 2.0, 4.0, 8.0)


@dataclass(frozen=True)
class Connection:
    """Where and how the client reaches the service."""

    url: str | None = None  # None: a client run starts the service in-process (``run_client``)
    api_key: str | None = None
    transport: str = "ws"  # ws (websocket /stream) or http (/sessions + /fault)
    reconnect: bool = False  # if the service goes away: a new session, the steps so far replayed


@dataclass(frozen=True)
class StreamOptions:
    """How each episode is streamed and recorded."""

    mode: str | None = None  # the session's recall mode (None: the service's choice, its model's served mode)
    out: Path = DEFAULT_DIR  # recordings folder
    session: dict[str, Any] = field(default_factory=dict)  # further session parameters: model, fpr, rate_hz
    realtime: bool = False  # send observation k no sooner than k periods after the first, as a robot would
    quiet: bool = False
    live: LiveViewer | None = None  # also shown in that Rerun viewer as it streams
    foxglove: FoxgloveLive | None = None  # also served to Foxglove


def _vector(values: dict[str, float] | None, names: tuple[str, ...]) -> np.ndarray | None:
    """Named values (absent from an HTTP ``/fault`` answer) in channel order."""
    return None if values is None else np.array([values[n] for n in names], np.float64)


class _Stream:
    """One episode's stream: its session (re)opened as needed, every step sent, scored, recorded."""

    def __init__(self, episode: StreamedEpisode, connection: Connection, options: StreamOptions) -> None:
        if connection.url is None or connection.transport not in TRANSPORTS:
            raise ValueError(f"a stream needs a service URL and a transport of {list(TRANSPORTS)}")
        self.episode, self.connection, self.options = episode, connection, options
        recording_id = new_run_id("client")  # the run id, shared with the service session so both files merge
        self.summary = EpisodeSummary(
            episode=episode.number, skill=episode.skill, seed=episode.seed, fault=episode.fault,
            disturbance=episode.disturbance, mode=options.mode or "", steps_total=len(episode.observations),
            steps_scored=0, detected=False, first_flag_step=None, first_flag_time_s=None, isolated_joint=None,
            fault_step=episode.fault_step, completed=False, reconnects=0, recording_id=recording_id, recordings={},
            service_recordings={}, **(asdict(episode.outcome) if episode.outcome else {}))
        self.params = {"cue_steps": 1, "recording_id": recording_id, **options.session}
        if options.mode is not None:  # else the service picks, and its reply names the mode
            self.params["mode"] = options.mode
        self.conn: Transport | None = None  # the session's connection while one is open

    def open(self, replay: int) -> Transport:
        """Connect, start a session and replay the first ``replay`` observations."""
        names, summary = self.episode.channel_names, self.summary
        t = TRANSPORTS[self.connection.transport](self.connection.url, self.connection.api_key)
        try:
            info = t.start(self.params)
            summary.mode = info.get("mode", summary.mode)
            service_names = tuple(info.get("channel_names", names))
            if service_names != names:
                raise ServiceError(f"the service's model expects channels {list(service_names)}, "
                                   f"the simulator sends {list(names)}")
            summary.service_recordings.update(
                {f"{k}#{summary.reconnects}" if summary.reconnects else k: v
                 for k, v in info.get("recordings", {}).items()})
            for k in range(replay):
                t.step(self.episode.observations[k].tolist())
            return t
        except BaseException:
            t.close()
            raise

    def connect(self) -> None:
        """The first session; an unreachable service is retried with ``reconnect``."""
        try:
            self.conn = self.open(0)
        except ServiceLost as exc:
            self.reopen(0, exc, "cannot reach the service")

    def reopen(self, k: int, exc: ServiceLost, what: str) -> None:
        """After losing the service (``what`` says when): a new session replaying ``k`` steps, if
        reconnecting, else the loss raised again."""
        if self.conn is not None:
            self.conn.close()
            self.conn = None
        say(f"{what}: {exc}", self.options.quiet)
        if not self.connection.reconnect:
            raise exc
        self.conn = _reconnect(self.open, k, self.summary, self.options.quiet)

    def recorder(self) -> EpisodeRecorder:
        """The client's recording. The service's own .rrd of the session logs the fault events;
        the client's then does not, so the merged view says each event once."""
        ep, summary = self.episode, self.summary
        metadata = {"source": "client", "skill": ep.skill, "seed": ep.seed, "fault": ep.fault,
                    "disturbance": ep.disturbance, "mode": summary.mode, "service_url": self.connection.url,
                    "transport": self.connection.transport, **(asdict(ep.outcome) if ep.outcome else {})}
        service_logs_events = any(k.split("#")[0] == "rrd" for k in summary.service_recordings)
        return EpisodeRecorder(summary.recording_id, ep.channel_names, folder=self.options.out,
                               recording_id=summary.recording_id, metadata=metadata,
                               view=View(ep.period_s, tuple(joint_channels(ep.channel_names)),
                                         events=not service_logs_events),
                               live=Live(self.options.live, self.options.foxglove))

    def score(self, k: int, answer: StepAnswer, rec: EpisodeRecorder) -> None:
        """Record and print step ``k``'s verdict."""
        names, summary, t_k = self.episode.channel_names, self.summary, k * self.episode.period_s
        line = StepLine.of(answer, k, t_k)
        rec.log_step(StepRecord(
            step=k, observation=self.episode.observations[k], expected=_vector(answer.expected, names),
            prediction=_vector(answer.prediction, names), errors=_vector(answer.errors, names),
            energy=line.energy, threshold=line.threshold, fault=line.fault,
            isolated_joint=line.isolated_joint, time_s=t_k))
        summary.steps.append(line)
        summary.steps_scored = k + 1
        if line.fault and not summary.detected:
            summary.detected = True
            summary.first_flag_step, summary.first_flag_time_s = k, t_k
            summary.isolated_joint = line.isolated_joint
        say(step_line(line), self.options.quiet)

    def send(self, rec: EpisodeRecorder, after_step: Callable[[int], None] | None) -> None:
        """Every step, the world up to its time logged first."""
        ep, world, k, shown = self.episode, self.episode.world, 0, 0
        started = time.monotonic()
        while k < len(ep.observations):
            t_k = k * ep.period_s
            if self.options.realtime:
                time.sleep(max(0.0, started + t_k - time.monotonic()))
            while shown < len(world) and world[shown].time_s <= t_k + 1e-9:
                rec.log_world(world[shown])
                shown += 1
            try:
                answer = self.conn.step(ep.observations[k].tolist())
            except ServiceLost as exc:
                self.reopen(k, exc, f"service lost at step {k}")
                continue  # send step k again on the new session
            self.score(k, answer, rec)
            if after_step is not None:
                after_step(k)
            k += 1
        for row in world[shown:]:  # settling
            rec.log_world(row)


def stream_episode(episode: StreamedEpisode, connection: Connection, options: StreamOptions,
                   after_step: Callable[[int], None] | None = None) -> EpisodeSummary:
    """Stream one episode to the service at ``connection``, recording it into ``options.out``;
    never leaves files open. ``after_step(k)`` is called after each scored step (tests use it to
    stop the service mid-episode). A service lost for good ends the summary with its error."""
    stream = _Stream(episode, connection, options)
    stream.connect()  # before recording: an unreachable service leaves no empty files
    with stream.recorder() as rec:
        stream.summary.recordings = {k: str(p) for k, p in rec.paths.items()}
        try:
            stream.send(rec, after_step)
            stream.summary.completed = True
            with contextlib.suppress(ServiceLost):
                stream.conn.end()
        except ServiceLost as exc:
            stream.summary.error = f"lost the service at {connection.url}: {exc}"
        finally:
            if stream.conn is not None:
                stream.conn.close()
    return stream.summary


def _reconnect(open_session: Callable[[int], Transport], k: int, summary: EpisodeSummary, quiet: bool) -> Transport:
    last: Exception | None = None
    for attempt, wait in enumerate(RECONNECT_BACKOFF_S[:RECONNECT_ATTEMPTS], 1):
        time.sleep(wait)
        say(f"reconnecting (attempt {attempt}/{RECONNECT_ATTEMPTS}): new session, replaying {k} step(s)", quiet)
        try:
            summary.reconnects += 1
            conn = open_session(k)
            say("reconnected", quiet)
            return conn
        except ServiceLost as exc:
            summary.reconnects -= 1
            last = exc
            say(f"  failed: {exc}", quiet)
    raise ServiceLost(f"gave up after {RECONNECT_ATTEMPTS} reconnect attempts: {last}")
