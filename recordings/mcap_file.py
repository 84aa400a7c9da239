"""An MCAP file (JSON channels, and Foxglove's protobuf messages) written so that a crash leaves it readable by any MCAP reader.

Messages go into small chunks, each followed by its message indexes, and a finished
file ends with the summary (chunk indexes, statistics), so readers seek it by time. A
chunk reaches the file once it holds ``CHUNK_SIZE`` bytes and ``flush()`` pushes it to
the OS, so a kill loses the chunk being filled: under 16 KiB, about four steps of a
25-channel model or a few world frames (a tenth of a second at 40 Hz).

Between chunks the file also ends as a whole MCAP file does: every flush writes the new
chunk followed by a data-end record, a footer without summary and the closing magic, in
one write at the place of the previous such ending (a kill cannot split one write to a
local file). So a file cut short by ``kill -9`` is still a valid MCAP file without a
summary: mcap's ``make_reader`` reads every whole chunk of it, linearly, and
``nasm recordings recover`` (or ``mcap recover``) adds the indexes. The mcap Writer is
not thread-safe: one file belongs to one thread.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import orjson
from foxglove import Schema as FoxgloveSchema
from mcap.data_stream import RecordBuilder
from mcap.records import DataEnd, Footer
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

_DUMP = orjson.OPT_SERIALIZE_NUMPY
CHUNK_SIZE = 16384  # bytes: what a kill may lose; in 4 KiB chunks the same steps took 1.3-1.5x as long


def _provisional_end() -> bytes:
    builder = RecordBuilder()
    DataEnd(data_section_crc=0).write(builder)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(builder)
    return bytes(builder.end()) + MCAP0_MAGIC


PROVISIONAL_END = _provisional_end()


class EndedFile:
    """The Writer's output stream: bytes pile up until ``flush``, which writes them with a
    provisional end after them, over the previous provisional end."""

    def __init__(self, path: Path) -> None:
        self.fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self.written = 0  # bytes of real content on disk; a provisional end may follow them
        self.pending = bytearray()

    def write(self, data: bytes | bytearray | memoryview) -> int:
        self.pending += data
        return len(data)

    def tell(self) -> int:
        return self.written + len(self.pending)

    def _put(self, end: bytes) -> None:
        data = bytes(self.pending) + end
        done = 0
        while done < len(data):  # one call in practice; a short write is finished
            done += os.pwrite(self.fd, data[done:], self.written + done)
        self.written += len(self.pending)
        self.pending.clear()

    def flush(self) -> None:
        if self.pending:
            self._put(PROVISIONAL_END)

    def close(self) -> None:
        """Write the real end (the Writer's summary and footer) and cut off any provisional one."""
        try:
            self._put(b"")
            os.ftruncate(self.fd, self.written)
        finally:
            os.close(self.fd)


class McapFile:
    def __init__(self, path: Path) -> None:
        self.file = EndedFile(path)
        self.writer = Writer(self.file, chunk_size=CHUNK_SIZE, compression=CompressionType.NONE)  # type: ignore[arg-type]
        self.writer.start(profile="", library="neural_asm")
        self.foxglove_schemas: dict[str, int] = {}
        self.file.flush()

    def channel(self, topic: str, schema: dict[str, Any]) -> int:
        """Register a JSON channel whose messages follow ``schema`` (titled)."""
        schema_id = self.writer.register_schema(schema["title"], "jsonschema", orjson.dumps(schema))
        return self.writer.register_channel(topic, "json", schema_id)

    def foxglove_channel(self, topic: str, schema: FoxgloveSchema) -> int:
        """Register a channel of a Foxglove message type (``foxglove.messages.X.get_schema()``:
        protobuf, its schema a serialized FileDescriptorSet, as MCAP's protobuf profile wants);
        channels of one type share its schema record (~5 KB for a SceneUpdate)."""
        if schema.name not in self.foxglove_schemas:
            self.foxglove_schemas[schema.name] = self.writer.register_schema(schema.name, schema.encoding, schema.data)
        return self.writer.register_channel(topic, schema.encoding, self.foxglove_schemas[schema.name])

    def metadata(self, name: str, values: dict[str, Any]) -> None:
        """An MCAP Metadata record (what ``mcap info`` and Foxglove list as the file's
        metadata): strings as they are, anything else as JSON."""
        self.writer.add_metadata(name, {k: v if isinstance(v, str) else orjson.dumps(v, option=_DUMP).decode()
                                        for k, v in values.items()})

    def wants(self, channel: int) -> bool:
        """A file keeps every message."""
        return True

    def write(self, channel: int, time_ns: int, message: dict[str, Any]) -> None:
        self.write_encoded(channel, time_ns, orjson.dumps(message, option=_DUMP))

    def write_encoded(self, channel: int, time_ns: int, data: bytes) -> None:
        """A message already in its channel's encoding (e.g. a Foxglove message's ``encode()``)."""
        self.writer.add_message(channel, time_ns, data, time_ns)

    def flush(self) -> None:
        """Put the chunks completed so far on disk, the file ending validly after them."""
        self.file.flush()

    def close(self) -> None:
        try:
            self.writer.finish()
        finally:
            self.file.close()
