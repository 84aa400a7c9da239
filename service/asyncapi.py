"""The websocket protocol as an AsyncAPI 3 document, built from the models that validate it.

``GET /asyncapi.json`` serves it. The message payloads are the JSON schemas of the
pydantic models the stream parses and answers with (``service.schemas``), so the
document cannot drift from the code; the operations are from the service's side: it
receives ``start``, ``step`` and ``end`` and replies to each, and sends ``metadata``
first.
"""

from typing import Any

from pydantic import BaseModel
from pydantic.json_schema import models_json_schema

from neural_asm.service.schemas import (EndedMessage, EndMessage, ErrorMessage, MetadataMessage, StartedMessage, StartMessage,
                             StepMessage, StepReply)

VERSION = "3.0.0"
MESSAGES: dict[str, type[BaseModel]] = {
    "start": StartMessage, "step": StepMessage, "end": EndMessage,
    "metadata": MetadataMessage, "started": StartedMessage, "stepResult": StepReply, "ended": EndedMessage,
    "error": ErrorMessage,
}
# what the service receives -> what it replies (an error instead, for a mistake)
EXCHANGES = {"start": "started", "step": "stepResult", "end": "ended"}
CLIENT_MESSAGES = tuple(EXCHANGES)


def _message_ref(name: str) -> dict[str, str]:
    return {"$ref": f"#/channels/stream/messages/{name}"}


def document(app_version: str, protocol: int, description: str) -> dict[str, Any]:
    modes = {name: ("validation" if name in CLIENT_MESSAGES else "serialization") for name in MESSAGES}
    _, schemas = models_json_schema([(MESSAGES[n], modes[n]) for n in MESSAGES],  # type: ignore[misc]
                                    ref_template="#/components/schemas/{model}")
    operations: dict[str, Any] = {
        f"receive_{name}": {
            "action": "receive",
            "channel": {"$ref": "#/channels/stream"},
            "messages": [_message_ref(name)],
            "reply": {"channel": {"$ref": "#/channels/stream"},
                      "messages": [_message_ref(reply), _message_ref("error")]},
        }
        for name, reply in EXCHANGES.items()
    }
    operations["send_metadata"] = {"action": "send", "channel": {"$ref": "#/channels/stream"},
                                   "messages": [_message_ref("metadata")],
                                   "summary": "sent once, as soon as the connection is accepted"}
    return {
        "asyncapi": VERSION,
        "info": {"title": "Neural ASM stream", "version": app_version, "description": description},
        "defaultContentType": "application/json",
        "channels": {
            "stream": {
                "address": "/stream",
                "title": f"one episode per session over a websocket (protocol {protocol})",
                "messages": {name: {"$ref": f"#/components/messages/{name}"} for name in MESSAGES},
            }
        },
        "operations": operations,
        "components": {
            "schemas": schemas["$defs"],
            "messages": {
                name: {"name": name, "title": model.__name__, "summary": (model.__doc__ or "").strip().split("\n")[0],
                       "payload": {"$ref": f"#/components/schemas/{model.__name__}"}}
                for name, model in MESSAGES.items()
            },
        },
    }
