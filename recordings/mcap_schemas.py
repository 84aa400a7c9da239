"""JSON schemas of the MCAP channels of our own messages (Foxglove's come from foxglove-sdk)."""

from __future__ import annotations

from typing import Any

METADATA = {
    "title": "neural_asm.Metadata",
    "description": "What the run is: ids, model, recall setting, channel names",
    "type": "object",
    "properties": {
        "run_id": {"type": "string"},
        "recording_id": {"type": "string"},
        "channel_names": {"type": "array", "items": {"type": "string"}},
    },
    "additionalProperties": True,
}

FAULT = {
    "title": "neural_asm.Fault",
    "description": "Energy of a step against its threshold, the fault flag and the isolated joint",
    "type": "object",
    "properties": {
        "step": {"type": "integer"},
        "energy": {"type": ["number", "null"]},
        "threshold": {"type": ["number", "null"]},
        "margin": {"type": ["number", "null"], "description": "log10(energy / threshold): above 0 is a fault"},
        "fault": {"type": ["boolean", "null"]},
        "isolated_joint": {"type": ["string", "null"]},
    },
}

TRAINING = {
    "title": "neural_asm.TrainingEpoch",
    "type": "object",
    "properties": {"epoch": {"type": "integer"}, "energy": {"type": "number"}},
}


def channel_vector(title: str, description: str, channel_names: tuple[str, ...]) -> dict[str, Any]:
    """One number per named channel plus the step, so plots can pick channels by name."""
    props: dict[str, Any] = {"step": {"type": "integer"}}
    props.update({name: {"type": "number"} for name in channel_names})
    return {"title": title, "description": description, "type": "object", "properties": props}
