"""The served step of a 7-skill memory not told the skill, against today's single model's.

7 synthetic skills (``models.synthetic.make_skills``: 10 demonstrations each, 40 steps, 12
channels), one network of the default configuration (hidden 256, two Gauss-Newton steps) trained
briefly (a step's cost does not depend on how long it trained): once as the single model the
service has served so far, once with a skill cue (``SkillMemory.fit(..., skill_cue=True)``). Both
are calibrated on held-out episodes of every skill and monitored as the service's sessions
step (``SkillMemory.monitor``: the single model's streamed step, ``step_streams``; the skill
memory's ``served_step`` of a ``SkillSession``, one row of online recall per skill and the
posterior over the 7 skills). The same held-out observations are stepped by each, in
alternating rounds, in the same run.

``posterior_vs_single`` = the single model's step time / the skill memory's not told: 0.5 is
twice the cost. The single model is timed in offline recall, what a session gets when it names
no mode, and in online recall (``posterior_vs_single_online``); ``told_vs_single`` is the
skill memory told the skill (one row). Times are CPU time, and ratios, because these machines
are shared and noisy: each ratio is the median over rounds of the ratio within a round. One JSON object is the last line.

    python benchmarks/bench_skills.py [--rounds 15] [--quick]

``--quick``: a tiny network and two rounds of a few episodes, in seconds; the test suite runs it
so the script keeps working (its numbers mean nothing).
"""

from __future__ import annotations

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from neural_asm import SkillMemory
from neural_asm.memory import Monitor
from neural_asm.models.config import FAST
from neural_asm.models.kernels import compile_now
from neural_asm.models.synthetic import make_skills

SKILLS, STEPS, CHANNELS = 7, 40, 12


def step_ms(monitor: Callable[[], Monitor], episodes: np.ndarray) -> float:
    """CPU milliseconds per served step over every observation of ``episodes``, a new monitor for
    each: this process's CPU time, so that the time it waits for a core of a shared machine does
    not count (the steps run on one thread)."""
    start = time.process_time()
    for episode in episodes:
        stepping = monitor()
        for x in episode:
            stepping.step(x)
    return (time.process_time() - start) / (episodes.shape[0] * episodes.shape[1]) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=15, help="alternating timing rounds")
    parser.add_argument("--quick", action="store_true",
                        help="tiny sizes (seconds, not minutes): checks the script runs, measures nothing")
    args = parser.parse_args()
    config = FAST.with_(hidden_size=16, epochs=2) if args.quick else FAST.with_(epochs=100)
    rounds, timed = (2, 2) if args.quick else (args.rounds, 3)  # rounds, and episodes stepped per round and model

    data = make_skills(n_skills=SKILLS, repetitions=14, steps=STEPS, channels=CHANNELS, seed=7)
    data = replace(data, labels=np.array([f"skill{k}" for k in data.labels]))
    held = np.arange(len(data)) % 14 >= 10  # the last 4 repetitions of every skill: calibration and timing
    demos, normal = data.take(~held), data.take(held)

    compile_now()  # a fresh install compiles the kernels once: not step time
    print(f"training the single model and the {SKILLS}-skill memory ...", flush=True)
    single = SkillMemory.fit(demos, preset=config, progress=False)
    single.calibrate(normal)
    memory = SkillMemory.fit(demos, preset=config, progress=False, skill_cue=True)
    memory.calibrate(normal)

    episodes = normal.data[np.arange(len(normal)) % 4 == 0][:timed]
    told_skill = str(normal.labels[0])
    monitors: dict[str, Callable[[], Monitor]] = {
        "single_offline": lambda: single.monitor("offline"),
        "single_online": lambda: single.monitor("online"),
        "posterior": lambda: memory.monitor(),
        "told": lambda: memory.monitor(skill=told_skill),
    }
    for monitor in monitors.values():  # warm every path once
        step_ms(monitor, episodes[:1])
    print(f"timing {rounds} rounds of {len(episodes)} episodes x {STEPS} steps each ...", flush=True)
    times = {name: [] for name in monitors}
    for _ in range(rounds):
        for name, monitor in monitors.items():
            times[name].append(step_ms(monitor, episodes))
    per_round = {name: np.array(t) for name, t in times.items()}

    def ratio(single_name: str, other: str) -> float:
        return round(float(np.median(per_round[single_name] / per_round[other])), 3)

    result = {
        "skills": SKILLS,
        "steps_timed_per_round": int(episodes.shape[0] * episodes.shape[1]),
        "rounds": rounds,
        "hidden_size": config.hidden_size,
        **{f"step_ms_{name}": round(float(np.median(t)), 4) for name, t in per_round.items()},
        "posterior_vs_single": ratio("single_offline", "posterior"),
        "posterior_vs_single_online": ratio("single_online", "posterior"),
        "told_vs_single": ratio("single_offline", "told"),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
