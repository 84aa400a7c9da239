"""A robot's driver in another process: once its ``joint_states`` publisher (ROS 2's default
QoS, under the namespace given) is matched and a line arrives on stdin, publishes COUNT
JointState messages at 40 Hz, message i holding i in its stamp and positions, then waits for
stdin to close.

    python joint_state_publisher.py NAMESPACE COUNT
"""

import sys
import time

import numpy as np

from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus

JOINTS = [f"panda_joint{j}" for j in range(1, 8)]

namespace, count = sys.argv[1], int(sys.argv[2])
writer = Bus(namespace).writer("joint_states", m.JOINT_STATE)
if not writer.wait_for_subscribers(1, timeout_s=60):
    sys.exit("joint_state_publisher: no subscriber matched within 60 s")
sys.stdin.readline()
T = m.STORE.types
for i in range(count):
    header = T[m.HEADER](stamp=T[m.TIME](sec=i, nanosec=0), frame_id="panda_link0")
    writer.write(T[m.JOINT_STATE](header=header, name=JOINTS, position=np.full(7, float(i)),
                                  velocity=np.zeros(7), effort=np.zeros(0)))
    time.sleep(1 / 40)  # the driver's rate, not a synchronisation
sys.stdin.read()
