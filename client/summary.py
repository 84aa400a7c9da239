"""What the client prints and returns: one line per scored step, one summary per episode."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

from neural_asm.models.answer import StepAnswer
from neural_asm.sim.config import SIM


@dataclass
class StepLine:
    step: int
    time_s: float
    energy: float
    threshold: float
    fault: bool
    isolated_joint: str | None
    inference_ms: float
    skill: str | None = None  # recognised by the service at this step

    @classmethod
    def of(cls, answer: StepAnswer, step: int, time_s: float) -> StepLine:
        """The line of the service's answer to the episode's step ``step``, observed at ``time_s``."""
        ms = float("nan") if answer.inference_ms is None else answer.inference_ms
        return cls(step, time_s, answer.energy, answer.threshold, answer.fault, answer.isolated_joint, ms, answer.skill)


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
    controller: str | None = None  # the simulated arm's joint controller (None: a replayed log)
    cube_error_m: float | None = None  # the cube's distance from its target at the end (None: a replayed log)
    correction: dict | None = None  # with --correct: {"engaged_step": int | None, "yielded_step": int | None}

    @property
    def energies(self) -> list[float]:
        return [s.energy for s in self.steps]

    @property
    def placed(self) -> bool | None:
        """Cube within the success tolerance of its target (None: not simulated)."""
        return None if self.cube_error_m is None else self.cube_error_m < SIM.success_tolerance_m

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _disturbance(d: dict) -> str:
    momentum = d["mass_kg"] * d["speed_m_s"]
    return f"falling object {d['mass_kg']:g} kg at {d['speed_m_s']:g} m/s ({momentum:g} kg m/s) at {d['release_s']:g} s"


def _verdict(s: EpisodeSummary) -> str:
    if s.detected:
        flag = next(line for line in s.steps if line.step == s.first_flag_step)
        return (f"DETECTED at step {s.first_flag_step} (t={s.first_flag_time_s:g} s, energy {flag.energy:.4g} > "
                f"threshold {flag.threshold:.4g}), isolated joint: {s.isolated_joint or 'none'}")
    verdict = "not detected" if s.completed else "not detected in the steps scored"
    if s.steps:
        peak = max(s.steps, key=lambda line: line.energy)
        verdict += f" (peak energy {peak.energy:.4g} at step {peak.step}, threshold {peak.threshold:.4g})"
    return verdict


def _outcome(s: EpisodeSummary) -> list[str]:
    """What the arm did: the correction, then where the cube ended (simulated episodes only)."""
    out = []
    if s.correction is not None:
        engaged, yielded = s.correction["engaged_step"], s.correction["yielded_step"]
        out.append("not corrected (the monitor never flagged)" if engaged is None else
                   f"corrected from step {engaged}" + (f", let go at step {yielded} (a joint near its torque limit)"
                                                       if yielded is not None else ""))
    if s.cube_error_m is not None:
        tolerance = f"{SIM.success_tolerance_m * 100:g} cm"
        out.append(f"cube {s.cube_error_m * 1000:.1f} mm from its target: "
                   + (f"placed (within {tolerance})" if s.placed else f"NOT placed (beyond {tolerance})"))
    return out


def summary_line(s: EpisodeSummary) -> str:
    what = f"{s.skill} seed {s.seed}"
    if s.controller:
        what += f", {s.controller} control"
    if s.fault:
        f = s.fault
        what += f", fault joint{f['joint']} {f['overshoot_deg']:+g} deg at {f['time_s']:g} s (step {s.fault_step})"
    if s.disturbance:
        what += ", " + _disturbance(s.disturbance)
    tail = f"{s.steps_scored}/{s.steps_total} steps scored"
    if s.reconnects:
        tail += f", {s.reconnects} reconnect(s)"
    if s.error:
        tail += f", INTERRUPTED: {s.error}"
    return f"summary: episode {s.episode} ({what}): " + "; ".join([_verdict(s), *_outcome(s), tail])


def _column(s: EpisodeSummary) -> list[str]:
    """One episode's cells of ``verdicts_side_by_side``."""
    if s.fault:
        f = s.fault
        title = f"joint {f['joint']} locked ({f['overshoot_deg']:+g} deg at {f['time_s']:g} s)"
    else:
        title = "normal" if s.disturbance is None else "falling object"
    flag = (f"step {s.first_flag_step} (t={s.first_flag_time_s:g} s)" if s.detected else
            "-" if s.completed else "- (not every step scored)")
    cube = "-" if s.cube_error_m is None else f"{'yes' if s.placed else 'NO'} ({s.cube_error_m * 1000:.1f} mm off)"
    return [title, "YES" if s.detected else "no", flag, s.isolated_joint or "-", cube]


def verdicts_side_by_side(summaries: list[EpisodeSummary]) -> str:
    """The episodes' verdicts in columns: flagged or not, when, the isolated joint, the cube."""
    rows = ["episode", "flagged", "first flag", "isolated joint", "cube placed"]
    columns = [_column(s) for s in summaries]
    widths = [max(len(c) for c in cells) for cells in [rows, *columns]]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip([row, *(c[i] for c in columns)], widths)).rstrip()
             for i, row in enumerate(rows)]
    return "\n".join(["", *lines, ""])


def step_line(line: StepLine) -> str:
    """One aligned line per step; the isolated joint is named only on a flagged step."""
    verdict = f"FAULT  joint={line.isolated_joint or '-'}" if line.fault else "ok"
    return (f"step {line.step:3d}  t={line.time_s:5.3f}s  energy={line.energy:10.4g}  "
            f"threshold={line.threshold:8.4g}  ({line.inference_ms:4.1f} ms)  {verdict}")


def closing_lines(summaries: list[EpisodeSummary]) -> str:
    """Totals over the run and the command that opens its recordings (client and service files together)."""
    flagged = sum(s.detected for s in summaries)
    faulty = sum(s.fault is not None or s.disturbance is not None for s in summaries)
    rrd = [s.recordings["rrd"] for s in summaries if "rrd" in s.recordings]
    rrd += [p for s in summaries for p in s.service_recordings.values() if p.endswith(".rrd")]
    mcap = [s.recordings["mcap"] for s in summaries if "mcap" in s.recordings]
    mcap += [p for s in summaries for p in s.service_recordings.values() if p.endswith(".mcap")]
    done = f"done: {len(summaries)} episode(s), {faulty} with a fault or disturbance, {flagged} flagged"
    corrected = [s for s in summaries if s.correction is not None]
    if corrected:
        done += f", {sum(s.correction['engaged_step'] is not None for s in corrected)} corrected"  # type: ignore[index]
    simulated = [s for s in summaries if s.placed is not None]
    if simulated:
        done += f", {sum(bool(s.placed) for s in simulated)}/{len(simulated)} cubes placed"
    lines = [done]
    if rrd:
        lines.append("open in Rerun:   rerun " + " ".join(rrd))
    if mcap:
        lines.append("MCAP (Foxglove): " + " ".join(mcap))
    return "\n".join(lines)


def say(text: str, quiet: bool) -> None:
    if not quiet:
        print(text, flush=True)
