"""A client run: the service (the given URL, or one started in-process), then each episode
simulated and streamed, observed at the skill layer's 2 Hz or at every 40 Hz control tick
(the session says its rate, so a model learnt at another refuses it).

Under stiff control (the default) an episode is the demonstrator's IK plan, as every data set
is. Under compliant control it is the memory's recalled plan (the correction experiment's
setting), corrected or not, and the session names the monitor calibrated for compliant
control (``pipelines.compliant``), the one the correction's gate also uses. At 40 Hz the plan is
the 2 Hz memory's (a 40 Hz one's offline recall drifts over 300 ticks) and the 40 Hz network
monitors every tick."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Callable, Iterator

from neural_asm.client.stream import stream_episode
from neural_asm.client.summary import EpisodeSummary, closing_lines, say, summary_line, verdicts_side_by_side
from neural_asm.client.transport import TRANSPORTS, ServiceError, check_url, served_digest
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import SCORING
from neural_asm.pipelines.compliant import compliant_episode, digest_of, ensure_compliant_model
from neural_asm.pipelines.default_model import RATE_MODES, ensure_default_model, model_name
from neural_asm.recordings import DEFAULT_DIR
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.live import LiveViewer
from neural_asm.runtime.home import home_path
from neural_asm.sim.config import CONTROLLERS, RATES, SIM
from neural_asm.sim.disturbances import FallingObject, elbow_hit
from neural_asm.sim.episode import Episode
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.runner import run_episode
from neural_asm.sim.skills import SKILLS

MODES = ("offline", "online")
# The showcase's fault: the README figure's locked joint, which the default model flags at its onset.
SHOWCASE_FAULT = FaultSpec(joint=4, time_s=3.0, overshoot_deg=5.0)


def fault_spec(joint: int | None, time_s: float | None, overshoot_deg: float | None) -> FaultSpec | None:
    """The fault the three ``--fault-*`` options describe: all three or none."""
    given = [v is not None for v in (joint, time_s, overshoot_deg)]
    if not any(given):
        return None
    if not all(given):
        raise ValueError("give all three of --fault-joint, --fault-time and --fault-overshoot, or none")
    return FaultSpec(joint, time_s, overshoot_deg)  # type: ignore[arg-type]


def falling_object(drop: bool, momentum_kg_m_s: float | None = None) -> FallingObject | None:
    """The hit ``--falling-object`` drops: the correction experiment's box on the elbow during the
    carry, of ``--hit-momentum`` (default ``SIM.hit.demo_momentum``, a hit the monitor flags)."""
    if momentum_kg_m_s is not None and not drop:
        raise ValueError("--hit-momentum needs --falling-object")
    if not drop:
        return None
    momentum = SIM.hit.demo_momentum if momentum_kg_m_s is None else momentum_kg_m_s
    if not momentum > 0:
        raise ValueError(f"--hit-momentum must be > 0 kg m/s, got {momentum}")
    return elbow_hit(momentum)


def _compliant_monitor(models_dir: Path, rate: float, quiet: bool) -> tuple[Path, tuple[NeuralASM, NeuralASM]]:
    """The compliant monitor's checkpoint at `rate` and (the monitor, the 2 Hz planner), built
    (with the default models) on first use."""
    path = ensure_compliant_model(models_dir, progress=not quiet, rate=rate)
    return path, (checkpoint.load(path), checkpoint.load(ensure_default_model(models_dir, progress=not quiet)))


def _check_served(url: str, api_key: str | None, path: Path) -> None:
    """The service must host the very checkpoint the correction's gate runs."""
    served = served_digest(url, api_key, path.stem)
    if served != digest_of(path):
        raise ServiceError(f"the service at {url} does not host {path} (model {path.stem!r}: "
                           f"{'digest ' + served if served else 'none'}); start it on that models folder "
                           f"(nasm serve --models-dir {path.parent}) or omit --url")


def _simulate(skill: str, seed: int, fault: FaultSpec | None, disturbance: FallingObject | None, rate: float,
              monitor: tuple[NeuralASM, NeuralASM] | None, correct: bool, mode: str) -> tuple[Episode, dict | None]:
    """The episode observed at ``rate`` (stiff: the IK plan; compliant, ``monitor`` = (monitor,
    planner) given: the recalled plan) and, with ``correct``, when its correction engaged and let go."""
    if monitor is None:
        return run_episode(skill, seed, fault=fault, disturbance=disturbance, rate=rate), None
    ep, correction = compliant_episode(monitor[0], skill, seed, disturbance, fault, correct, mode,
                                       SCORING.default_fpr, planner=monitor[1])
    if correction is None:
        return ep, None
    return ep, {"engaged_step": correction.engaged_step, "yielded_step": correction.yielded_step}


@contextlib.contextmanager
def _service(url: str | None, api_key: str | None, models_dir: Path, out: Path, rate: float,
             quiet: bool) -> Iterator[str]:
    """The given URL, or an embedded service on a free loopback port for the block's duration,
    hosting the default model at ``rate`` (built first if missing)."""
    if url:
        yield url
        return
    from neural_asm.service.embedded import start_embedded  # only to start it in-process
    from neural_asm.service.settings import Settings

    say(f"starting the service in-process (models: {models_dir}; the default Panda model at {rate:g} Hz is built "
        "on first run, which takes a few minutes)", quiet)
    ensure_default_model(models_dir, progress=not quiet, rate=rate)
    settings = Settings(models_dir=models_dir, recordings_dir=out, api_key=api_key or None)
    with start_embedded(settings) as server:
        say(f"service at {server.url}", quiet)
        yield server.url


def run_client(
    skill: str = SKILLS[0],
    seed: int = SIM.seeds.client,
    fault: FaultSpec | None = None,
    falling_object: FallingObject | None = None,
    episodes: int = 1,
    url: str | None = None,
    api_key: str | None = None,
    mode: str | None = None,
    out: Path = DEFAULT_DIR,
    reconnect: bool = False,
    transport: str = "ws",
    models_dir: Path | None = None,
    quiet: bool = False,
    after_step: Callable[[int, int], None] | None = None,
    controller: str = SIM.controller,
    correct: bool = False,
    rate: float = SIM.timing.observation_hz,
    realtime: bool = False,
    showcase: bool = False,
    live: LiveViewer | None = None,
    foxglove: FoxgloveLive | None = None,
) -> list[EpisodeSummary]:
    """Simulate ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) and stream each to the service.

    ``controller`` is the arm's joint controller; ``correct`` (compliant only) turns the
    memory's correction on. ``rate`` (Hz) is how often the episode is observed and streamed
    (the default model at that rate, ``panda`` or ``panda-40hz``, built on first use when the
    service is started here); ``mode`` defaults to the rate's ``RATE_MODES``; ``realtime``
    sends each observation at its time in the episode instead of as fast as the service answers.
    ``after_step(episode, step)`` is called after each scored step (tests use it to stop the
    service mid-episode). ``showcase`` (no fault, falling object or second episode given) streams
    the episode of ``seed`` twice, normal and with ``SHOWCASE_FAULT``, and prints both verdicts
    side by side: what the monitor is for, on a first run. ``live``: each episode also shown in
    that Rerun viewer as it streams, ``foxglove`` on that Foxglove server. Stops after an episode the service was lost in.
    """
    if rate not in RATES:
        raise ValueError(f"--rate must be one of {', '.join(map(str, RATES))} Hz, got {rate!r}")
    mode = RATE_MODES[rate] if mode is None else mode
    for name, value, known in (("skill", skill, SKILLS), ("mode", mode, MODES), ("transport", transport, TRANSPORTS),
                               ("controller", controller, CONTROLLERS)):
        if value not in known:
            raise ValueError(f"--{name} must be one of {', '.join(known)}, got {value!r}")
    if episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {episodes}")
    if showcase and (fault is not None or falling_object is not None or episodes != 1):
        raise ValueError("the showcase streams its own normal and faulty episode: give no fault, falling object "
                         "or --episodes with it")
    if correct and controller != "compliant":
        raise ValueError("--correct needs --controller compliant: the correction drives a compliant arm's "
                         "set-point (the stiff servos hold these hits alone)")
    if url:
        check_url(url)
    out = Path(out)
    summaries: list[EpisodeSummary] = []
    models_dir = home_path("models") if models_dir is None else Path(models_dir)
    monitor_path, monitor = _compliant_monitor(models_dir, rate, quiet) if controller == "compliant" else (None, None)
    with _service(url, api_key, models_dir, out, rate, quiet) as service_url:
        session: dict = {"rate_hz": rate}
        if monitor_path is not None:
            if url:
                _check_served(url, api_key, monitor_path)
            session |= {"model": monitor_path.stem, "fpr": SCORING.default_fpr}
        elif not url or rate != SIM.timing.observation_hz:  # at 2 Hz a given service's default model
            session["model"] = model_name(rate)
        plans = [(seed, None), (seed, SHOWCASE_FAULT)] if showcase else [(seed + i, fault) for i in range(episodes)]
        for i, (episode_seed, episode_fault) in enumerate(plans):
            ep, correction = _simulate(skill, episode_seed, episode_fault, falling_object, rate, monitor, correct, mode)
            say(f"episode {i + 1}/{len(plans)}: {skill}, seed {episode_seed}, {rate:g} Hz, {controller} control"
                + (", corrected" if correct else "")
                + (f", fault {episode_fault.to_dict()}" if episode_fault else "")
                + (", falling object" if falling_object else "") + f", streaming to {service_url}", quiet)
            hook = None if after_step is None else (lambda k, i=i: after_step(i, k))
            outcome = {"controller": controller, "correction": correction, "cube_error_m": ep.cube_error_m}
            s = stream_episode(ep, i + 1, service_url, api_key, mode, out, transport, reconnect, quiet, hook,
                               period=1.0 / rate, session=session, metadata=outcome, realtime=realtime, live=live,
                               foxglove=foxglove)
            s.controller, s.correction, s.cube_error_m = controller, correction, ep.cube_error_m
            summaries.append(s)
            say(summary_line(s), quiet)
            if s.error:
                break
    if showcase:
        say(verdicts_side_by_side(summaries), quiet)
    say(closing_lines(summaries), quiet)
    return summaries
