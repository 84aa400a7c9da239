"""A client run: the service (the given URL, or one started in-process), then each episode
simulated and streamed."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Callable, Iterator

from client.stream import stream_episode
from client.summary import EpisodeSummary, closing_lines, say, summary_line
from client.transport import TRANSPORTS, check_url
from recordings import DEFAULT_DIR
from runtime.home import home_path
from sim.config import SIM
from sim.disturbances import FallingObject
from sim.faults import FaultSpec
from sim.runner import run_episode
from sim.skills import SKILLS

MODES = ("offline", "online")


def fault_spec(joint: int | None, time_s: float | None, overshoot_deg: float | None) -> FaultSpec | None:
    """The fault the three ``--fault-*`` options describe: all three or none."""
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

    say(f"starting the service in-process (models: {models_dir}; the default Panda model is built on "
        "first run, which takes a few minutes)", quiet)
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
    mode: str = "offline",
    out: Path = DEFAULT_DIR,
    reconnect: bool = False,
    transport: str = "ws",
    models_dir: Path | None = None,
    quiet: bool = False,
    after_step: Callable[[int, int], None] | None = None,
) -> list[EpisodeSummary]:
    """Simulate ``episodes`` episodes (seeds ``seed``, ``seed + 1``, ...) and stream each to the service.

    ``after_step(episode, step)`` is called after each scored step (tests use it to stop
    the service mid-episode). Stops after an episode the service was lost in.
    """
    for name, value, known in (("skill", skill, SKILLS), ("mode", mode, MODES), ("transport", transport, TRANSPORTS)):
        if value not in known:
            raise ValueError(f"--{name} must be one of {', '.join(known)}, got {value!r}")
    if episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {episodes}")
    if url:
        check_url(url)
    out = Path(out)
    summaries: list[EpisodeSummary] = []
    models_dir = home_path("models") if models_dir is None else Path(models_dir)
    with _service(url, api_key, models_dir, out, quiet) as service_url:
        for i in range(episodes):
            ep = run_episode(skill, seed + i, fault=fault, disturbance=falling_object)
            say(f"episode {i + 1}/{episodes}: {skill}, seed {seed + i}"
                + (f", fault {fault.to_dict()}" if fault else "")
                + (", falling object" if falling_object else "") + f", streaming to {service_url}", quiet)
            hook = None if after_step is None else (lambda k, i=i: after_step(i, k))
            s = stream_episode(ep, i + 1, service_url, api_key, mode, out, transport, reconnect, quiet, hook)
            summaries.append(s)
            say(summary_line(s), quiet)
            if s.error:
                break
    say(closing_lines(summaries), quiet)
    return summaries
