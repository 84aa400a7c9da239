"""A bag, a dataset or a lab's tables, read through a mapping, as the project's ``Sequences``.

The provenance keeps the source, the mapping file and the whole validated mapping, so a
checkpoint trained from logs says where its data came from and how it was mapped, and later
data can be checked against it (``logs.mapping.check_checkpoint``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from neural_asm.logs import lerobot, rosbag, tables
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import Kind, Mapping, check_checkpoint, load_mapping, parse_mapping
from neural_asm.logs.recorded import Recorded
from neural_asm.models.sequences import Sequences


def source_kind(source: Path) -> Kind:
    return "lerobot" if lerobot.is_dataset(source) else "rosbag"


def read_mapped(source: str | Path, mapping: Mapping, mapping_file: str = "", skip_bad: bool = False) -> Sequences:
    """Every episode of ``source`` under ``mapping``; a bad or missing one is an error, or with
    ``skip_bad`` a warning. Warnings go into the provenance, and ``episode_numbers`` keeps each
    episode's number in the source, so that a skipped one shifts no other."""
    path = Path(source)
    if not path.exists():
        raise LogError(f"no bag, dataset or table at {path}")
    kind = "table" if mapping.kind == "table" else source_kind(path)
    if kind != mapping.kind:
        raise LogError(f"{path} is a {'LeRobot dataset' if kind == 'lerobot' else 'bag source'} but the "
                       f"mapping's channels read {'features' if mapping.kind == 'lerobot' else 'topics'}")
    reader = {"lerobot": lerobot.read_episodes, "rosbag": rosbag.read_episodes, "table": tables.read_episodes}[kind]
    episodes: list[Recorded] = []
    warnings: list[str] = []
    for item in reader(path, mapping, skip_bad):
        (warnings if isinstance(item, str) else episodes).append(item)  # type: ignore[arg-type]
    if not episodes:
        raise LogError(f"{path} holds no episode" + (f" ({'; '.join(warnings)})" if warnings else ""))
    episodes.sort(key=lambda e: e.number)
    provenance = {"source": str(path), "format": kind, "mapping_file": mapping_file, "mapping": mapping.to_dict(),
                  "episodes": [e.origin for e in episodes], "episode_numbers": [e.number for e in episodes],
                  "warnings": warnings}
    if kind == "table":
        provenance["anomalies"] = [e.anomaly for e in episodes]
        provenance["onsets_s"] = [e.onset_s for e in episodes]
        provenance["lengths_s"] = [e.length_s for e in episodes]
        provenance["starts_s"] = [e.start_s for e in episodes]
    return Sequences(np.stack([e.data for e in episodes]), np.array([e.label for e in episodes]),
                     mapping.channel_names, provenance=provenance)


def load_log_sequences(source: str | Path, mapping_file: str | Path, skip_bad: bool = False) -> Sequences:
    """Every episode of a bag source or LeRobot dataset as ``Sequences``, read through the
    channel mapping file ``mapping_file`` (TOML or YAML); a ``LogError`` names what is wrong, or
    with ``skip_bad`` a bad episode is left out with a warning in the provenance."""
    return read_mapped(source, load_mapping(mapping_file), str(mapping_file), skip_bad)


def episode_position(seqs: Sequences, number: int) -> int:
    """Where episode ``number`` of the source is in ``seqs``, or a LogError saying why it is not there."""
    numbers = list(seqs.provenance.get("episode_numbers", range(len(seqs.data))))
    if number in numbers:
        return numbers.index(number)
    skipped = [w for w in seqs.provenance.get("warnings", []) if f"episode {number}" in w]
    have = f"{numbers[0]}..{numbers[-1]}" if numbers == list(range(numbers[0], numbers[-1] + 1)) else str(numbers)
    raise LogError(f"episode {number} is not among the episodes read from {seqs.provenance.get('source')}"
                   + (f": {skipped[0]}" if skipped else f" (it has episodes {have})"))


def own_steps(seqs: Sequences, i: int) -> int:
    """How many of episode ``i``'s steps are its own: a table episode shorter than the mapping's
    steps is padded by holding its last sample (``timing.shorter = "hold"``), other episodes are whole."""
    lengths = seqs.provenance.get("lengths_s")
    steps = seqs.data.shape[1]
    if not lengths or lengths[i] is None:
        return steps
    period = float(seqs.provenance["mapping"]["timing"]["period_s"])
    return min(int(round(lengths[i] / period)) + 1, steps)


def check_model(seqs: Sequences, channel_names: tuple[str, ...], provenance: dict, same_length: bool = True) -> None:
    """Refuse logged sequences mapped otherwise than the model's training data (no-op for other
    sources); ``same_length=False`` for data streamed to a session, whose length is its own."""
    if "mapping" in seqs.provenance:
        check_checkpoint(parse_mapping(seqs.provenance["mapping"], "the mapping"), channel_names, provenance,
                         same_length)
