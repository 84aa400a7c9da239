"""A JSON-over-MCAP file written so that a crash leaves it readable.

Messages are written unchunked and ``flush()`` pushes them to the OS, so a truncated
file still reads up to its last whole record (``readers.read_mcap``) and
``mcap recover broken.mcap -o fixed.mcap`` rebuilds its index. The mcap Writer is not
thread-safe: one file belongs to one thread.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import orjson
from mcap.writer import CompressionType, Writer

_DUMP = orjson.OPT_SERIALIZE_NUMPY


class McapFile:
    def __init__(self, path: Path) -> None:
        self.file = open(path, "wb")
        self.writer = Writer(self.file, use_chunking=False, compression=CompressionType.NONE)
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
