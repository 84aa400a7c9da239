"""A simulated Panda's driver in another process: once its publishers under NAMESPACE are
matched and a line arrives on stdin, publishes the episode in OBSERVATIONS (a .npy of (T, 25)
observations on the model's 0.5 s clock) as a robot does: ``joint_states`` (JointState: the arm's
joints and fingers, and the end effector and gripper as named entries) and the finger pads'
``left_pad/wrench`` and ``right_pad/wrench`` (WrenchStamped), every 0.25 s of episode time
(midpoints interpolated, one more sample holding the last), at 40 Hz; first, with SKILL, the
skill's name on ``skill`` (String). Stamps are header stamps from the wall clock at the start.
Then waits for stdin to close.

    python panda_publisher.py NAMESPACE OBSERVATIONS [SKILL]
"""

import sys
import time

import numpy as np

from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus
from neural_asm.sim.channels import CHANNEL_NAMES

STATE = [n for n in CHANNEL_NAMES if not n.startswith(("left_", "right_"))]
PERIOD_S = 0.5

namespace, observations = sys.argv[1], np.load(sys.argv[2])
skill = sys.argv[3] if len(sys.argv) > 3 else None
bus = Bus(namespace)
writers = {"joint_states": bus.writer("joint_states", m.JOINT_STATE),
           "left_pad/wrench": bus.writer("left_pad/wrench", m.WRENCH_STAMPED),
           "right_pad/wrench": bus.writer("right_pad/wrench", m.WRENCH_STAMPED)}
labels = bus.writer("skill", m.STRING) if skill else None
for writer in [*writers.values(), *([labels] if labels else [])]:
    if not writer.wait_for_subscribers(1, timeout_s=60):
        sys.exit(f"panda_publisher: no subscriber of {writer.topic} matched within 60 s")
sys.stdin.readline()
T = m.STORE.types
if labels is not None:
    labels.write(T[m.STRING](data=skill))
steps = len(observations)
times = np.arange(2 * steps) * PERIOD_S / 2
values = np.stack([np.interp(times, np.arange(steps) * PERIOD_S, observations[:, j])
                   for j in range(observations.shape[1])], axis=1)
column = {name: j for j, name in enumerate(CHANNEL_NAMES)}
start = time.time_ns()


def vector(kind, row, side):
    return T["geometry_msgs/msg/Vector3"](**{a: float(row[column[f"{side}_{kind}{a}"]]) for a in "xyz"})


for t, row in zip(times, values):
    ns = start + round(t * 1e9)
    header = T[m.HEADER](stamp=T[m.TIME](sec=ns // 10**9, nanosec=ns % 10**9), frame_id="panda_link0")
    writers["joint_states"].write(T[m.JOINT_STATE](
        header=header, name=STATE, position=np.array([row[column[n]] for n in STATE]),
        velocity=np.zeros(0), effort=np.zeros(0)))
    for side in ("left", "right"):
        wrench = T["geometry_msgs/msg/Wrench"](force=vector("f", row, side), torque=vector("t", row, side))
        writers[f"{side}_pad/wrench"].write(T[m.WRENCH_STAMPED](header=header, wrench=wrench))
    time.sleep(1 / 40)  # the driver's rate, not a synchronisation
sys.stdin.read()
