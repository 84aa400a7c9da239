"""Contextual inference end to end: the protocol's summary, its table and its figures."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from neural_asm.experiments.contextual import report
from neural_asm.experiments.contextual.config import ContextualConfig, ContextualRun
from neural_asm.experiments.contextual.protocol import run_protocol
from neural_asm.models.config import PRESETS


@dataclass(frozen=True)
class ContextualResult:
    summary: dict[str, Any]  # contextual.json: PEAD, separations, the K sweep, energy vs skills, the setup
    protocol: ContextualConfig

    stem: ClassVar[str] = "contextual"

    def to_json(self) -> dict[str, Any]:
        return self.summary

    def markdown(self) -> str:
        return report.markdown(self.summary)

    def files(self, out: Path) -> list[Path]:
        from neural_asm.experiments.contextual import figures
        from neural_asm.experiments.contextual.dataset import conditions_data

        cfg = self.protocol
        return [figures.dataset_figure(conditions_data(0, cfg, False), cfg, out / "dataset.png"),
                figures.pead_figure(self.summary, out / "pead.png"),
                figures.hand_paths_figure(self.summary, cfg, out / "hand_paths.png"),
                figures.speed_accuracy_figure(self.summary, out / "recall_vs_iterations.png"),
                figures.energy_figure(self.summary, out / "energy_vs_skills.png")]


def run_contextual(config: ContextualRun) -> ContextualResult:
    protocol = config.protocol
    return ContextualResult(run_protocol(protocol, PRESETS[config.preset], config.workers, backend=config.backend),
                            protocol)
