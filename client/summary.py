"""What the client prints and returns: one line per scored step, one summary per episode."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any


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
    """One aligned line per step; the isolated joint is named only on a flagged step."""
    verdict = f"FAULT  joint={line.isolated_joint or '-'}" if line.fault else "ok"
    return (f"step {line.step:2d}  t={line.time_s:4.1f}s  energy={line.energy:10.4g}  "
            f"threshold={line.threshold:8.4g}  ({line.inference_ms:4.1f} ms)  {verdict}")


def closing_lines(summaries: list[EpisodeSummary]) -> str:
    """Totals over the run and the command that opens its recordings (client and service files together)."""
    flagged = sum(s.detected for s in summaries)
    faulty = sum(s.fault is not None or s.disturbance is not None for s in summaries)
    rrd = [s.recordings["rrd"] for s in summaries if "rrd" in s.recordings]
    rrd += [p for s in summaries for p in s.service_recordings.values() if p.endswith(".rrd")]
    mcap = [s.recordings["mcap"] for s in summaries if "mcap" in s.recordings]
    mcap += [p for s in summaries for p in s.service_recordings.values() if p.endswith(".mcap")]
    lines = [f"done: {len(summaries)} episode(s), {faulty} with a fault or disturbance, {flagged} flagged"]
    if rrd:
        lines.append("open in Rerun:   rerun " + " ".join(rrd))
    if mcap:
        lines.append("MCAP (Foxglove): " + " ".join(mcap))
    return "\n".join(lines)


def say(text: str, quiet: bool) -> None:
    if not quiet:
        print(text, flush=True)
