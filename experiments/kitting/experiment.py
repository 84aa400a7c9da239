"""The kitting benchmark as a registered experiment: `run_kitting(KittingRun) -> KittingReport`,
whose report the shared writer makes into fault_sweep.json, fault_sweep.md, the figures and the
timeline recording."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterable

from neural_asm.experiments.kitting.config import KittingRun
from neural_asm.experiments.kitting.report import markdown, write_figures
from neural_asm.experiments.kitting.run import PUBLISHED, KittingResult, run
from neural_asm.experiments.writer import headline_first

FIGURES = ("auroc_vs_delta.png", "timeline.png", "timeline.rrd")
PUBLISHED_CELL = f"Wu et al. 2022: {PUBLISHED['paper']['figure']} (whole segments, split by segment)"


@dataclass(frozen=True)
class Target:
    """One of the benchmark's targets for the featured network, its value ``read`` from the
    headline (None where the run could not measure it)."""

    name: str
    read: Callable[[dict[str, Any]], float | None]
    bound: float
    at_least: bool  # a floor (True) or a ceiling
    unit: str  # "", "%" (fractions shown in percent) or "ms"

    def miss(self, headline: dict[str, Any]) -> str | None:
        """What the measured value misses the bound by ("name >= bound by ..."), or None."""
        value = self.read(headline)
        if value is None:
            return None
        short = self.bound - value if self.at_least else value - self.bound
        if short <= 0:
            return None
        shown = {"%": (f"{100 * self.bound:g} %", f"{100 * short:.2g} points"),
                 "ms": (f"{self.bound:g} ms", f"{short:.0f} ms")}
        bound, by = shown.get(self.unit, (f"{self.bound:g}", f"{short:.2g}"))
        return f"{self.name} {'>=' if self.at_least else '<='} {bound} by {by}"


def _one(h: dict[str, Any]) -> dict[str, Any]:
    return h["methods"][h["featured"]]


def _lowest(values: Iterable[float | None]) -> float | None:
    measured = [v for v in values if v is not None]
    return min(measured) if measured else None


TARGETS = (
    Target("mean AUROC", lambda h: _one(h)["auroc"]["0.5"], 0.99, True, ""),
    Target("every anomaly type's AUROC", lambda h: _lowest(t["auroc_0.5"] for t in _one(h)["per_type"].values()
                                                           if t["n"] >= 5), 0.95, True, ""),
    Target("balanced accuracy", lambda h: _lowest(s.get("balanced_accuracy") for s in _one(h)["per_skill"].values()
                                                  if s["n_normal_train"] >= 40), 0.94, True, ""),
    Target("detected", lambda h: _one(h)["detected_1pct"], 0.95, True, "%"),
    Target("normal flagged", lambda h: _one(h)["normal_flagged_1pct"], 0.02, False, "%"),
    Target("median delay", lambda h: _one(h)["delay_ms_median"], 100.0, False, "ms"),
    Target("whole-run anomalies flagged within 1 s", lambda h: h["whole_runs"]["flagged_within_1s"], 0.90, True, "%"),
    Target("flagged early", lambda h: h["whole_runs"]["flagged_early"], 0.05, False, "%"),
    Target("clean phases flagged", lambda h: h["whole_runs"]["clean_phases_flagged"], 0.05, False, "%"),
    Target("skill recognised", lambda h: h["whole_runs"]["skill_recognised"], 0.95, True, "%"),
)


@dataclass(frozen=True)
class KittingReport:
    result: KittingResult

    stem: ClassVar[str] = "fault_sweep"

    def to_json(self) -> dict[str, Any]:
        return headline_first(self.result)

    def markdown(self) -> str:
        return markdown(self.result)

    def files(self, out: Path) -> list[Path]:
        write_figures(self.result, out)
        return [out / name for name in FIGURES] + [Path(self.result.model_path)]


def run_kitting(options: KittingRun) -> KittingReport:
    config = options.config()
    config.out.mkdir(parents=True, exist_ok=True)  # the model is saved as the run goes
    return KittingReport(run(config))


def headline(doc: dict[str, Any]) -> str:
    """The README's cell: the featured network half a second after the onset on one split, its
    weakest skill and anomaly type, the strongest rival, and the whole runs through the product."""
    h, delta = doc["headline"], "0.5"
    one, paired, runs = h["methods"][h["featured"]], h["paired"], h["whole_runs"]
    skill = min(one["per_skill"], key=lambda s: one["per_skill"][s]["auroc"][delta])
    kind = min(one["per_type"], key=lambda t: one["per_type"][t]["auroc_0.5"])
    rival = h["methods"][paired["baseline"]]
    return (f"one network not told the skill, {one['trainings']} trainings, run-wise split "
            f"{doc['split']['seed']} (others: docs), 0.5 s after the onset: mean AUROC over "
            f"skills {', '.join(one['per_skill'])} {one['auroc'][delta]:.2f} (skill {skill} "
            f"{one['per_skill'][skill]['auroc'][delta]:.2f}, {kind} {one['per_type'][kind]['auroc_0.5']:.2f}); "
            f"{100 * one['detected_1pct']:.0f} % detected and {100 * one['normal_flagged_1pct']:.1f} % of normal "
            f"segments flagged at the served 1 % threshold; strongest rival {paired['baseline']} "
            f"{rival['auroc'][delta]:.2f} (p = {paired['p_value']:.2g}); whole runs through `nasm replay` to `nasm serve`: "
            f"{100 * runs['flagged_within_1s']:.0f} % of anomalies flagged within 1 s, "
            f"{100 * runs['clean_phases_flagged']:.0f} % of clean phases flagged. Targets missed (why, and the "
            f"experiments that show it: the report's \"Against the targets\"): " + "; ".join(_misses(h)))


def _misses(h: dict[str, Any]) -> list[str]:
    misses = [m for t in TARGETS if (m := t.miss(h)) is not None]
    paired = h["paired"]
    if paired["baseline_only"] > paired["nasm_only"] and paired["p_value"] < 0.01:
        misses.append(f"no rival significantly ahead: {paired['baseline']} is (p = {paired['p_value']:.2g})")
    return misses
