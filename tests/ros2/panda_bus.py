"""The tests' bus: a simulated Panda's topics on a loopback DDS domain of their own, the node's
mapping of them, a node spinning in a thread with a listener of /diagnostics, and its messages."""

from __future__ import annotations

import random
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cyclonedds")

from neural_asm.logs.mapping import parse_mapping  # noqa: E402
from neural_asm.ros2 import messages as m  # noqa: E402
from neural_asm.ros2.bus import DEFAULT, Bus  # noqa: E402
from neural_asm.ros2.node import MonitorNode  # noqa: E402
from neural_asm.sim.channels import CHANNEL_NAMES, JOINT_NAMES  # noqa: E402


PUBLISHER = Path(__file__).with_name("panda_publisher.py")
DOMAIN = str(100 + random.randrange(100))
LOOPBACK = {"ROS_DOMAIN_ID": DOMAIN, "ROS_LOCALHOST_ONLY": "1"}
NAMESPACE = "/robot1"
FPR = 0.01
STEPS = 15


def channel(name: str) -> dict:
    if name.startswith(("left_", "right_")):
        side, axis = name.split("_")
        kind = {"f": "force", "t": "torque"}[axis[0]]
        return {"name": name, "topic": f"/{side}_pad/wrench", "field": f"wrench.{kind}.{axis[1]}", "units": "1"}
    return {"name": name, "topic": "/joint_states", "field": "position", "key": name, "units": "rad",
            "joint": name in JOINT_NAMES}


def mapping(label_topic: str | None = None):
    source = {"kind": "rosbag", "split": "gap", "gap_s": 2.0, "stamp": "header",
              **({"label_topic": label_topic} if label_topic else {})}
    return parse_mapping({"timing": {"period_s": 0.5, "steps": STEPS, "max_gap_s": 0.3}, "source": source,
                          "channels": [channel(n) for n in CHANNEL_NAMES]}, "the test's mapping")


def statuses(reader) -> list:
    return [s for r in reader.take() for s in r.message.status]


def values(status) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


class Running:
    """A node spinning in a thread on the loopback domain, and a listener of /diagnostics."""

    def __init__(self, found, judge, out: Path | None) -> None:
        self.listener = Bus(env=LOOPBACK)
        self.diagnostics = self.listener.reader("/diagnostics", m.DIAGNOSTIC_ARRAY, qos=DEFAULT)
        self.node = MonitorNode(Bus(NAMESPACE, env=LOOPBACK), found, judge, out)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.node.spin, args=(self.stop,))
        self.thread.start()
        self.said: list = []

    def until(self, done, timeout_s: float = 60) -> None:
        """Collect the statuses until one makes ``done`` true (or ``timeout_s``)."""
        deadline = time.monotonic() + timeout_s
        while not any(done(s) for s in self.said) and time.monotonic() < deadline:
            self.listener.wait(deadline - time.monotonic())
            self.said += statuses(self.diagnostics)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()


def joint_state(names: list[str], sec: int, nanosec: int):
    T = m.STORE.types
    header = T[m.HEADER](stamp=T[m.TIME](sec=sec, nanosec=nanosec), frame_id="")
    return T[m.JOINT_STATE](header=header, name=names, position=np.zeros(len(names)), velocity=np.zeros(0),
                            effort=np.zeros(0))


def wrench(sec: int, nanosec: int):
    T = m.STORE.types
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T[m.WRENCH_STAMPED](header=T[m.HEADER](stamp=T[m.TIME](sec=sec, nanosec=nanosec), frame_id=""),
                              wrench=T["geometry_msgs/msg/Wrench"](force=zero, torque=zero))


def writers(running: Running) -> dict:
    bus = Bus(NAMESPACE, env=LOOPBACK)
    found = {t: bus.writer(t, k) for t, k in (("joint_states", m.JOINT_STATE), ("left_pad/wrench", m.WRENCH_STAMPED),
                                               ("right_pad/wrench", m.WRENCH_STAMPED))}
    assert all(w.wait_for_subscribers(1, timeout_s=30) for w in found.values())
    assert all(r.wait_for_publishers(1, timeout_s=30) for r in running.node.readers)
    return found


STATE = [n for n in CHANNEL_NAMES if not n.startswith(("left_", "right_"))]


