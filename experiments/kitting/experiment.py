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


def _one(h: dict[str, Any], row: str = "featured") -> dict[str, Any]:
    return h["methods"][h[row]]


def _lowest(values: Iterable[float | None]) -> float | None:
    measured = [v for v in values if v is not None]
    return min(measured) if measured else None


def _highest(values: Iterable[float | None]) -> float | None:
    measured = [v for v in values if v is not None]
    return max(measured) if measured else None


def _each_split(h: dict[str, Any], row: str, key: str) -> list[float | None]:
    """``key`` of the ``row`` (featured or featured_told) on each split."""
    return [methods[h[row]][key] for methods in h["by_split"].values()]


def _other_types(h: dict[str, Any]) -> float | None:
    return _lowest(t["auroc_0.5"] for name, t in _one(h)["per_type"].items() if t["n"] >= 5 and name != "no_object")


def _operating(row: str, told: str) -> tuple[Target, ...]:
    """The served operating point's targets of both rows, on every split."""
    return (Target(f"detected ({told}, every split)", lambda h: _lowest(_each_split(h, row, "detected_1pct")), 0.85,
                   True, "%"),
            Target(f"normal flagged ({told}, every split)", lambda h: _highest(_each_split(h, row, "normal_flagged_1pct")),
                   0.02, False, "%"),
            Target(f"median delay ({told})", lambda h: _one(h, row)["delay_ms_median"], 100.0, False, "ms"),
            Target(f"p95 delay ({told})", lambda h: _one(h, row)["delay_ms_p95"], 500.0, False, "ms"))


TARGETS = (
    Target("mean AUROC (not told, every split)", lambda h: _lowest(_each_split(h, "featured", "auroc")), 0.97, True, ""),
    Target("no_object's AUROC (not told)", lambda h: _one(h)["per_type"].get("no_object", {}).get("auroc_0.5"), 0.90,
           True, ""),
    Target("every other anomaly type's AUROC (not told)", _other_types, 0.95, True, ""),
    Target("mean AUROC (told)", lambda h: _one(h, "featured_told")["auroc"]["0.5"], 0.98, True, ""),
    *_operating("featured", "not told"),
    *_operating("featured_told", "told"),
    Target("whole-run anomalies flagged within 1 s (not told)", lambda h: h["whole_runs"]["flagged_within_1s"], 0.80,
           True, "%"),
    Target("flagged early (not told)", lambda h: h["whole_runs"]["flagged_early"], 0.05, False, "%"),
    Target("clean phases flagged (not told)", lambda h: h["whole_runs"]["clean_phases_flagged"], 0.05, False, "%"),
    Target("skill served right (skills with >= 20 demonstrations)",
           lambda h: h["whole_runs"]["skill_recognised_demonstrated"], 0.90, True, "%"),
    Target("whole-run anomalies flagged within 1 s (told)", lambda h: h["whole_runs_told"]["flagged_within_1s"], 0.90,
           True, "%"),
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
    """The README's cell: the skill memory not told the skill and told it, half a second after the
    onset on the run-wise splits, its weakest anomaly type, the strongest rivals, and the whole runs
    through the product."""
    h, delta = doc["headline"], "0.5"
    one, told, runs = _one(h), _one(h, "featured_told"), h["whole_runs"]
    kind = min(one["per_type"], key=lambda t: one["per_type"][t]["auroc_0.5"])
    splits = ", ".join(map(str, h["splits"]))
    rivals = "; ".join(f"strongest rival {'told' if key.endswith('told') else 'not told'} {h[key]['baseline']} "
                       f"{h['methods'][h[key]['baseline']]['auroc'][delta]:.2f} (p = {h[key]['p_value']:.2g})"
                       for key in ("paired", "paired_told"))
    matched = "; ".join(f"{h[key]['baseline']} p = {h[key]['p_value']:.2g}"
                        for key in ("paired_cross_fitted", "paired_told_cross_fitted") if key in h) or "not run"
    return (f"one skill memory (one network told each demonstration's skill by a cue, each skill's course and "
            f"dynamics), {one['trainings']} trainings over run-wise splits {splits}, 0.5 s after the onset: not told "
            f"the skill, mean AUROC over skills {', '.join(one['per_skill'])} {one['auroc'][delta]:.2f} ({kind} "
            f"{one['per_type'][kind]['auroc_0.5']:.2f}), {100 * one['detected_1pct']:.0f} % detected and "
            f"{100 * one['normal_flagged_1pct']:.1f} % of normal segments flagged at the served 1 % threshold; told, "
            f"{told['auroc'][delta]:.2f}, {100 * told['detected_1pct']:.0f} % and {100 * told['normal_flagged_1pct']:.1f} %; "
            f"{rivals} (at the memory's cross-fitted threshold rule: {matched}); whole runs through `nasm replay` to `nasm serve`, not told: "
            f"{100 * runs['flagged_within_1s']:.0f} % of anomalies flagged within 1 s, "
            f"{100 * runs['clean_phases_flagged']:.0f} % of clean phases flagged. Targets missed (why, and the "
            f"experiments that show it: the report's \"Against the targets\"): " + "; ".join(_misses(h)))


def _misses(h: dict[str, Any]) -> list[str]:
    misses = [m for t in TARGETS if (m := t.miss(h)) is not None]
    for key in ("paired", "paired_told"):
        paired = h[key]
        if paired["baseline_only"] > paired["nasm_only"] and paired["p_value"] < 0.01:
            misses.append(f"no rival {'told' if key.endswith('told') else 'not told'} significantly ahead: "
                          f"{paired['baseline']} is (p = {paired['p_value']:.2g})")
    return misses
