"""JSON schemas of the MCAP channels, including Foxglove's standard FrameTransforms."""

from __future__ import annotations

from typing import Any

_VECTOR3 = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z")},
}
_QUATERNION = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in ("x", "y", "z", "w")},
}
_TIME = {
    "type": "object",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
    },
}

FRAME_TRANSFORMS = {
    "title": "foxglove.FrameTransforms",
    "description": "An array of FrameTransform messages",
    "type": "object",
    "properties": {
        "transforms": {
            "type": "array",
            "items": {
                "title": "foxglove.FrameTransform",
                "type": "object",
                "properties": {
                    "timestamp": _TIME,
                    "parent_frame_id": {"type": "string"},
                    "child_frame_id": {"type": "string"},
                    "translation": _VECTOR3,
                    "rotation": _QUATERNION,
                },
            },
        }
    },
}

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
