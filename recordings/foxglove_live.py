"""Episodes live in Foxglove: a Foxglove WebSocket server (foxglove-sdk) on loopback whose
topics and schemas are the MCAP files' (``mcap_writer``), so the shipped layout shows a running
robot as it shows a file. Connect Foxglove to ``ws://127.0.0.1:PORT`` (an SSH tunnel reaches it
from another machine; it has no key, so it never binds beyond loopback).

``McapEpisode`` writes to a ``FoxgloveOut`` exactly as to an ``McapFile``. A topic is one
channel of the server, shared by every episode on it (the SDK keeps one channel per topic):
a service's concurrent sessions interleave on ``/fault`` and the rest, each message naming
its step.
"""

from __future__ import annotations

from typing import Any

import foxglove
import orjson
from foxglove import Schema as FoxgloveSchema

LOOPBACK = "127.0.0.1"
_DUMP = orjson.OPT_SERIALIZE_NUMPY


class FoxgloveLive:
    """A Foxglove WebSocket server of its own context, serving on ``port`` (0: any free one)."""

    def __init__(self, port: int) -> None:
        self.context = foxglove.Context()
        self.server = foxglove.start_server(name="neural_asm", host=LOOPBACK, port=port, context=self.context)
        self.channels: dict[str, foxglove.Channel] = {}

    @property
    def url(self) -> str:
        return f"ws://{LOOPBACK}:{self.server.port}"

    @property
    def how(self) -> str:
        return f"Foxglove: open a connection to {self.url} (the layout recordings/layouts/neural_asm.json shows it)"

    def channel(self, topic: str, schema: FoxgloveSchema, encoding: str) -> foxglove.Channel:
        if topic not in self.channels:
            self.channels[topic] = foxglove.Channel(topic, schema=schema, message_encoding=encoding,
                                                    context=self.context)
        return self.channels[topic]

    def episode(self) -> FoxgloveOut:
        return FoxgloveOut(self)

    def close(self) -> None:
        self.server.stop()


class FoxgloveOut:
    """An episode's messages to the live server, with ``McapFile``'s calls."""

    def __init__(self, live: FoxgloveLive) -> None:
        self.live = live

    def channel(self, topic: str, schema: dict[str, Any]) -> foxglove.Channel:
        return self.live.channel(topic, FoxgloveSchema(name=schema["title"], encoding="jsonschema",
                                                       data=orjson.dumps(schema)), "json")

    def foxglove_channel(self, topic: str, schema: FoxgloveSchema) -> foxglove.Channel:
        return self.live.channel(topic, schema, schema.encoding)

    def wants(self, channel: foxglove.Channel) -> bool:
        """Whether anyone subscribes to ``channel``: building a message no one receives costs the
        recorder as much as one that someone does."""
        return channel.has_sinks()

    def metadata(self, name: str, values: dict[str, Any]) -> None:
        """A file's metadata record: live, the ``/metadata`` topic says it."""

    def write(self, channel: foxglove.Channel, time_ns: int, message: dict[str, Any]) -> None:
        channel.log(orjson.dumps(message, option=_DUMP), log_time=time_ns)

    def write_encoded(self, channel: foxglove.Channel, time_ns: int, data: bytes) -> None:
        channel.log(data, log_time=time_ns)

    def flush(self) -> None:
        """Sent as logged."""

    def close(self) -> None:
        """The channels stay with the server, for the next episode."""
