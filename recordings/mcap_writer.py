"""An episode to an MCAP file: JSON-schema channels any MCAP reader or Foxglove opens.

Run metadata is an MCAP Metadata record named ``run`` and, for readers of messages, the
``/metadata`` topic (once). Topics: ``/observation``, ``/expected`` (what the model expected
of the step), ``/prediction`` (its forecast of the next step), ``/errors`` (weighted
prediction errors), ``/fault`` (energy, threshold, flag, isolated joint) and ``/tf``
(``foxglove.FrameTransforms``: link frames, tool point and cube in ``world``).
Timestamps are the recorder's start time plus episode time. Flushed after every step.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from recordings import mcap_schemas as schemas
from recordings.mcap_file import McapFile
from recordings.records import StepRecord, WorldRecord

_VECTOR_TOPICS = {
    "/observation": "the observation, original units",
    "/expected": "what the model expected of this step, original units",
    "/prediction": "the model's forecast of the next step, original units",
    "/errors": "prediction errors divided by their expected spread (the channels isolation ranks)",
}
_IDENTITY = (0.0, 0.0, 0.0, 1.0)


class McapEpisode:
    def __init__(self, path: Path, channel_names: tuple[str, ...], step_period_s: float) -> None:
        self.channel_names = channel_names
        self.step_period_s = step_period_s
        self.start_ns = time.time_ns()
        self.out = McapFile(path)
        self.channels = {
            topic: self.out.channel(topic, schemas.channel_vector(f"neural_asm.{topic[1:].capitalize()}", doc, channel_names))
            for topic, doc in _VECTOR_TOPICS.items()
        }
        self.channels["/fault"] = self.out.channel("/fault", schemas.FAULT)
        self.channels["/metadata"] = self.out.channel("/metadata", schemas.METADATA)
        self.channels["/tf"] = self.out.channel("/tf", schemas.FRAME_TRANSFORMS)

    def _write(self, topic: str, time_s: float, message: dict[str, Any]) -> None:
        self.out.write(self.channels[topic], self.start_ns + int(time_s * 1e9), message)

    def write_metadata(self, metadata: dict[str, Any]) -> None:
        self.out.metadata("run", metadata)
        self._write("/metadata", 0.0, metadata)
        self.out.flush()

    def _named(self, step: int, values: np.ndarray) -> dict[str, Any]:
        return {"step": step, **dict(zip(self.channel_names, np.asarray(values, np.float64).tolist()))}

    def write_step(self, r: StepRecord) -> None:
        t = r.step * self.step_period_s if r.time_s is None else r.time_s
        vectors = {"/observation": r.observation, "/expected": r.expected, "/prediction": r.prediction, "/errors": r.errors}
        for topic, values in vectors.items():
            if values is not None:
                self._write(topic, t, self._named(r.step, values))
        if r.energy is not None:
            self._write("/fault", t, {"step": r.step, "energy": r.energy, "threshold": r.threshold,
                                      "fault": r.fault, "isolated_joint": r.isolated_joint})
        self.out.flush()

    def write_world(self, w: WorldRecord) -> None:
        frames: list[tuple[str, Any, Any]] = []
        if w.link_positions is not None:
            quats = [None] * len(w.link_positions) if w.link_quaternions is None else w.link_quaternions
            frames += [(f"link{i}", p, q) for i, (p, q) in enumerate(zip(w.link_positions, quats))]
        if w.ee is not None:
            frames.append(("ee", w.ee, None))
        if w.cube is not None:
            frames.append(("cube", w.cube, None))
        if not frames:
            return
        ns = self.start_ns + int(w.time_s * 1e9)
        stamp = {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}
        transforms = [
            {
                "timestamp": stamp,
                "parent_frame_id": "world",
                "child_frame_id": name,
                "translation": dict(zip("xyz", np.asarray(p, np.float64).tolist())),
                "rotation": dict(zip("xyzw", _IDENTITY if q is None else np.asarray(q, np.float64).tolist())),
            }
            for name, p, q in frames
        ]
        self._write("/tf", w.time_s, {"transforms": transforms})
        self.out.flush()

    def flush(self) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.close()
