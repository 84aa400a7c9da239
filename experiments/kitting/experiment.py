"""The kitting benchmark as a registered experiment: `run_kitting(KittingRun) -> KittingReport`,
whose report the shared writer makes into fault_sweep.json, fault_sweep.md, the figures and the
timeline recording."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from neural_asm.experiments.kitting.config import KittingRun
from neural_asm.experiments.kitting.report import markdown, write_figures
from neural_asm.experiments.kitting.run import PUBLISHED, KittingResult, run
from neural_asm.experiments.writer import headline_first

FIGURES = ("auroc_vs_delta.png", "timeline.png", "timeline.rrd")
PUBLISHED_CELL = f"Wu et al. 2022: {PUBLISHED['paper']['figure']} (whole segments, split by segment)"


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
            f"{100 * runs['clean_phases_flagged']:.0f} % of clean phases flagged")
