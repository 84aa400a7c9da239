"""How both 3D views (Rerun, Foxglove) draw the world: sizes and colours (RGBA, 0..1)."""

from __future__ import annotations

TABLE_TOP_THICKNESS = 0.03  # m: the table drawn as its top only, so it frames the arm instead of filling the view
LINK_RADIUS = 0.04  # m: the arm's links as capsules this thick
FAULT_MARKER_RADIUS = 0.07  # m: the sphere around a faulty joint
ARM = (0.25, 0.75, 0.65, 1.0)
FAULTY = (0.95, 0.15, 0.1, 1.0)
TABLE = (0.6, 0.45, 0.3, 1.0)  # the simulator's colours for table and cube
CUBE = (0.85, 0.2, 0.2, 1.0)
BOX = (0.95, 0.65, 0.1, 1.0)


def table_top(center: tuple[float, float, float], half_size: tuple[float, float, float]
              ) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(centre, half size) of the table's top slab, the part of the table the views draw."""
    top = center[2] + half_size[2]
    return (center[0], center[1], top - TABLE_TOP_THICKNESS / 2), (half_size[0], half_size[1], TABLE_TOP_THICKNESS / 2)
