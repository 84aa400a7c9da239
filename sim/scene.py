"""The workcell, composed with `dm_control.mjcf`: floor, table, cube, a parked falling box and two
parked posts (static mocap bodies the varied task stands on the table as obstacles).

The Panda's base sits at the world origin on the table's surface (z = 0), as a bench-mounted
arm does, so the table top is where a lowered hand first hits. The falling box hovers
out of reach, gravity-compensated (so it costs no contact solving), until a `FallingObject`
disturbance moves it above the arm and lets gravity act on it.
"""

from __future__ import annotations

from dataclasses import dataclass

from dm_control import mjcf

from neural_asm.sim.panda import ARM_CONTYPE, PandaHandles, build_panda

CUBE_HALF = 0.025  # a 5 cm cube, comfortably inside the Franka Hand's 8 cm stroke
CUBE_MASS = 0.1
BOX_HALF = (0.06, 0.06, 0.04)
BOX_PARK = (-1.5, 1.5, 1.0)  # hovering (gravity-compensated) behind the robot: no contacts to solve
POST_HALF = (0.025, 0.025, 0.125)  # a 25 cm post that a carried cube must go around, not over
POST_PARK = ((-1.5, -1.5, 0.0), (-1.7, -1.5, 0.0))  # where the two posts wait, off the table
TABLE_TOP, FLOOR_Z = 0.0, -0.75
TABLE_HALF = (0.45, 0.7, 0.375)
TABLE_CENTER = (0.35, 0.0, TABLE_TOP - TABLE_HALF[2])  # reaching 10 cm behind the Panda's base (the origin)
WORLD_CONTYPE, WORLD_CONAFFINITY = 1, 1 | ARM_CONTYPE


@dataclass
class SceneHandles:
    """Element handles of the composed scene."""

    root: mjcf.RootElement
    panda: PandaHandles
    cube: mjcf.Element  # free joint
    cube_body: mjcf.Element
    box: mjcf.Element  # free joint of the falling box
    box_body: mjcf.Element
    table: mjcf.Element
    posts: tuple[mjcf.Element, mjcf.Element]  # mocap bodies: the varied task's obstacle, a stray one


def build_scene(timestep_s: float) -> SceneHandles:
    """Compose the Panda into the workcell."""
    root = mjcf.RootElement(model="workcell")
    root.option.timestep = timestep_s
    root.option.cone = "elliptic"  # elliptic friction cones hold a pinched cube without creep
    root.option.impratio = 10
    contact = dict(contype=WORLD_CONTYPE, conaffinity=WORLD_CONAFFINITY)

    root.worldbody.add("light", pos=(0, 0, 3), dir=(0, 0, -1))
    root.worldbody.add("geom", name="floor", type="plane", size=(3, 3, 0.1), pos=(0, 0, FLOOR_Z),
                       rgba=(0.5, 0.55, 0.6, 1), **contact)
    table = root.worldbody.add("geom", name="table", type="box", size=TABLE_HALF, pos=TABLE_CENTER,
                               rgba=(0.6, 0.45, 0.3, 1), **contact)

    cube_body = root.worldbody.add("body", name="cube", pos=(0.5, 0, CUBE_HALF))
    cube = cube_body.add("freejoint", name="cube_free")
    cube_body.add("geom", name="cube_geom", type="box", size=(CUBE_HALF,) * 3, mass=CUBE_MASS,
                  friction=(1.0, 0.02, 0.002), condim=4, rgba=(0.85, 0.2, 0.2, 1), **contact)

    box_body = root.worldbody.add("body", name="falling_box", pos=BOX_PARK, gravcomp=1)
    box = box_body.add("freejoint", name="falling_box_free")
    box_body.add("geom", name="falling_box_geom", type="box", size=BOX_HALF, mass=5.0,
                 rgba=(0.3, 0.3, 0.8, 1), **contact)

    posts = []
    for name, park in zip(("post", "stray_post"), POST_PARK):
        post = root.worldbody.add("body", name=name, mocap=True, pos=park)
        post.add("geom", name=f"{name}_geom", type="box", size=POST_HALF, pos=(0, 0, POST_HALF[2]),
                 rgba=(0.2, 0.6, 0.3, 1), **contact)
        posts.append(post)

    panda = build_panda()
    root.attach(panda.root)
    return SceneHandles(root, panda, cube, cube_body, box, box_body, table, tuple(posts))
