"""Read recordings back: time series from ``.rrd`` and messages from ``.mcap``.

Used by the tests to check that files hold exactly what the service answered, and
handy for analysis. ``read_mcap`` accepts a file cut short by a crash; an ``.rrd`` cut
short is first repaired with ``repair_rrd``.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import orjson
from mcap.exceptions import McapError
from mcap.reader import StreamReader
from mcap.records import Channel, Message
from rerun.chunk import RrdReader

SCALARS = "Scalars:scalars"


def read_rrd_series(path: str | Path, entity: str, timeline: str = "step") -> tuple[np.ndarray, np.ndarray]:
    """(times (N,), values (N, k)) of a ``Scalars`` entity, sorted by ``timeline``."""
    times: list[int] = []
    values: list[list[float]] = []
    for chunk in RrdReader(path).stream():
        if chunk.entity_path != entity or chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if SCALARS not in batch.schema.names:
            continue
        times += batch.column(timeline).to_pylist()
        values += batch.column(SCALARS).to_pylist()
    order = np.argsort(times, kind="stable")
    return np.asarray(times)[order], np.asarray(values, np.float64)[order]


def repair_rrd(path: str | Path, out: str | Path) -> None:
    """Keep what decodes of an .rrd cut short by a crash (``rerun rrd merge --continue-on-error``)."""
    cmd = [sys.executable, "-m", "rerun", "rrd", "merge", "--continue-on-error", str(path), "-o", str(out)]
    subprocess.run(cmd, check=True, capture_output=True)


def read_mcap(path: str | Path) -> dict[str, list[dict[str, Any]]]:
    """Every JSON message by topic, in file order; stops at a chunk torn by a crash."""
    channels: dict[int, Channel] = {}
    messages: dict[str, list[dict[str, Any]]] = defaultdict(list)
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages[channels[record.channel_id].topic].append(orjson.loads(record.data))
        except (McapError, EOFError, struct.error, orjson.JSONDecodeError):
            pass  # truncated: keep what was whole
    return dict(messages)
