"""Read recordings back: time series from ``.rrd`` and messages from ``.mcap``.

Used by the tests to check that files hold exactly what the service answered, and
handy for analysis. ``read_mcap`` accepts a file cut short by a crash; an ``.rrd`` cut
short is first repaired with ``repair_rrd``. MCAP messages come back as dicts: JSON ones
as they are, protobuf ones (Foxglove's) decoded from the schema the file carries, with
their field names.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any, Callable

import numpy as np
import orjson
from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
from google.protobuf.message import DecodeError
from mcap.exceptions import McapError
from mcap.reader import StreamReader
from mcap.records import Channel, Message, Schema
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


Decoder = Callable[[bytes], dict[str, Any]]


def protobuf_decoder(schema: Schema) -> Decoder:
    """Messages of a protobuf schema (a serialized FileDescriptorSet) as dicts."""
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:  # dependencies come first
        pool.Add(file)
    message_class = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return lambda data: json_format.MessageToDict(message_class.FromString(data), preserving_proto_field_name=True)


def read_mcap(path: str | Path) -> dict[str, list[dict[str, Any]]]:
    """Every message by topic, in file order; stops at a chunk torn by a crash."""
    decoders: dict[int, Decoder] = {}
    topics: dict[int, tuple[str, Decoder]] = {}
    messages: dict[str, list[dict[str, Any]]] = defaultdict(list)
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Schema) and record.encoding == "protobuf":
                    decoders[record.id] = protobuf_decoder(record)
                elif isinstance(record, Channel):
                    topics[record.id] = (record.topic, orjson.loads if record.message_encoding == "json"
                                         else decoders[record.schema_id])
                elif isinstance(record, Message):
                    topic, decode = topics[record.channel_id]
                    messages[topic].append(decode(record.data))
        except (McapError, EOFError, struct.error, orjson.JSONDecodeError, DecodeError):
            pass  # truncated: keep what was whole
    return dict(messages)
