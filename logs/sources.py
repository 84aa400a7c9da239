"""A bag, a dataset or a lab's tables, read through a mapping, as the project's ``Sequences``.

The sequences carry the mapping's clock (``rate_hz``) and each episode's facts (``episodes``).
The provenance keeps where they came from: the source, the mapping file, the whole validated
mapping and the warnings, so a checkpoint trained from logs says how its data were mapped, and
later data can be checked against it (``logs.mapping.check_checkpoint``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neural_asm.logs import formats
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Mapping, Timing, check_checkpoint, load_mapping, parse_mapping
from neural_asm.logs.recorded import Recorded
from neural_asm.models.sequences import EpisodeFacts, Sequences


def read_mapped(source: str | Path, mapping: Mapping, mapping_file: str = "", skip_bad: bool = False) -> Sequences:
    """Every episode of ``source`` under ``mapping``, on the mapping's clock (``rate_hz``), each with
    its facts (``Sequences.episodes``: its number in the source, so that a skipped one shifts no
    other, its origin, own steps, start, anomaly and onset); a bad or missing one is an error, or
    with ``skip_bad`` a warning kept in the provenance."""
    path = Path(source)
    if not path.exists():
        raise LogError(f"nothing at {path} (expected {formats.described()})")
    reader = formats.reader(mapping.kind)
    if not reader.recognises(path):
        other = formats.recognised(path)
        if other is not None:
            raise LogError(f"{path} is {other.named}, but the mapping reads {reader.named}")
    episodes: list[Recorded] = []
    warnings: list[str] = []
    for item in reader.read(path, mapping, skip_bad):
        (warnings if isinstance(item, str) else episodes).append(item)  # type: ignore[arg-type]
    if not episodes:
        raise LogError(f"{path} holds no episode" + (f" ({'; '.join(warnings)})" if warnings else ""))
    episodes.sort(key=lambda e: e.number)
    provenance = {"source": str(path), "format": mapping.kind, "mapping_file": mapping_file, "mapping": mapping.to_dict(),
                  "warnings": warnings}
    return Sequences(np.stack([e.data for e in episodes]), np.array([e.label for e in episodes]),
                     mapping.channel_names, provenance=provenance, rate_hz=1.0 / mapping.timing.period_s,
                     episodes=tuple(_facts(e, mapping.timing) for e in episodes), warnings=tuple(warnings))


def read_again(provenance: dict) -> Sequences | None:
    """The logs a model was trained on, read again as `read_mapped` read them (its provenance's
    source, through the whole mapping it keeps, not the mapping's file, which may have changed
    since), or None when its data were not logs."""
    if "mapping" not in provenance:
        return None
    return read_mapped(provenance["source"], parse_mapping(provenance["mapping"], "the checkpoint's mapping"),
                       provenance.get("mapping_file", ""), skip_bad=bool(provenance.get("warnings")))


def _facts(episode: Recorded, timing: Timing) -> EpisodeFacts:
    """A read episode's facts: its own steps are all of them unless it was padded (``timing.shorter = "hold"``)."""
    steps = len(episode.data)
    if episode.length_s is not None:
        steps = min(int(round(episode.length_s / timing.period_s)) + 1, steps)
    return EpisodeFacts(episode.number, episode.origin, steps, episode.start_s, episode.anomaly, episode.onset_s)


def load_log_sequences(source: str | Path, mapping_file: str | Path, skip_bad: bool = False) -> Sequences:
    """Every episode of a source in a registered format (``logs.formats``) as ``Sequences``, read through the
    channel mapping file ``mapping_file`` (TOML or YAML); a ``LogError`` names what is wrong, or
    with ``skip_bad`` a bad episode is left out with a warning in the provenance."""
    return read_mapped(source, load_mapping(mapping_file), str(mapping_file), skip_bad)


def read_as(seqs: Sequences) -> list[str]:
    """How the mapping the sequences were read through lays out and reads the logs, in words
    (``nasm logs inspect``); nothing for data read without one."""
    doc = seqs.provenance.get("mapping")
    lines = parse_mapping(doc, "the mapping").source.layout() if doc else []
    return [f"read as {line}" if i == 0 else line for i, line in enumerate(lines)]


def episode_position(seqs: Sequences, number: int) -> int:
    """Where episode ``number`` of the source is in ``seqs``, or a LogError saying why it is not there."""
    numbers = [e.number for e in seqs.episodes] if seqs.episodes else list(range(len(seqs.data)))
    if number in numbers:
        return numbers.index(number)
    skipped = [w for w in seqs.warnings if f"episode {number}" in w]
    have = f"{numbers[0]}..{numbers[-1]}" if numbers == list(range(numbers[0], numbers[-1] + 1)) else str(numbers)
    raise LogError(f"episode {number} is not among the episodes read from {seqs.provenance.get('source')}"
                   + (f": {skipped[0]}" if skipped else f" (it has episodes {have})"))


def check_model(seqs: Sequences, channel_names: tuple[str, ...], provenance: dict, same_length: bool = True) -> None:
    """Refuse logged sequences mapped otherwise than the model's training data (no-op for other
    sources); ``same_length=False`` for data streamed to a session, whose length is its own."""
    if "mapping" in seqs.provenance:
        check_checkpoint(parse_mapping(seqs.provenance["mapping"], "the mapping"), channel_names, provenance,
                         same_length)
