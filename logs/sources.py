"""A bag or a dataset, read through a mapping, as the project's ``Sequences``.

The provenance keeps the source, the mapping file and the whole validated mapping, so a
checkpoint trained from logs says where its data came from and how it was mapped, and later
data can be checked against it (``logs.mapping.check_checkpoint``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from logs import lerobot, rosbag
from logs.errors import LogError
from logs.mapping import Kind, Mapping, check_checkpoint, load_mapping, parse_mapping
from logs.recorded import Recorded
from models.sequences import Sequences


def source_kind(source: Path) -> Kind:
    return "lerobot" if lerobot.is_dataset(source) else "rosbag"


def read_mapped(source: str | Path, mapping: Mapping, mapping_file: str = "") -> Sequences:
    """Every episode of ``source`` under ``mapping``; warnings (a damaged bag) go into the provenance."""
    path = Path(source)
    if not path.exists():
        raise LogError(f"no bag or dataset at {path}")
    kind = source_kind(path)
    if kind != mapping.kind:
        raise LogError(f"{path} is a {'LeRobot dataset' if kind == 'lerobot' else 'ROS 2 bag source'} but the "
                       f"mapping's channels read {'features' if mapping.kind == 'lerobot' else 'topics'}")
    reader = lerobot.read_episodes if kind == "lerobot" else rosbag.read_episodes
    episodes: list[Recorded] = []
    warnings: list[str] = []
    for item in reader(path, mapping):
        (warnings if isinstance(item, str) else episodes).append(item)  # type: ignore[arg-type]
    if not episodes:
        raise LogError(f"{path} holds no episode" + (f" ({'; '.join(warnings)})" if warnings else ""))
    provenance = {"source": str(path), "format": kind, "mapping_file": mapping_file, "mapping": mapping.to_dict(),
                  "episodes": [e.origin for e in episodes], "warnings": warnings}
    return Sequences(np.stack([e.data for e in episodes]), np.array([e.label for e in episodes]),
                     mapping.channel_names, provenance=provenance)


def load_log_sequences(source: str | Path, mapping_file: str | Path) -> Sequences:
    """``read_mapped`` with the mapping read from its file."""
    return read_mapped(source, load_mapping(mapping_file), str(mapping_file))


def check_model(seqs: Sequences, channel_names: tuple[str, ...], provenance: dict) -> None:
    """Refuse logged sequences mapped otherwise than the model's training data (no-op for other sources)."""
    if "mapping" in seqs.provenance:
        check_checkpoint(parse_mapping(seqs.provenance["mapping"], "the mapping"), channel_names, provenance)
