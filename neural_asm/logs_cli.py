"""``nasm logs``: what the commands would read from a robot's logs, before anything is trained on them."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from neural_asm.data import DATA_HELP, SYNTHETIC
from neural_asm.logs.cli import DataCommand, mapping_help
from neural_asm.runtime.cli import Group

app = typer.Typer(cls=Group, help="A robot's logs: what the commands would read from them.", no_args_is_help=True,
                  add_completion=False)


def _episodes(seqs: Any) -> list[dict[str, Any]]:
    """Each sequence's facts as the readers give them (data without them: its position, whole)."""
    rows = []
    for i, skill in enumerate(seqs.labels.tolist()):
        facts = seqs.episodes[i] if seqs.episodes else None
        rows.append({"number": i if facts is None else facts.number, "steps": seqs.own_steps(i), "skill": str(skill),
                     "anomaly": None if facts is None else facts.anomaly,
                     "onset_s": None if facts is None else facts.onset_s,
                     "origin": seqs.provenance.get("source", SYNTHETIC) if facts is None else facts.origin})
    return rows


@app.command(cls=DataCommand)
def inspect(
    data: str = typer.Argument(..., help=DATA_HELP),
    mapping: Path | None = typer.Option(None, help=mapping_help("DATA")),
    as_json: bool = typer.Option(False, "--json", help="print what would be read as JSON"),
) -> None:
    """What the commands would read from DATA, without training anything.

    Each episode's own steps, skill, anomaly label and onset, the rate and the channels; for
    logs, what would be skipped and why (the warnings)."""
    from neural_asm.data import read_data

    seqs = read_data(data, mapping, skip_bad=mapping is not None)
    rows = _episodes(seqs)
    skipped = seqs.warnings
    if as_json:
        typer.echo(json.dumps({"source": data, "format": seqs.provenance.get("format"), "rate_hz": seqs.rate_hz,
                               "steps": seqs.data.shape[1], "channels": list(seqs.channel_names), "episodes": rows,
                               "skipped": skipped}, indent=1))
        return
    typer.echo(f"{data}: {len(rows)} episodes of {seqs.data.shape[1]} steps at {seqs.rate_hz:g} Hz "
               f"(a step every {1 / seqs.rate_hz:g} s), {len(seqs.channel_names)} channels: "
               f"{', '.join(seqs.channel_names)}")
    for row in rows:
        label = "normal" if row["anomaly"] is None else f"anomaly {row['anomaly']}" + (
            "" if row["onset_s"] is None else f" from {row['onset_s']:.3g} s")
        typer.echo(f"  episode {row['number']:>4}: {row['steps']:>5} steps, skill {row['skill']}, {label}, "
                   f"{row['origin']}")
    if skipped:
        typer.echo(f"{len(skipped)} skipped (the warnings above): the commands refuse this source unless given --skip-bad")
