"""A JSON-over-MCAP file written so that a crash leaves it readable.

Messages go into small chunks, each followed by its message indexes, and a finished
file ends with the summary (chunk indexes, statistics), so readers seek it by time. A
chunk reaches the file once it holds ``CHUNK_SIZE`` bytes and ``flush()`` pushes it to
the OS, so a kill loses the chunk being filled: under 4 KiB, about three steps of a
10-channel model or one or two world frames. A file cut short has no summary: it reads
linearly up to its last whole chunk (``readers.read_mcap``, or mcap's
``NonSeekingReader(...).iter_messages(log_time_order=False)``), and
``mcap recover broken.mcap -o fixed.mcap`` rebuilds the summary. The mcap Writer is
not thread-safe: one file belongs to one thread.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import orjson
from mcap.writer import CompressionType, Writer

_DUMP = orjson.OPT_SERIALIZE_NUMPY
CHUNK_SIZE = 4096  # bytes: what a kill may lose, against ~8% more bytes for chunk and index records


class McapFile:
    def __init__(self, path: Path) -> None:
        self.file = open(path, "wb")
        self.writer = Writer(self.file, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE)
        self.writer.start(profile="", library="neural_asm")

    def channel(self, topic: str, schema: dict[str, Any]) -> int:
        """Register a JSON channel whose messages follow ``schema`` (titled)."""
        schema_id = self.writer.register_schema(schema["title"], "jsonschema", orjson.dumps(schema))
        return self.writer.register_channel(topic, "json", schema_id)

    def write(self, channel: int, time_ns: int, message: dict[str, Any]) -> None:
        self.writer.add_message(channel, time_ns, orjson.dumps(message, option=_DUMP), time_ns)

    def flush(self) -> None:
        self.file.flush()

    def close(self) -> None:
        try:
            self.writer.finish()
        finally:
            self.file.close()
