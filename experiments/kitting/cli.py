"""``nasm faults --task kitting``: run the benchmark and write its report (called by fault_sweep's cli)."""

from __future__ import annotations

from pathlib import Path

import typer

from neural_asm.experiments.kitting.config import KITTING_NETWORK, KittingConfig
from neural_asm.experiments.kitting.report import markdown, write_figures, write_json
from neural_asm.experiments.kitting.run import run
from neural_asm.logs.errors import LogError
from neural_asm.models.config import TPCConfig


def run_kitting(data: Path, out: Path, trainings: int, network: TPCConfig = KITTING_NETWORK) -> None:
    """The benchmark into ``out``; ``network`` the one network's (and the per-skill networks') size
    and training (docs/kitting.md measures a larger one)."""
    if not (data / "successful_skills").is_dir():
        raise LogError(f"{data} has no successful_skills folder: give the clone's "
                       "'anomaly_detection_feature_selection_folder/No.0 filtering scheme' folder")
    out.mkdir(parents=True, exist_ok=True)
    result = run(KittingConfig(data=data, out=out, trainings=trainings, network=network))
    write_json(result, out / "fault_sweep.json")
    (out / "fault_sweep.md").write_text(markdown(result))
    write_figures(result, out)
    typer.echo((out / "fault_sweep.md").read_text())
    typer.echo(f"wrote {out} in {result.seconds:.0f} s")
