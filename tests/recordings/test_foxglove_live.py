"""``nasm serve --foxglove PORT``: a client speaking Foxglove's WebSocket protocol
(``foxglove.sdk.v1``, the v1 messages) subscribes to the fault topic and receives one message per step,
with the MCAP files' schema."""

from __future__ import annotations

import json
import socket
import struct

import numpy as np
from websockets.sync.client import connect

from neural_asm.recordings import mcap_schemas
from neural_asm.service.embedded import start_embedded
from neural_asm.service.settings import Settings

MESSAGE_DATA = 0x01  # binary opcode of a message on a subscription
# Foxglove's WebSocket protocol, as foxglove-sdk 0.30 names it (it refuses the older name,
# foxglove.websocket.v1, whose messages are the same); offered both, it picks its own.
SUBPROTOCOLS = ["foxglove.sdk.v1", "foxglove.websocket.v1"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def advertised(fox, topic: str) -> dict:
    """Read the Foxglove server's messages until it advertises ``topic``."""
    while True:
        message = fox.recv(timeout=30)
        if isinstance(message, str):
            op = json.loads(message)
            if op["op"] == "advertise":
                for channel in op["channels"]:
                    if channel["topic"] == topic:
                        return channel


def test_a_foxglove_client_receives_one_fault_message_per_step(servable_model, tmp_path):
    models = servable_model(n_skills=1, repetitions=4, steps=8, hidden_size=16, epochs=10, name="panda")
    episode = np.load(models / "episodes.npy")[0]
    port = free_port()
    settings = Settings(models_dir=models, recordings_dir=tmp_path, build_default_model=False, foxglove=port)
    with start_embedded(settings) as srv, \
            connect(f"ws://127.0.0.1:{port}", subprotocols=SUBPROTOCOLS) as fox, \
            connect(srv.url.replace("http", "ws") + "/stream") as ws:
        assert fox.subprotocol == "foxglove.sdk.v1"
        assert json.loads(fox.recv(timeout=30))["op"] == "serverInfo"
        ws.recv()
        ws.send(json.dumps({"type": "start", "mode": "offline"}))
        assert json.loads(ws.recv())["type"] == "started"
        channel = advertised(fox, "/fault")  # the session's channels, as its recorder opened them
        assert channel["encoding"] == "json" and channel["schemaName"] == mcap_schemas.FAULT["title"]
        assert json.loads(channel["schema"]) == mcap_schemas.FAULT
        fox.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": 7, "channelId": channel["id"]}]}))
        answers = []
        for x in episode:
            ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
            answers.append(json.loads(ws.recv()))
        ws.send(json.dumps({"type": "end"}))
        assert json.loads(ws.recv())["type"] == "ended"  # the recorder has written (and sent) every step
        received = []
        while len(received) < len(episode):
            message = fox.recv(timeout=30)
            if isinstance(message, bytes) and message[0] == MESSAGE_DATA:
                subscription, _log_time = struct.unpack_from("<IQ", message, 1)
                assert subscription == 7
                received.append(json.loads(message[13:]))
    assert [m["step"] for m in received] == list(range(len(episode)))
    assert [m["energy"] for m in received] == [a["energy"] for a in answers]
    assert [m["fault"] for m in received] == [a["fault"] for a in answers]
