"""One episode streamed to the service step by step, recorded on the way, surviving a lost service
with ``reconnect`` (a new session, the steps sent so far replayed)."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from neural_asm.client.summary import EpisodeSummary, StepLine, say, step_line
from neural_asm.client.transport import TRANSPORTS, ServiceError, ServiceLost, Transport
from neural_asm.client.world import world_records
from neural_asm.models.fault import joint_channels
from neural_asm.recordings import EpisodeRecorder, new_run_id
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.live import LiveViewer
from neural_asm.recordings.records import StepRecord
from neural_asm.sim.config import SIM
from neural_asm.sim.episode import Episode

RECONNECT_ATTEMPTS = 5
RECONNECT_BACKOFF_S = (0.5, 1.0, 2.0, 4.0, 8.0)


def _vector(result: dict[str, Any], key: str, names: tuple[str, ...]) -> np.ndarray | None:
    values = result.get(key)
    if not values:
        return None
    return np.array([values[n] for n in names], np.float64)


def stream_episode(
    ep: Episode,
    index: int,
    url: str,
    api_key: str | None,
    mode: str,
    out: Path,
    transport: str = "ws",
    reconnect: bool = False,
    quiet: bool = False,
    after_step: Callable[[int], None] | None = None,
    period: float = 1.0 / SIM.timing.observation_hz,
    session: dict[str, Any] | None = None,
    metadata: dict[str, Any] | None = None,
    realtime: bool = False,
    live: LiveViewer | None = None,
    foxglove: FoxgloveLive | None = None,
) -> EpisodeSummary:
    """Stream one episode (simulated, or recorded with no 40 Hz world trace) to the service,
    recording it; never leaves files open. ``period`` is the time between its observations;
    ``session`` adds session parameters (the model, its rate), ``metadata`` what the
    client's recording says about the run; ``realtime`` sends observation k no sooner than
    k periods after the first (as a robot would), else each as soon as the last is answered;
    ``live``: also shown in that Rerun viewer as it streams; ``foxglove``: on that Foxglove server."""
    names = tuple(ep.channel_names)
    run_id = new_run_id("client")
    recording_id = run_id  # shared with the service session so both files merge
    summary = EpisodeSummary(
        episode=index, skill=ep.skill, seed=ep.seed,
        fault=None if ep.fault is None else ep.fault.to_dict(),
        disturbance=None if ep.disturbance is None else ep.disturbance.to_dict(),
        mode=mode, steps_total=len(ep.observations), steps_scored=0, detected=False, first_flag_step=None,
        first_flag_time_s=None, isolated_joint=None, fault_step=None if ep.fault is None else ep.fault.step,
        completed=False, reconnects=0, recording_id=recording_id, recordings={}, service_recordings={},
    )
    params = {"mode": mode, "cue_steps": 1, "recording_id": recording_id, **(session or {})}
    metadata = {"source": "client", "skill": ep.skill, "seed": ep.seed, "fault": summary.fault,
                "disturbance": summary.disturbance, "mode": mode, "service_url": url, "transport": transport,
                **(metadata or {})}
    make = TRANSPORTS[transport]

    def open_session(replay: int) -> Transport:
        """Connect, start a session and replay the first ``replay`` observations."""
        t = make(url, api_key)
        try:
            info = t.start(params)
            service_names = tuple(info.get("channel_names", names))
            if service_names != names:
                raise ServiceError(f"the service's model expects channels {list(service_names)}, "
                                   f"the simulator sends {list(names)}")
            summary.service_recordings.update(
                {f"{k}#{summary.reconnects}" if summary.reconnects else k: v
                 for k, v in info.get("recordings", {}).items()})
            for k in range(replay):
                t.step(ep.observations[k].tolist())
            return t
        except BaseException:
            t.close()
            raise

    try:  # connect before recording: an unreachable service leaves no empty files
        conn: Transport | None = open_session(0)
    except ServiceLost as exc:
        say(f"cannot reach the service: {exc}", quiet)
        if not reconnect:
            raise
        conn = _reconnect(open_session, 0, summary, quiet)
    # The service's own .rrd of the session logs the fault events; the client's then does not,
    # so the merged view says each event once.
    service_logs_events = any(k.split("#")[0] == "rrd" for k in summary.service_recordings)
    with EpisodeRecorder(run_id, names, folder=out, recording_id=recording_id, metadata=metadata,
                         step_period_s=period, joints=joint_channels(names), events=not service_logs_events,
                         live=live, foxglove=foxglove) as rec:
        summary.recordings = {k: str(p) for k, p in rec.paths.items()}
        try:
            next_row = 0
            k = 0
            started = time.monotonic()
            while k < len(ep.observations):
                t_k = k * period
                if realtime:
                    time.sleep(max(0.0, started + t_k - time.monotonic()))
                for row, world in world_records(ep, t_k, next_row):
                    rec.log_world(world)
                    next_row = row + 1
                try:
                    result = conn.step(ep.observations[k].tolist())
                except ServiceLost as exc:
                    conn.close()
                    conn = None
                    say(f"service lost at step {k}: {exc}", quiet)
                    if not reconnect:
                        raise
                    conn = _reconnect(open_session, k, summary, quiet)
                    continue  # send step k again on the new session
                line = StepLine(step=k, time_s=t_k, energy=float(result["energy"]),
                                threshold=float(result["threshold"]), fault=bool(result["fault"]),
                                isolated_joint=result.get("isolated_joint"),
                                inference_ms=float(result.get("inference_ms", float("nan"))), skill=result.get("skill"))
                rec.log_step(StepRecord(
                    step=k, observation=ep.observations[k], expected=_vector(result, "expected", names),
                    prediction=_vector(result, "prediction", names), errors=_vector(result, "errors", names),
                    energy=line.energy, threshold=line.threshold, fault=line.fault,
                    isolated_joint=line.isolated_joint, time_s=t_k))
                summary.steps.append(line)
                summary.steps_scored = k + 1
                if line.fault and not summary.detected:
                    summary.detected = True
                    summary.first_flag_step, summary.first_flag_time_s = k, t_k
                    summary.isolated_joint = line.isolated_joint
                say(step_line(line), quiet)
                if after_step is not None:
                    after_step(k)
                k += 1
            for _, world in world_records(ep, float(ep.t_hi[-1]) if len(ep.t_hi) else 0.0, next_row):  # settling
                rec.log_world(world)
            summary.completed = True
            with contextlib.suppress(ServiceLost):
                conn.end()
        except ServiceLost as exc:
            summary.error = f"lost the service at {url}: {exc}"
        finally:
            if conn is not None:
                conn.close()
    return summary


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
