"""An episode to an MCAP file that Foxglove opens as it is.

Run metadata is an MCAP Metadata record named ``run`` and, for readers of messages, the
``/metadata`` topic (once). Our own messages are JSON with JSON schemas (``neural_asm.X``):
``/observation``, ``/expected`` (what the model expected of the step), ``/prediction`` (its
forecast of the next step), ``/errors`` (weighted prediction errors) and ``/fault`` (energy,
threshold, their log ratio ``margin``, flag, isolated joint). The world is in Foxglove's
own messages, protobuf from foxglove-sdk: ``/tf`` (``foxglove.FrameTransforms``: link
frames, tool point and cube in ``world``), ``/scene`` (``foxglove.SceneUpdate``: the arm,
cube and falling box) and ``/scene/workcell`` (the table, once), registered with the
first world record (a service session's file has none).
Timestamps are the recorder's start time plus episode time. Flushed after every step.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from foxglove.messages import FrameTransform, FrameTransforms, Quaternion, SceneUpdate, Timestamp, Vector3

from neural_asm.recordings import foxglove_scene
from neural_asm.recordings import mcap_schemas as schemas
from neural_asm.recordings.foxglove_live import FoxgloveOut
from neural_asm.recordings.mcap_file import McapFile
from neural_asm.recordings.records import StepRecord, WorldRecord, Workcell

VECTOR_TOPICS = {
    "/observation": "the observation, original units",
    "/expected": "what the model expected of this step, original units",
    "/prediction": "the model's forecast of the next step, original units",
    "/errors": "prediction errors divided by their expected spread (the channels isolation ranks)",
}
FAULT, METADATA, TF, SCENE, WORKCELL = "/fault", "/metadata", "/tf", "/scene", "/scene/workcell"


class McapEpisode:
    def __init__(self, out: McapFile | FoxgloveOut, channel_names: tuple[str, ...], step_period_s: float) -> None:
        """Writes to ``out``: a file, or a live Foxglove server (``foxglove_live``)."""
        self.channel_names = channel_names
        self.step_period_s = step_period_s
        self.start_ns = time.time_ns()
        self.workcell: Workcell | None = None  # the one drawn on WORKCELL
        self.out = out
        self.channels = {
            topic: self.out.channel(topic, schemas.channel_vector(f"neural_asm.{topic[1:].capitalize()}", doc, channel_names))
            for topic, doc in VECTOR_TOPICS.items()
        }
        self.channels[FAULT] = self.out.channel(FAULT, schemas.FAULT)
        self.channels[METADATA] = self.out.channel(METADATA, schemas.METADATA)

    def _world_channel(self, topic: str) -> Any:
        """A world topic's channel, registered with its first message: a file without a world
        (a service session's) carries no Foxglove schemas."""
        if topic not in self.channels:
            message_type = FrameTransforms if topic == TF else SceneUpdate
            self.channels[topic] = self.out.foxglove_channel(topic, message_type.get_schema())
        return self.channels[topic]

    def _ns(self, time_s: float) -> int:
        return self.start_ns + int(time_s * 1e9)

    def _write(self, topic: str, time_s: float, message: dict[str, Any]) -> None:
        self.out.write(self.channels[topic], self._ns(time_s), message)

    def _wanted(self, topic: str) -> bool:
        """Whether to build ``topic``'s message: a world topic not yet registered is (its first
        message registers it, so that a live viewer can subscribe)."""
        return topic not in self.channels or self.out.wants(self.channels[topic])

    def write_metadata(self, metadata: dict[str, Any]) -> None:
        self.out.metadata("run", metadata)
        self._write(METADATA, 0.0, metadata)
        self.out.flush()

    def _named(self, step: int, values: np.ndarray) -> dict[str, Any]:
        return {"step": step, **dict(zip(self.channel_names, np.asarray(values, np.float64).tolist()))}

    def write_step(self, r: StepRecord) -> None:
        t = r.step * self.step_period_s if r.time_s is None else r.time_s
        vectors = {"/observation": r.observation, "/expected": r.expected, "/prediction": r.prediction, "/errors": r.errors}
        for topic, values in vectors.items():
            if values is not None and self._wanted(topic):
                self._write(topic, t, self._named(r.step, values))
        if r.energy is not None and self._wanted(FAULT):
            self._write(FAULT, t, {"step": r.step, "energy": r.energy, "threshold": r.threshold, "margin": r.margin,
                                   "fault": r.fault, "isolated_joint": r.isolated_joint})
        self.out.flush()

    def write_world(self, w: WorldRecord) -> None:
        ns = self._ns(w.time_s)
        stamp = Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)
        if w.workcell is not None and w.workcell != self.workcell:
            self.workcell = w.workcell
            self.out.write_encoded(self._world_channel(WORKCELL), ns, foxglove_scene.workcell_update(w.workcell, stamp).encode())
        if self._wanted(SCENE) and (scene := foxglove_scene.world_update(w, stamp)) is not None:
            self.out.write_encoded(self._world_channel(SCENE), ns, scene.encode())
        if self._wanted(TF) and (transforms := _frames(w, stamp)):
            self.out.write_encoded(self._world_channel(TF), ns, FrameTransforms(transforms=transforms).encode())
        self.out.flush()

    def flush(self) -> None:
        self.out.flush()

    def close(self) -> None:
        self.out.close()


def _frames(w: WorldRecord, stamp: Timestamp) -> list[FrameTransform]:
    """Link frames, tool point and cube as children of ``world``."""
    frames: list[tuple[str, Any, Any]] = []
    if w.link_positions is not None:
        quats = [None] * len(w.link_positions) if w.link_quaternions is None else w.link_quaternions
        frames += [(f"link{i}", p, q) for i, (p, q) in enumerate(zip(w.link_positions, quats))]
    if w.ee is not None:
        frames.append(("ee", w.ee, None))
    if w.cube is not None:
        frames.append(("cube", w.cube, None))
    transforms = []
    for name, p, q in frames:
        x, y, z = np.asarray(p, np.float64).tolist()
        qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if q is None else np.asarray(q, np.float64).tolist()
        transforms.append(FrameTransform(timestamp=stamp, parent_frame_id=foxglove_scene.FRAME, child_frame_id=name,
                                         translation=Vector3(x=x, y=y, z=z),
                                         rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
    return transforms
