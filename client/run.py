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
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterator

from neural_asm.client.source import Outcome, simulated
from neural_asm.client.stream import Connection, StreamOptions, stream_episode
from neural_asm.client.summary import EpisodeSummary, closing_lines, say, summary_line, verdicts_side_by_side
from neural_asm.client.transport import TRANSPORTS, ServiceError, check_url, served_digest
from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import SCORING
from neural_asm.pipelines.compliant import Gate, compliant_episode, digest_of, ensure_compliant_model
from neural_asm.pipelines.default_model import ensure_default_model, model_name
from neural_asm.runtime.home import home_path
from neural_asm.sim.config import CONTROLLERS, RATES, SIM
from neural_asm.sim.disturbances import FallingObject, elbow_hit
from neural_asm.sim.episode import Episode
from neural_asm.sim.faults import FaultSpec
from neural_asm.sim.paper import Job, run_episode
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


@dataclass(frozen=True)
class SimulatedRun:
    """What a client run simulates: ``episodes`` episodes of ``skill`` (seeds ``seed``, ``seed + 1``,
    ...), with the fault and falling object given, under ``controller`` (``correct``, compliant
    only: the memory's correction on), observed and streamed at ``rate`` Hz. The ``showcase`` (no
    fault, falling object or second episode given) streams the episode of ``seed`` twice, normal and
    with ``SHOWCASE_FAULT``, and prints both verdicts side by side: what the monitor is for, on a
    first run."""

    skill: str = SKILLS[0]
    seed: int = SIM.seeds.client
    fault: FaultSpec | None = None
    falling_object: FallingObject | None = None
    episodes: int = 1
    controller: str = SIM.controller
    correct: bool = False
    rate: float = SIM.timing.observation_hz
    showcase: bool = False

    def __post_init__(self) -> None:
        if self.rate not in RATES:
            raise ValueError(f"--rate must be one of {', '.join(map(str, RATES))} Hz, got {self.rate!r}")
        for name, value, known in (("skill", self.skill, SKILLS), ("controller", self.controller, CONTROLLERS)):
            if value not in known:
                raise ValueError(f"--{name} must be one of {', '.join(known)}, got {value!r}")
        if self.episodes < 1:
            raise ValueError(f"--episodes must be >= 1, got {self.episodes}")
        if self.showcase and (self.fault is not None or self.falling_object is not None or self.episodes != 1):
            raise ValueError("the showcase streams its own normal and faulty episode: give no fault, falling object "
                             "or --episodes with it")
        if self.correct and self.controller != "compliant":
            raise ValueError("--correct needs --controller compliant: the correction drives a compliant arm's "
                             "set-point (the stiff servos hold these hits alone)")

    def jobs(self) -> list[Job]:
        """The episodes in order."""
        if self.showcase:
            return [Job(self.skill, self.seed, fault=fault, rate=self.rate) for fault in (None, SHOWCASE_FAULT)]
        return [Job(self.skill, self.seed + i, self.fault, self.falling_object, self.rate)
                for i in range(self.episodes)]


def _simulate(run: SimulatedRun, job: Job, mode: str,
              monitor: tuple[NeuralASM, NeuralASM] | None) -> tuple[Episode, Outcome]:
    """The episode of ``job`` (stiff: the IK plan; compliant, ``monitor`` = (monitor, planner)
    given: the recalled plan, corrected with ``run.correct``) and what the arm did."""
    if monitor is None:
        ep, correction = run_episode(job.skill, job.seed, job.fault, job.disturbance, rate=job.rate), None
    else:
        ep, corrected = compliant_episode(monitor[0], job, Gate(mode, SCORING.default_fpr) if run.correct else None,
                                          monitor[1])
        correction = None if corrected is None else {"engaged_step": corrected.engaged_step,
                                                     "yielded_step": corrected.yielded_step}
    return ep, Outcome(run.controller, correction, ep.cube_error_m)


@contextlib.contextmanager
def _service(connection: Connection, models_dir: Path, out: Path, rate: float, quiet: bool) -> Iterator[Connection]:
    """The given service, or an embedded one on a free loopback port for the block's duration,
    hosting the default model at ``rate`` (built first if missing)."""
    if connection.url:
        yield connection
        return
    from neural_asm.service.embedded import start_embedded  # only to start it in-process
    from neural_asm.service.settings import Settings

    say(f"starting the service in-process (models: {models_dir}; the default Panda model at {rate:g} Hz is built "
        "on first run, which takes a few minutes)", quiet)
    ensure_default_model(models_dir, progress=not quiet, rate=rate)
    settings = Settings(models_dir=models_dir, recordings_dir=out, api_key=connection.api_key or None)
    with start_embedded(settings) as server:
        say(f"service at {server.url}", quiet)
        yield replace(connection, url=server.url)


def run_client(run: SimulatedRun = SimulatedRun(), connection: Connection = Connection(),
               options: StreamOptions = StreamOptions(), models_dir: Path | None = None,
               after_step: Callable[[int, int], None] | None = None) -> list[EpisodeSummary]:
    """Simulate the ``run``'s episodes and stream each to the service at ``connection`` (its URL,
    or one started here, on ``models_dir``, hosting the default model at the run's rate,
    ``panda`` or ``panda-40hz``, built on first use); ``options.mode`` defaults to the rate's
    served mode (`ScoringConfig.served_mode`). ``after_step(episode, step)`` is called after each scored step (tests use it
    to stop the service mid-episode). Stops after an episode the service was lost in.
    """
    rate, quiet = run.rate, options.quiet
    options = replace(options, mode=SCORING.served_mode(rate) if options.mode is None else options.mode)
    for name, value, known in (("mode", options.mode, MODES), ("transport", connection.transport, TRANSPORTS)):
        if value not in known:
            raise ValueError(f"--{name} must be one of {', '.join(known)}, got {value!r}")
    if connection.url:
        check_url(connection.url)
    out = Path(options.out)
    summaries: list[EpisodeSummary] = []
    models_dir = home_path("models") if models_dir is None else Path(models_dir)
    compliant = run.controller == "compliant"
    monitor_path, monitor = _compliant_monitor(models_dir, rate, quiet) if compliant else (None, None)
    with _service(connection, models_dir, out, rate, quiet) as service:
        session: dict = {"rate_hz": rate}
        if monitor_path is not None:
            if connection.url:
                _check_served(connection.url, connection.api_key, monitor_path)
            session |= {"model": monitor_path.stem, "fpr": SCORING.default_fpr}
        elif not connection.url or rate != SIM.timing.observation_hz:  # at 2 Hz a given service's default model
            session["model"] = model_name(rate)
        options = replace(options, out=out, session={**options.session, **session})
        jobs = run.jobs()
        for i, job in enumerate(jobs):  # each simulated once the previous one has been streamed
            ep, outcome = _simulate(run, job, options.mode, monitor)
            say(f"episode {i + 1}/{len(jobs)}: {job.skill}, seed {job.seed}, {rate:g} Hz, {run.controller} control"
                + (", corrected" if run.correct else "")
                + (f", fault {job.fault.to_dict()}" if job.fault else "")
                + (", falling object" if job.disturbance else "") + f", streaming to {service.url}", quiet)
            hook = None if after_step is None else (lambda k, i=i: after_step(i, k))
            s = stream_episode(simulated(ep, i + 1, outcome), service, options, hook)
            summaries.append(s)
            say(summary_line(s), quiet)
            if s.error:
                break
    if run.showcase:
        say(verdicts_side_by_side(summaries), quiet)
    say(closing_lines(summaries), quiet)
    return summaries
