"""``nasm faults``: the paper's systematic fault evaluation, or the varied-task benchmark, in one command."""

from __future__ import annotations

import json
import time
from enum import Enum
from pathlib import Path

import typer

from neural_asm.runtime.cli import Command, Group
from neural_asm.experiments.plotting import require_matplotlib
from neural_asm.models.config import FAITHFUL
from neural_asm.pipelines.episodes import SetMismatch
from neural_asm.runtime.home import home_path
from neural_asm.runtime.parallel import Backend, Parallel
from neural_asm.sim.dataset import set_folder
from neural_asm.sim.cli import RATE_HELP, Task, check_rate
from neural_asm.sim.config import SIM

# The paper's batch-1 training over 160 varied demonstrations costs ~3 s per epoch here: the
# varied benchmark caps the paper-configured network's epochs to stay within minutes.
VARIED_PAPER_EPOCHS = 40

app = typer.Typer(cls=Group)


class FaultTask(str, Enum):
    """The simulated tasks (``nasm demos --task``) and the real robots' datasets."""

    paper = Task.paper.value
    varied = Task.varied.value
    kitting = "kitting"
    voraus = "voraus"


class Context(str, Enum):
    observed = "observed"
    hidden = "hidden"


@app.command(cls=Command)
def faults(
    task: FaultTask = typer.Option(FaultTask.paper, help="paper: the 980 joint locks of the paper's fixed task; varied: "
                                   "four skills whose cube, goal, speed and obstacle vary, with nine fault families; "
                                   "kitting: a real Baxter's labelled failures (--data: the clone's 'No.0 filtering "
                                   "scheme' folder); voraus: voraus-AD (--data: its parquet file)"),
    context: Context = typer.Option(Context.observed, help="varied task: whether the goal is an observed channel"),
    rate: int = typer.Option(int(SIM.timing.observation_hz), help=f"{RATE_HELP} At 40 Hz: the served monitor at 40 "
                             "and 2 Hz on the joint locks and the falling object, with latency (no baselines)",
                             callback=check_rate),
    out: Path | None = typer.Option(None, help="output folder (default: fault_sweep, varied_<context> in the data home)"),
    data: Path | None = typer.Option(None, help="episode sets, simulated when missing (default: data, data_varied in the data home)"),
    paper_epochs: int = typer.Option(FAITHFUL.epochs, help="epochs of the paper-configuration model"),
    fast_epochs: int | None = typer.Option(None, help="override the default model's epochs"),
    ablation: bool = typer.Option(False, "--ablation", help="varied task: train one Neural ASM per lever "
                                  "(experiments/varied/ablation.py) and write ablation.json and ablation.md"),
    ceiling: bool = typer.Option(False, "--ceiling", help="varied task: score two oracles that know each episode's "
                                 "exact context (experiments/varied/ceiling.py); write ceiling.json and ceiling.md"),
    diagnostic: bool = typer.Option(False, "--diagnostic", help="varied task: train the default network by its "
                                    "Hebbian rule and by BPTT (a measurement beyond the paper, "
                                    "experiments/varied/diagnostic.py), --seeds trainings each, against the best linear "
                                    "one-step predictor; write diagnostic.json and diagnostic.md"),
    seeds: int = typer.Option(3, min=1, help="trainings per learner (--diagnostic), per variant (--ablation) or "
                              "per rate (--rate 40; the first is saved and headlines)"),
    variant: list[str] = typer.Option([], help="--ablation: only this variant (repeat for more; default: all of "
                                      "experiments/varied/ablation.py's VARIANTS)"),
    n_normal: int | None = typer.Option(None, min=60, help="held-out normal episodes: simulated when the data "
                                        "folder has none (default 400); a set already there must hold this many"),
    workers: int = typer.Option(2, min=1, help="simulation processes (CPUs of a local Ray instance)"),
    backend: Backend = typer.Option("processes", help="processes (this machine) or ray (RAY_ADDRESS or a local instance)"),
) -> None:
    """Run the 980-fault sweep (or the varied-task benchmark) against baselines; write JSON, markdown and figures."""
    if task == Task.paper or not (ceiling or diagnostic or ablation):  # these three write tables only
        require_matplotlib("faults")
    if task in (FaultTask.kitting, FaultTask.voraus):
        if data is None:
            typer.secho(f"--task {task.value} needs --data: the dataset you cloned or downloaded", fg="red", err=True)
            raise typer.Exit(2)
        _real(task.value, data, out or home_path(task.value), seeds)
        return
    parallel = Parallel(workers, backend)
    if task == Task.varied:
        out, data = out or home_path(f"varied_{context.value}"), data or home_path("data_varied")
        if ceiling:
            _ceiling(context.value, out, data, parallel=parallel)
        elif diagnostic:
            _diagnostic(context.value, out, data, seeds, parallel=parallel)
        elif ablation:
            _ablation(context.value, out, data, fast_epochs, tuple(variant), seeds, parallel=parallel)
        else:
            _varied(context.value, out, data, fast_epochs, paper_epochs, parallel=parallel)
        return
    try:
        if rate != SIM.timing.observation_hz:
            _rate(rate, out or home_path(f"fault_sweep_{rate}hz"), data or home_path(set_folder(rate)), n_normal,
                  fast_epochs, seeds, parallel=parallel)
        else:
            _paper(out or home_path("fault_sweep"), data or home_path("data"), paper_epochs, n_normal, fast_epochs,
                   parallel=parallel)
    except SetMismatch as exc:
        typer.secho(str(exc), fg="red", err=True)
        raise typer.Exit(2) from exc


def _real(task: str, data: Path, out: Path, trainings: int) -> None:
    """A real robot's dataset: its experiment's own module does the work (experiments/kitting, experiments/voraus)."""
    from neural_asm.logs.errors import LogError

    if task == "kitting":
        from neural_asm.experiments.kitting.cli import run_kitting as run_real
    else:
        from neural_asm.experiments.voraus.cli import run_voraus as run_real
    try:
        run_real(data, out, trainings)
    except LogError as exc:
        typer.secho(f"error: {exc}", fg="red", err=True)
        raise typer.Exit(2) from None


def _paper(out: Path, data: Path, paper_epochs: int, n_normal: int | None, fast_epochs: int | None, *,
           parallel: Parallel) -> None:
    from neural_asm.experiments.fault_sweep.figures import write_figures
    from neural_asm.experiments.fault_sweep.report import write_csv, write_json, write_markdown
    from neural_asm.experiments.fault_sweep.run import run_sweep

    out.mkdir(parents=True, exist_ok=True)
    result = run_sweep(data, out, paper_epochs, n_normal, fast_epochs, parallel=parallel)
    write_json(result, out / "fault_sweep.json")
    write_markdown(result, out / "fault_sweep.md")
    write_csv(result, out / "episodes.csv")
    write_figures(result, out)
    typer.echo((out / "fault_sweep.md").read_text())
    typer.echo(f"wrote {out}")


def _rate(rate: int, out: Path, data: Path, n_normal: int | None, epochs: int | None, trainings: int, *,
          parallel: Parallel) -> None:
    from neural_asm.experiments.fault_sweep.rate import markdown, run_rate_sweep, write
    from neural_asm.experiments.fault_sweep.rate_figures import write_latency_figure

    out.mkdir(parents=True, exist_ok=True)
    result = run_rate_sweep(data, out, rate, n_normal, epochs, trainings, parallel=parallel)
    write(result, out)
    write_latency_figure(result, out / "latency.png")
    typer.echo(markdown(result))
    typer.echo(f"wrote {out} in {result['seconds']:.0f} s")


def _varied(context: str, out: Path, data: Path, fast_epochs: int | None, paper_epochs: int, *,
            parallel: Parallel) -> None:
    from neural_asm.experiments.varied.report import write_figures, write_json, write_markdown
    from neural_asm.experiments.varied.run import run_varied
    from neural_asm.models.config import PRECISE

    start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    fast = PRECISE if fast_epochs is None else PRECISE.with_(epochs=fast_epochs)
    result = run_varied(data, out, context, fast, min(paper_epochs, VARIED_PAPER_EPOCHS), parallel=parallel)
    write_json(result, out / "fault_sweep.json", time.perf_counter() - start)
    write_markdown(result, out / "fault_sweep.md")
    write_figures(result, out)
    typer.echo((out / "fault_sweep.md").read_text())
    typer.echo(f"wrote {out} in {time.perf_counter() - start:.0f} s")


def _ablation(context: str, out: Path, data: Path, epochs: int | None, names: tuple[str, ...], seeds: int, *,
              parallel: Parallel) -> None:
    from neural_asm.experiments.varied.ablation import ablation_markdown, run_ablation

    rows = run_ablation(data, context, epochs, names=names, seeds=tuple(range(seeds)), parallel=parallel)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ablation.json").write_text(json.dumps(rows, indent=1))
    (out / "ablation.md").write_text(ablation_markdown(rows, context))
    typer.echo((out / "ablation.md").read_text())


def _diagnostic(context: str, out: Path, data: Path, seeds: int, *, parallel: Parallel) -> None:
    from neural_asm.experiments.varied.diagnostic import run_diagnostic
    from neural_asm.experiments.varied.diagnostic_report import diagnostic_markdown, per_group_markdown

    start = time.perf_counter()
    result = run_diagnostic(data, context, tuple(range(seeds)), parallel=parallel)
    result["seconds"]["total"] = round(time.perf_counter() - start, 1)
    out.mkdir(parents=True, exist_ok=True)
    (out / "diagnostic.json").write_text(json.dumps(result, indent=1))
    (out / "diagnostic.md").write_text(diagnostic_markdown([result]) + "\n" + per_group_markdown([result]))
    typer.echo((out / "diagnostic.md").read_text())
    typer.echo(f"wrote {out} in {result['seconds']['total']:.0f} s")


def _ceiling(context: str, out: Path, data: Path, *, parallel: Parallel) -> None:
    from neural_asm.experiments.varied.ceiling import ceiling_markdown, run_ceiling

    start = time.perf_counter()
    result = run_ceiling(data, context, parallel=parallel)
    result["seconds"] = round(time.perf_counter() - start, 1)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ceiling.json").write_text(json.dumps(result, indent=1))
    (out / "ceiling.md").write_text(ceiling_markdown(result))
    typer.echo((out / "ceiling.md").read_text())
    typer.echo(f"wrote {out} in {result['seconds']:.0f} s")


if __name__ == "__main__":
    app()
