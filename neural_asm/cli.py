"""The ``nasm`` command line: train, recall and score Neural ASMs, and everything else
the packages offer (simulated demonstrations, the service, the experiments)."""

from __future__ import annotations

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from neural_asm.data import DATA_HELP, SYNTHETIC
from neural_asm.logs.cli import SKIP_BAD_HELP, DataCommand, mapping_help
from neural_asm.models.config import PRESETS
from neural_asm.runtime.cli import Command, Lazy, fail, lazy_group
from neural_asm.runtime.home import home, home_path

if TYPE_CHECKING:
    from neural_asm.client.source import StreamedEpisode
    from neural_asm.models.asm import NeuralASM


# Every other command, imported when it runs (`nasm --help` loads neither torch nor MuJoCo):
# name -> where it is and the line the listing shows.
COMMANDS = {
    "faults": Lazy("neural_asm.experiments.fault_sweep.cli:faults", "The fault benchmark of --task; the other options "
                   "are the task's (nasm faults --task TASK --help).", pass_on=True),
    "demos": Lazy("neural_asm.sim.cli:demos", "Simulate episode sets and write <out>/<set>.mcap and <set>.npz."),
    "serve": Lazy("neural_asm.service.cli:serve", "Serve the models in --models-dir over HTTP and websocket (OpenAPI "
                  "docs at /docs)."),
    "client": Lazy("neural_asm.client.cli:client", "Simulate Panda episodes, stream them to the Neural ASM service and "
                   "record them."),
    "view": Lazy("neural_asm.recordings.cli:view", "Open a run's client and service recordings together in the Rerun "
                 "viewer, or screenshot them."),
    "replay": Lazy("neural_asm.client.cli:replay_command", "Stream recorded episodes to a running service exactly as the live "
                   "robot client does, after the same checks as ``nasm score`` against the served model; or, with "
                   "``--ros2``, play them onto a robot's ROS 2 bus for the monitor node (``nasm ros2``)."),
    "evaluate": Lazy("neural_asm.logs.cli:evaluate_command", "Faults-style evaluation on logs: faulty episodes detected, normal "
                     "ones flagged, AUROC."),
    "calibrate": Lazy("neural_asm.calibrate_cli:calibrate_command", "Calibrate a checkpoint's precisions and fault thresholds on "
                      "held-out normal episodes."),
    "correction": Lazy("neural_asm.experiments.cli:correction", "the memory's reactive correction of a falling-object "
                       "hit, stiff and compliant arms"),
    "contextual": Lazy("neural_asm.experiments.cli:contextual", "contextual inference (after Sheahan et al. 2016) against "
                       "BPTT-trained RNNs"),
    "ros2": Lazy("neural_asm.ros2.cli:ros2", "Monitor a robot on its ROS 2 bus: read the mapping's topics, judge each step "
                 "and publish the verdict on /diagnostics, nasm/fault and nasm/energy."),
    "logs": Lazy("neural_asm.logs_cli:app", "A robot's logs: what the commands would read from them."),
    "recordings": Lazy("neural_asm.recordings.cli:app", "Tools for the .rrd and .mcap recordings."),
    "experiments": Lazy("neural_asm.experiments.cli:app", "The paper's experiments and our benchmarks: list them, run "
                        "one."),
}


def play_on_ros2(episodes: Sequence[StreamedEpisode], mapping: Path, namespace: str, speed: float) -> int:
    """``nasm replay --ros2``'s player (``ros2.play``), handed to the client's replay command as the
    command line's context object: the client package stands below ros2 and cannot import it."""
    from neural_asm.ros2.cli import play

    return play(episodes, mapping, namespace, speed)


app = typer.Typer(cls=lazy_group(COMMANDS), help="Neural ASM: train, recall and score skill memories; simulate Panda demonstrations, serve "
                  "models, stream the client and run the experiments.", no_args_is_help=True,
                  pretty_exceptions_show_locals=False, context_settings={"obj": play_on_ros2})


def _load_model(path: Path) -> NeuralASM:
    from neural_asm.models import checkpoint

    try:
        return checkpoint.load(path)
    except checkpoint.CheckpointError as exc:
        raise fail(str(exc))


def _check_mode(mode: str) -> None:
    from neural_asm.models.recall import RECALL_MODES

    if mode not in RECALL_MODES:
        raise fail(f"--mode must be one of {', '.join(RECALL_MODES)}, got {mode!r}")


@app.command(cls=DataCommand)
def train(
    data: str = typer.Argument(SYNTHETIC, help=DATA_HELP),
    out: Path = typer.Option(home_path("models", "model.safetensors"), help="checkpoint to write"),
    preset: str = typer.Option("fast", help=f"hyper-parameter preset: {', '.join(PRESETS)}"),
    epochs: int | None = typer.Option(None, help="override the preset's epochs"),
    hidden: int | None = typer.Option(None, help="override the preset's hidden size"),
    seed: int = typer.Option(0, help="seed of the weights and the training order"),
    mapping: Path | None = typer.Option(None, help=mapping_help("DATA")),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    skill_cue: bool = typer.Option(False, "--skill-cue", help="also tell the network each demonstration's skill (its "
                                   "label: a mapping's skill or phase tag) by a cue, so that a session can be told "
                                   "the skill or infer it (needs at least two skills; nasm calibrate it before "
                                   "serving)"),
) -> None:
    """Train a Neural ASM on demonstrations and write a checkpoint."""
    from neural_asm.data import read_data
    from neural_asm.memory import SkillMemory

    if preset not in PRESETS:
        raise fail(f"--preset must be one of {', '.join(PRESETS)}, got {preset!r}")
    config = PRESETS[preset].with_(seed=seed)
    if epochs is not None:
        config = config.with_(epochs=epochs)
    if hidden is not None:
        config = config.with_(hidden_size=hidden)
    seqs = read_data(data, mapping, skip_bad)
    try:
        memory = SkillMemory.fit(seqs, preset=config, skill_cue=skill_cue)
    except ValueError as exc:  # data the preset cannot be fitted on, named before training
        raise fail(str(exc))
    memory.save(out)
    told = f", told the skills {', '.join(memory.skills)} by a cue" if memory.skills else ""
    typer.echo(f"trained on {len(seqs)} sequences at {seqs.rate_hz:g} Hz{told}; final energy "
               f"{memory.model.history[-1]:.4g}; wrote {out}")


@app.command(cls=DataCommand)
def recall(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors)"),
    data: str = typer.Argument(SYNTHETIC, help=f"sequences to cue from and compare with: {DATA_HELP}"),
    cue_steps: int = typer.Option(1, min=1, help="observations the recall is cued from"),
    mapping: Path | None = typer.Option(None, help=mapping_help("DATA")),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
) -> None:
    """Offline recall from the first observations; prints the error of each recalled sequence."""
    from neural_asm.data import read_data

    model = _load_model(model_path)
    seqs = read_data(data, mapping, skip_bad, model)
    steps = seqs.data.shape[1]
    plan = model.recall(seqs.data[:, :cue_steps], steps)
    err = model.normaliser.normalise(plan) - model.normaliser.normalise(seqs.data)
    mse = (err[:, cue_steps:] ** 2).mean(axis=(1, 2))
    for label in sorted(set(seqs.labels.tolist())):
        pick = seqs.labels == label
        typer.echo(f"{label:>16}: recall MSE {mse[pick].mean():.4f} (normalised units, {pick.sum()} sequences)")
    typer.echo(f"{'all':>16}: recall MSE {mse.mean():.4f}")


@app.command(cls=DataCommand)
def score(
    model_path: Path = typer.Argument(..., help="checkpoint (.safetensors)"),
    data: str = typer.Argument(SYNTHETIC, help=f"sequences to score: {DATA_HELP}"),
    mode: str | None = typer.Option(None, help="recall mode: offline or online (default: the model's served mode, "
                                    "offline at 2 Hz and online faster)"),
    cue_steps: int = typer.Option(1, min=1, help="observations the recall is cued from"),
    weighted: bool = typer.Option(True, help="precision-weight the errors (needs a calibration)"),
    as_json: bool = typer.Option(False, "--json", help="print per-step energies as JSON"),
    mapping: Path | None = typer.Option(None, help=mapping_help("DATA")),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
) -> None:
    """Energy of every step of every sequence, and the channel with the largest error."""
    import numpy as np

    from neural_asm.data import read_data

    if mode is not None:
        _check_mode(mode)
    model = _load_model(model_path)
    seqs = read_data(data, mapping, skip_bad, model)
    try:
        result = model.score(seqs.data, model.served_mode if mode is None else mode, cue_steps, weighted)
    except (KeyError, ValueError) as exc:
        raise fail(str(exc.args[0]))
    if as_json:
        typer.echo(json.dumps({"energy": result.energy.round(6).tolist()}))
        return
    worst = np.abs(result.errors).max(axis=1).argmax(axis=1)
    for i, e in enumerate(result.energy):
        typer.echo(
            f"{i:4d} {seqs.labels[i]:>12}: mean energy {e.mean():8.3f}, peak {e.max():8.3f} at step "
            f"{e.argmax():2d}, largest error in {model.channel_names[worst[i]]}"
        )


@app.command(cls=Command)
def info(model_path: Path | None = typer.Argument(None, help="checkpoint (.safetensors); none: the data home")) -> None:
    """Print a checkpoint's configuration, channels, calibrations and provenance; without one,
    where the data home is (NASM_HOME) and what it holds."""
    if model_path is None:
        root = home()
        folders = sorted(p.name for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
        typer.echo(json.dumps({"data_home": str(root), "set_by": "NASM_HOME" if os.environ.get("NASM_HOME") else
                               "the platform's user data folder (set NASM_HOME to move it)", "holds": folders}, indent=2))
        return
    model = _load_model(model_path)
    summary = {
        "config": model.config.to_dict(),
        "rate_hz": model.rate_hz,
        "channels": list(model.channel_names),
        "calibrations": {
            k: {"source": c.source, "whitened": c.error_precision is not None, "thresholds": c.thresholds}
            for k, c in model.calibrations.items()
        },
        "provenance": model.provenance,
        "epochs_trained": len(model.history),
        "final_energy": model.history[-1] if model.history else None,
    }
    typer.echo(json.dumps(summary, indent=2, default=str))


if __name__ == "__main__":
    app()
