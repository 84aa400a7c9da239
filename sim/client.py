"""Streaming Panda client: simulate an episode, stream it to the Neural ASM service, record it.

    python sim/client.py                                  # one episode, embedded service
    python sim/client.py --fault-joint 2 --fault-time 3 --fault-overshoot 15
    python sim/client.py --url http://127.0.0.1:8000 --api-key KEY --episodes 5 --reconnect

Each episode is simulated first (``sim.runner.run_episode``), then its 15 observations
are streamed to the service one step at a time over the websocket ``/stream`` (or, with
``--transport http``, ``POST /sessions`` + ``POST /fault``). A live line is printed per
step (energy, threshold, flag, isolated joint) and a summary per episode.

The client talks to the service only over HTTP/websocket. With no ``--url`` it starts the
service in-process on a free loopback port (``service.embedded``), which builds the
default Panda model on first run (a few minutes, with a progress bar).

Every episode is recorded to ``<out>/client-....rrd`` and ``.mcap`` (``recordings``) under
a Rerun recording id that is also given to the service session, so the client's file
(world: arm, tool path, cube; scores) and the service's file merge into one view:
``rerun runs/recordings/client-X.rrd runs/recordings/service-client-X-*.rrd``.

If the service goes away mid-episode the client says so; with ``--reconnect`` it opens a
new session, replays the steps sent so far and carries on. Recordings are closed in all
cases (normal exit, lost service, Ctrl-C, errors) and stay readable.

Exit codes: 0 done, 2 the service refused (bad API key, unknown model, ...), 3 the service
went away (or could not be reached), 130 Ctrl-C. ``run_client`` is the function behind the
CLI; it returns one ``EpisodeSummary`` per episode.
"""

from __future__ import annotations

import runtime  # noqa: F401  (first: one BLAS thread, no display)

import sys
from pathlib import Path

if __package__ in (None, ""):  # run as a script: import the project, not sim/'s modules as top level
    _here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _here]
    sys.path.insert(0, str(_here.parent))

import contextlib
import json
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Iterator

import numpy as np
import typer

from recordings import DEFAULT_DIR, EpisodeRecorder, new_run_id
from recordings.records import StepRecord, WorldRecord
from sim.config import SIM
from sim.disturbances import FallingObject
from sim.episode import Episode
from sim.faults import FaultSpec
from sim.panda import dh_frames
from sim.runner import run_episode
from sim.skills import SKILLS
from sim.transport import TRANSPORTS, ServiceError, ServiceLost, Transport

RECONNECT_ATTEMPTS = 5
RECONNECT_BACKOFF_S = (0.5, 1.0, 2.0, 4.0, 8.0)


# --------------------------------------------------------------------------- episode results


@dataclass
class StepLine:
    step: int
    time_s: float
    energy: float
    threshold: float
    fault: bool
    isolated_joint: str | None
    inference_ms: float


@dataclass
class EpisodeSummary:
    episode: int
    skill: str
    seed: int
    fault: dict | None
    disturbance: dict | None
    mode: str
    steps_total: int
    steps_scored: int
    detected: bool
    first_flag_step: int | None
    first_flag_time_s: float | None
    isolated_joint: str | None  # at the first flagged step
    fault_step: int | None
    completed: bool  # every step scored
    reconnects: int
    recording_id: str
    recordings: dict[str, str]
    service_recordings: dict[str, str]
    error: str | None = None
    steps: list[StepLine] = field(default_factory=list)

    @property
    def energies(self) -> list[float]:
        return [s.energy for s in self.steps]

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def summary_line(s: EpisodeSummary) -> str:
    what = f"{s.skill} seed {s.seed}"
    if s.fault:
        f = s.fault
        what += f", fault joint{f['joint']} {f['overshoot_deg']:+g} deg at {f['time_s']:g} s (step {s.fault_step})"
    if s.disturbance:
        what += f", falling object at {s.disturbance['release_s']:g} s"
    if s.detected:
        verdict = (f"DETECTED at step {s.first_flag_step} (t={s.first_flag_time_s:g} s), "
                   f"isolated joint: {s.isolated_joint or 'none'}")
    else:
        verdict = "not detected" if s.completed else "not detected in the steps scored"
    tail = f"{s.steps_scored}/{s.steps_total} steps scored"
    if s.reconnects:
        tail += f", {s.reconnects} reconnect(s)"
    if s.error:
        tail += f", INTERRUPTED: {s.error}"
    return f"summary: episode {s.episode} ({what}): {verdict}; {tail}"


def step_line(line: StepLine) -> str:
    flag = "FAULT" if line.fault else "ok"
    return (f"step {line.step:2d}  t={line.time_s:4.1f}s  energy={line.energy:10.3f}  "
            f"threshold={line.threshold:9.3f}  {flag:5s}  joint={line.isolated_joint or '-':7s}  "
            f"({line.inference_ms:.1f} ms)")


# --------------------------------------------------------------------------- world for the 3D view


def link_positions(q: np.ndarray) -> np.ndarray:
    """(10, 3) origins of the base, the 8 DH frames (Franka's table) and the tool centre point."""
    return np.array([frame[:3, 3] for frame in dh_frames(q)])


def world_records(ep: Episode, upto_s: float, start_row: int) -> Iterator[tuple[int, WorldRecord]]:
    """40 Hz world rows from ``start_row`` with time <= ``upto_s``."""
    row = start_row
    while row < len(ep.t_hi) and ep.t_hi[row] <= upto_s + 1e-9:
        yield row, WorldRecord(time_s=float(ep.t_hi[row]), link_positions=link_positions(ep.qpos_hi[row]),
                               ee=ep.ee_hi[row], cube=ep.cube_hi[row])
        row += 1


# --------------------------------------------------------------------------- streaming one episode


def _vector(result: dict[str, Any], key: str, names: tuple[str, ...]) -> np.ndarray | None:
    values = result.get(key)
    if not values:
        return None
    return np.array([values[n] for n in names], np.float64)


def _print(text: str, quiet: bool) -> None:
    if not quiet:
        print(text, flush=True)


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
) -> EpisodeSummary:
    """Stream one episode (simulated, or recorded with no 40 Hz world trace) to the service,
    recording it; never leaves files open. ``period`` is the time between its observations."""
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
    params = {"mode": mode, "cue_steps": 1, "recording_id": recording_id}
    metadata = {"source": "client", "skill": ep.skill, "seed": ep.seed, "fault": summary.fault,
                "disturbance": summary.disturbance, "mode": mode, "service_url": url, "transport": transport}
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

    with EpisodeRecorder(run_id, names, folder=out, recording_id=recording_id, metadata=metadata,
                         step_period_s=period) as rec:
        summary.recordings = {k: str(p) for k, p in rec.paths.items()}
        conn: Transport | None = None
        try:
            try:
                conn = open_session(0)
            except ServiceLost as exc:
                _print(f"cannot reach the service: {exc}", quiet)
                if not reconnect:
                    raise
                conn = _reconnect(open_session, 0, summary, quiet)
            next_row = 0
            k = 0
            while k < len(ep.observations):
                t_k = k * period
                for row, world in world_records(ep, t_k, next_row):
                    rec.log_world(world)
                    next_row = row + 1
                try:
                    result = conn.step(ep.observations[k].tolist())
                except ServiceLost as exc:
                    conn.close()
                    conn = None
                    _print(f"service lost at step {k}: {exc}", quiet)
                    if not reconnect:
                        raise
                    conn = _reconnect(open_session, k, summary, quiet)
                    continue  # send step k again on the new session
                line = StepLine(step=k, time_s=t_k, energy=float(result["energy"]),
                                threshold=float(result["threshold"]), fault=bool(result["fault"]),
                                isolated_joint=result.get("isolated_joint"),
                                inference_ms=float(result.get("inference_ms", float("nan"))))
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
                _print(step_line(line), quiet)
                if after_step is not None:
                    after_step(k)
                k += 1
            for _, world in world_records(ep, float(ep.t_hi[-1]) if len(ep.t_hi) else 0.0, next_row):  # settling
                rec.log_world(world)
            summary.completed = True
            with contextlib.suppress(ServiceLost):
                conn.end()
        except ServiceLost as exc:
            summary.error = f"service at {url} went away: {exc}"
        finally:
            if conn is not None:
                conn.close()
    return summary


def _reconnect(open_session: Callable[[int], Transport], k: int, summary: EpisodeSummary, quiet: bool) -> Transport:
    last: Exception | None = None
    for attempt, wait in enumerate(RECONNECT_BACKOFF_S[:RECONNECT_ATTEMPTS], 1):
        time.sleep(wait)
        _print(f"reconnecting (attempt {attempt}/{RECONNECT_ATTEMPTS}): new session, replaying {k} step(s)", quiet)
        try:
            summary.reconnects += 1
            conn = open_session(k)
            _print("reconnected", quiet)
            return conn
        except ServiceLost as exc:
            summary.reconnects -= 1
            last = exc
            _print(f"  failed: {exc}", quiet)
    raise ServiceLost(f"gave up after {RECONNECT_ATTEMPTS} reconnect attempts: {last}")


# --------------------------------------------------------------------------- the whole run


def _fault_spec(joint: int | None, time_s: float | None, overshoot_deg: float | None) -> FaultSpec | None:
    given = [v is not None for v in (joint, time_s, overshoot_deg)]
    if not any(given):
        return None
    if not all(given):
        raise ValueError("give all three of --fault-joint, --fault-time and --fault-overshoot, or none")
    return FaultSpec(joint, time_s, overshoot_deg)  # type: ignore[arg-type]


@contextlib.contextmanager
def _service(url: str | None, api_key: str | None, models_dir: Path, out: Path, quiet: bool) -> Iterator[str]:
    """The given URL, or an embedded service on a free loopback port for the block's duration."""
    if url:
        yield url
        return
    from service.embedded import start_embedded  # only to start it in-process
    from service.settings import Settings

    _print(f"starting the service in-process (models: {models_dir}; the default Panda model is built on "
           "first run, which takes a few minutes)", quiet)
    settings = Settings(models_dir=models_dir, recordings_dir=out, api_key=api_key or None)
    with start_embedded(settings) as server:
        _print(f"service at {server.url}", quiet)
        yield server.url


def run_client(
    skill: str = SKILLS[0],
    seed: int = SIM.seeds.client,
    fault: FaultSpec | None = None,
    falling_object: FallingObject | None = None,
    episodes: int = 1,
    url: str | None = None,
    api_key: str | None = None,
    mode: str = "offline",
    out: Path = DEFAULT_DIR,
    reconnect: bool = False,
    transport: str = "ws",
    models_dir: Path = Path("runs/models"),
    quiet: bool = False,
    after_step: Callable[[int, int], None] | None = None,
) -> list[EpisodeSummary]:
    """Simulate ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) and stream each to the service.

    ``after_step(episode, step)`` is called after each scored step (tests use it to stop
    the service mid-episode). Stops after an episode the service was lost in.
    """
    if skill not in SKILLS:
        raise ValueError(f"unknown skill {skill!r}; known: {', '.join(SKILLS)}")
    if mode not in ("offline", "online"):
        raise ValueError(f"mode must be 'offline' or 'online', got {mode!r}")
    if transport not in TRANSPORTS:
        raise ValueError(f"transport must be one of {sorted(TRANSPORTS)}, got {transport!r}")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    out = Path(out)
    summaries: list[EpisodeSummary] = []
    with _service(url, api_key, Path(models_dir), out, quiet) as service_url:
        for i in range(episodes):
            ep = run_episode(skill, seed + i, fault=fault, disturbance=falling_object)
            _print(f"episode {i + 1}/{episodes}: {skill}, seed {seed + i}"
                   + (f", fault {fault.to_dict()}" if fault else "")
                   + (", falling object" if falling_object else "") + f", streaming to {service_url}", quiet)
            hook = None if after_step is None else (lambda k, i=i: after_step(i, k))
            s = stream_episode(ep, i + 1, service_url, api_key, mode, out, transport, reconnect, quiet, hook)
            summaries.append(s)
            _print(summary_line(s), quiet)
            _print(f"recordings: {s.recordings.get('rrd')} {s.recordings.get('mcap')}"
                   + (f" (service: {', '.join(s.service_recordings.values())})" if s.service_recordings else ""),
                   quiet)
            if s.error:
                break
    return summaries


# --------------------------------------------------------------------------- CLI

app = typer.Typer(add_completion=False, help=__doc__.split("\n\n")[0])


@app.command()
def main(
    skill: str = typer.Option(SKILLS[0], help=f"skill to run: {', '.join(SKILLS)}"),
    seed: int = typer.Option(SIM.seeds.client, help="episode seed (episode i uses seed + i); the default is in no training or calibration set"),
    fault_joint: int | None = typer.Option(None, help="fault: joint 1..7 (give all three fault options or none)"),
    fault_time: float | None = typer.Option(None, help="fault: time in s, on the 0.5 s grid"),
    fault_overshoot: float | None = typer.Option(None, help="fault: overshoot in degrees"),
    falling_object: bool = typer.Option(False, "--falling-object", help="drop a 5 kg box on the arm at 4 s"),
    episodes: int = typer.Option(1, min=1, help="number of episodes"),
    url: str | None = typer.Option(None, help="service URL; default: start one in-process on a free port"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="API key (X-API-Key header)"),
    mode: str = typer.Option("offline", help="recall mode: offline (the paper's setting) or online"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder"),
    reconnect: bool = typer.Option(False, "--reconnect", help="if the service goes away, reconnect and replay"),
    transport: str = typer.Option("ws", help="ws (websocket /stream) or http (/sessions + /fault)"),
    models_dir: Path = typer.Option(Path("runs/models"), help="models folder of the in-process service"),
    json_out: Path | None = typer.Option(None, "--json", help="also write the summaries as JSON here"),
) -> None:
    """Run Panda episodes and stream them to the Neural ASM service."""
    try:
        fault = _fault_spec(fault_joint, fault_time, fault_overshoot)
        if mode not in ("offline", "online"):
            raise ValueError(f"--mode must be offline or online, got {mode!r}")
        if skill not in SKILLS:
            raise ValueError(f"--skill must be one of {', '.join(SKILLS)}, got {skill!r}")
        if transport not in TRANSPORTS:
            raise ValueError(f"--transport must be ws or http, got {transport!r}")
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from exc
    try:
        summaries = run_client(skill, seed, fault, FallingObject() if falling_object else None, episodes, url,
                               api_key, mode, out, reconnect, transport, models_dir)
    except ServiceError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from exc
    except ServiceLost as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(3) from exc
    except KeyboardInterrupt:
        typer.echo("interrupted; recordings closed", err=True)
        raise typer.Exit(130) from None
    if json_out is not None:
        json_out.write_text(json.dumps([s.to_dict() for s in summaries], indent=1))
    if any(s.error for s in summaries):
        typer.echo("the service went away; recordings so far are closed and readable", err=True)
        raise typer.Exit(3)


if __name__ == "__main__":
    app()
