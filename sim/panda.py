"""Franka Emika Panda arm and two-finger hand, built with `dm_control.mjcf`.

Kinematics come straight from Franka's published modified-DH table (FCI documentation):
each link frame is placed relative to its parent by Rot_x(alpha) Trans_x(a) Trans_z(d), and
every joint turns about its own z axis. Joint position, velocity and torque limits and link
masses, centres of mass and inertias are Franka's published / identified values (the same
numbers MuJoCo Menagerie uses). Geometry is primitive capsules and boxes: collision only needs
the right volume, and no mesh files have to ship.

Actuation: one position servo per joint (gains in `sim.config.Servo`, force clipped to the
torque limits), gravity compensation on the arm links, one gripper actuator driving both
fingers through a tendon, and a force and a torque sensor on each finger pad.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dm_control import mjcf

from neural_asm.sim.config import SIM, Servo

# Franka's modified DH parameters (a, d, alpha) for joints 1..7 and the flange.
DH_A = (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088, 0.0)
DH_D = (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0, 0.107)
DH_ALPHA = (0.0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, np.pi / 2, 0.0)
HAND_YAW = -np.pi / 4  # the hand is mounted at -45 deg about the flange z axis
TCP_OFFSET = 0.1034  # flange to the tool centre point between the fingertips

Q_MIN = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
Q_MAX = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])
DQ_MAX = np.array([2.175, 2.175, 2.175, 2.175, 2.61, 2.61, 2.61])
TAU_MAX = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])

# (mass kg, centre of mass, full inertia xx yy zz xy xz yz) of links 0..7 (Gaz et al. 2019).
LINK_INERTIA = (
    (0.629769, (-0.041018, -0.00014, 0.049974), (0.00315, 0.00388, 0.004285, 8.2904e-7, 0.00015, 8.2299e-6)),
    (4.970684, (0.003875, 0.002081, -0.04762), (0.70337, 0.70661, 0.009117, -0.000139, 0.006772, 0.019169)),
    (0.646926, (-0.003141, -0.02872, 0.003495), (0.007962, 0.02811, 0.025995, -0.003925, 0.010254, 0.000704)),
    (3.228604, (0.027518, 0.039252, -0.066502), (0.037242, 0.036155, 0.01083, -0.004761, -0.011396, -0.012805)),
    (3.587895, (-0.05317, 0.104419, 0.027454), (0.025853, 0.019552, 0.028323, 0.007796, -0.001332, 0.008641)),
    (1.225946, (-0.011953, 0.041065, -0.038437), (0.035549, 0.029474, 0.008627, -0.002117, -0.004037, 0.000229)),
    (1.666555, (0.060149, -0.014117, -0.010517), (0.001964, 0.004354, 0.005433, 0.000109, -0.001158, 0.000341)),
    (0.735522, (0.010517, -0.004252, 0.061597), (0.012516, 0.010027, 0.004815, -0.000428, -0.001196, -0.000741)),
)
HAND_MASS, FINGER_MASS = 0.73, 0.015

# Collision capsules per link, in the link's own frame: (from xyz, to xyz, radius).
LINK_CAPSULES = (
    ((0, 0, 0.02), (0, 0, 0.2), 0.07),
    ((0, 0, -0.19), (0, 0, 0.0), 0.065),
    ((0, 0, -0.06), (0, -0.2, 0.0), 0.065),
    ((0, 0, -0.2), (0.0825, 0, 0), 0.06),
    ((0, 0, 0), (-0.0825, 0.11, 0), 0.06),
    ((0, 0.05, -0.26), (0, 0, -0.02), 0.055),
    ((0, 0, -0.01), (0.088, 0, 0), 0.055),
    ((0, 0, 0.0), (0, 0, 0.08), 0.045),
)

# Contact bits: the arm touches the world but never itself (neighbouring capsules overlap).
ARM_CONTYPE, ARM_CONAFFINITY = 2, 1


@dataclass
class PandaHandles:
    """Element handles of one Panda, for `physics.bind(...)`."""

    root: mjcf.RootElement
    joints: list[mjcf.Element]
    actuators: list[mjcf.Element]
    gripper: mjcf.Element
    finger_joints: list[mjcf.Element]
    hand: mjcf.Element
    tcp: mjcf.Element
    force_sensors: list[mjcf.Element]  # left, right
    torque_sensors: list[mjcf.Element]  # left, right
    lock_equalities: list[mjcf.Element]  # disabled brakes, one per joint (used by faults)


def dh_frame(i: int) -> tuple[np.ndarray, np.ndarray]:
    """Position and quaternion of link i+1 in link i's frame: Rot_x(alpha) Trans_x(a) Trans_z(d)."""
    a, d, alpha = DH_A[i], DH_D[i], DH_ALPHA[i]
    pos = np.array([a, -np.sin(alpha) * d, np.cos(alpha) * d])
    quat = np.array([np.cos(alpha / 2), np.sin(alpha / 2), 0.0, 0.0])
    return pos, quat


def _add_link_inertial(body: mjcf.Element, i: int) -> None:
    mass, com, inertia = LINK_INERTIA[i]
    body.add("inertial", pos=com, mass=mass, fullinertia=inertia)


def _add_finger(hand: mjcf.Element, side: str, servo: Servo) -> tuple[mjcf.Element, mjcf.Element]:
    """A slide finger whose joint value is its distance from the hand's centre line."""
    quat = (1, 0, 0, 0) if side == "left" else (0, 0, 0, 1)
    finger = hand.add("body", name=f"{side}_finger", pos=(0, 0, 0.0584), quat=quat)
    finger.add("inertial", pos=(0, 0.006, 0.025), mass=FINGER_MASS, diaginertia=(2.375e-6, 2.375e-6, 7.5e-7))
    joint = finger.add("joint", name=f"{side}_finger_joint", type="slide", axis=(0, 1, 0),
                       range=(0, servo.gripper_open_m), damping=2.0, armature=0.01)
    finger.add("geom", name=f"{side}_pad", type="box", size=(0.011, 0.006, 0.025), pos=(0, 0.006, 0.025),
               friction=(1.5, 0.02, 0.002), condim=4, contype=ARM_CONTYPE, conaffinity=ARM_CONAFFINITY,
               rgba=(0.2, 0.2, 0.2, 1))
    site = finger.add("site", name=f"{side}_pad", pos=(0, 0, 0.025), size=(0.005,))
    return joint, site


def build_panda(servo: Servo = SIM.servo) -> PandaHandles:
    """Build the arm, hand, servos and finger force/torque sensors."""
    root = mjcf.RootElement(model="panda")
    root.compiler.angle = "radian"
    root.default.geom.rgba = (0.9, 0.9, 0.92, 1)

    parent = root.worldbody.add("body", name="link0")
    _add_link_inertial(parent, 0)
    joints = []
    for i in range(7):
        pos, quat = dh_frame(i)
        body = parent.add("body", name=f"link{i + 1}", pos=pos, quat=quat, gravcomp=1)
        _add_link_inertial(body, i + 1)
        joints.append(body.add("joint", name=f"joint{i + 1}", axis=(0, 0, 1), range=(Q_MIN[i], Q_MAX[i]),
                               armature=0.1, damping=1.0))
        parent = body
    for i, (p0, p1, r) in enumerate(LINK_CAPSULES):
        body = root.find("body", f"link{i}")
        body.add("geom", name=f"link{i}_geom", type="capsule", fromto=(*p0, *p1), size=(r,),
                 contype=ARM_CONTYPE, conaffinity=ARM_CONAFFINITY)

    flange_pos, _ = dh_frame(7)
    hand = parent.add("body", name="hand", pos=flange_pos, quat=(np.cos(HAND_YAW / 2), 0, 0, np.sin(HAND_YAW / 2)),
                      gravcomp=1)
    hand.add("inertial", pos=(-0.01, 0, 0.03), mass=HAND_MASS, diaginertia=(0.001, 0.0025, 0.0017))
    hand.add("geom", name="hand_geom", type="box", size=(0.03, 0.1, 0.025), pos=(0, 0, 0.03),
             contype=ARM_CONTYPE, conaffinity=ARM_CONAFFINITY)
    tcp = hand.add("site", name="tcp", pos=(0, 0, TCP_OFFSET), size=(0.005,))
    left_joint, left_site = _add_finger(hand, "left", servo)
    right_joint, right_site = _add_finger(hand, "right", servo)

    root.equality.add("joint", name="finger_coupling", joint1=left_joint, joint2=right_joint, polycoef=(0, 1, 0, 0, 0))
    tendon = root.tendon.add("fixed", name="grip")
    tendon.add("joint", joint=left_joint, coef=0.5)
    tendon.add("joint", joint=right_joint, coef=0.5)

    actuators = [
        root.actuator.add("position", name=f"servo{i + 1}", joint=j, kp=servo.kp[i], kv=servo.kv[i],
                          forcerange=(-TAU_MAX[i], TAU_MAX[i]))
        for i, j in enumerate(joints)
    ]
    gripper = root.actuator.add("position", name="gripper", tendon=tendon, kp=servo.gripper_kp, kv=servo.gripper_kv,
                                ctrlrange=(0, servo.gripper_open_m),
                                forcerange=(-servo.gripper_force_n, servo.gripper_force_n))
    force_sensors = [root.sensor.add("force", name=f"{s.name}_force", site=s) for s in (left_site, right_site)]
    torque_sensors = [root.sensor.add("torque", name=f"{s.name}_torque", site=s) for s in (left_site, right_site)]
    lock_equalities = [root.equality.add("joint", name=f"lock{i + 1}", joint1=j, active=False,
                                         polycoef=(0, 0, 0, 0, 0), solref=(0.005, 1))
                       for i, j in enumerate(joints)]
    return PandaHandles(root, joints, actuators, gripper, [left_joint, right_joint], hand, tcp,
                        force_sensors, torque_sensors, lock_equalities)


def dh_frames(q: np.ndarray) -> list[np.ndarray]:
    """4x4 poses of the base, the 8 DH frames (Franka's table) and the tool centre point,
    from the DH product alone (a reference independent of the MJCF)."""
    pose = np.eye(4)
    frames = [pose]
    for i in range(8):
        a, d, alpha = DH_A[i], DH_D[i], DH_ALPHA[i]
        theta = q[i] if i < 7 else 0.0
        ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(theta), np.sin(theta)
        pose = pose @ np.array([[ct, -st, 0, a], [st * ca, ct * ca, -sa, -d * sa],
                                [st * sa, ct * sa, ca, d * ca], [0, 0, 0, 1]])
        frames.append(pose)
    c, s = np.cos(HAND_YAW), np.sin(HAND_YAW)
    frames.append(pose @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, TCP_OFFSET], [0, 0, 0, 1]]))
    return frames


def dh_forward(q: np.ndarray) -> np.ndarray:
    """4x4 pose of the tool centre point from Franka's DH table."""
    return dh_frames(q)[-1]
