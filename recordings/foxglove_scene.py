"""The world of a ``WorldRecord`` as Foxglove ``SceneUpdate`` messages (foxglove-sdk types).

Foxglove's 3D panel draws these as they are: the arm as cylinders between consecutive link
origins with a sphere at each, the cube and the falling box as cubes, all in frame ``world``.
The table, which never moves, is an update of its own (written once, on its own topic, so
that a seek finds it as the latest message of that topic).
"""

from __future__ import annotations

import numpy as np
from foxglove.messages import (Color, CubePrimitive, CylinderPrimitive, Pose, Quaternion, SceneEntity, SceneUpdate,
                               SpherePrimitive, Timestamp, Vector3)

from neural_asm.recordings import drawing
from neural_asm.recordings.records import WorldRecord, Workcell

FRAME = "world"
_MIN_LINK_M = 1e-3  # consecutive origins closer than this (Franka's frames 1-2, 5-6) share a sphere


def _vector(v: np.ndarray | tuple[float, ...]) -> Vector3:
    x, y, z = (float(c) for c in v)
    return Vector3(x=x, y=y, z=z)


def _color(rgba: tuple[float, float, float, float]) -> Color:
    r, g, b, a = rgba
    return Color(r=r, g=g, b=b, a=a)


def _z_to(direction: np.ndarray) -> Quaternion:
    """The rotation taking +z onto the unit vector ``direction`` (a cylinder's axis is z)."""
    x, y, z = direction
    if z < -1 + 1e-9:
        return Quaternion(x=1.0, y=0.0, z=0.0, w=0.0)
    q = np.array([-y, x, 0.0, 1.0 + z])
    q /= np.linalg.norm(q)
    return Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))


def _cube(stamp: Timestamp, name: str, center: np.ndarray | tuple[float, ...], half: tuple[float, ...],
          rgba: tuple[float, float, float, float]) -> SceneEntity:
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id=name, cubes=[
        CubePrimitive(pose=Pose(position=_vector(center), orientation=Quaternion(w=1.0)),
                      size=_vector(2 * np.asarray(half, np.float64)), color=_color(rgba))])


def _arm(stamp: Timestamp, links: np.ndarray) -> SceneEntity:
    """A sphere at each distinct link origin, a cylinder from each to the next."""
    d = 2 * drawing.LINK_RADIUS
    color = _color(drawing.ARM)
    points = [links[0]]
    for p in links[1:]:
        if np.linalg.norm(p - points[-1]) >= _MIN_LINK_M:
            points.append(p)
    spheres = [SpherePrimitive(pose=Pose(position=_vector(p), orientation=Quaternion(w=1.0)),
                               size=Vector3(x=d, y=d, z=d), color=color) for p in points]
    cylinders = []
    for a, b in zip(points[:-1], points[1:]):
        length = float(np.linalg.norm(b - a))
        cylinders.append(CylinderPrimitive(pose=Pose(position=_vector((a + b) / 2), orientation=_z_to((b - a) / length)),
                                           size=Vector3(x=d, y=d, z=length), bottom_scale=1.0, top_scale=1.0,
                                           color=color))
    return SceneEntity(timestamp=stamp, frame_id=FRAME, id="arm", cylinders=cylinders, spheres=spheres)


def world_update(w: WorldRecord, stamp: Timestamp) -> SceneUpdate | None:
    """The arm, and with the workcell's sizes the cube and the falling box; None if nothing to draw."""
    entities = []
    if w.link_positions is not None:
        entities.append(_arm(stamp, np.asarray(w.link_positions, np.float64)))
    if w.workcell is not None and w.cube is not None:
        half = (w.workcell.cube_half_size,) * 3
        entities.append(_cube(stamp, "cube", w.cube, half, drawing.CUBE))
    if w.workcell is not None and w.box is not None:
        entities.append(_cube(stamp, "falling_box", w.box, w.workcell.box_half_size, drawing.BOX))
    return SceneUpdate(entities=entities) if entities else None


def workcell_update(cell: Workcell, stamp: Timestamp) -> SceneUpdate:
    center, half_size = drawing.table_top(cell.table_center, cell.table_half_size)
    return SceneUpdate(entities=[_cube(stamp, "table", center, half_size, drawing.TABLE)])
