"""Many robots' messages into one ROS 2 monitor node process, beside the websocket service measured
in the same run on the same episodes.

64 simulated robots (namespaces ``/robot0`` ... ``/robot63``, each publishing ``joint_states``,
a ``sensor_msgs/msg/JointState``, and ``wrench``, a ``geometry_msgs/msg/WrenchStamped``) stream
one 300-step episode each of the benchmark's 40 Hz model (``service_harness.build_model``) at
the controller's pace, from one process of their own: robot r's tick k at k / 40 s plus its phase
r / 64 of a tick (independent robots' clocks are not aligned), as ``bench_service.py``'s paced
fleet sends its steps; one more tick completes the last step (a resampler judges a step once it
has seen past it). One node process (this one) reads them all: a ``MonitorNode`` per namespace on
one DDS participant (``Bus.under``), all spun by one thread (``Fleet``: the steps ready in a spin
judged together, as the service batches its sessions'), judging in-process with the memory's
monitor, nothing recorded, on loopback (``ROS_LOCALHOST_ONLY=1``). Measured:

- ``ros2_steps_per_s``: each robot's steps judged per second of its episode (its ticks' span,
  or longer if its last verdict came later), summed, as ``fleet_steps_per_s`` is: 2,560 when
  every robot was kept up with;
- ``ros2_lag_p50_ms`` / ``ros2_lag_p95_ms``: from the publication of the message that
  completes a step (its source time stamp) to the node's verdict on that step, published on
  ``/diagnostics``, ``nasm/fault`` and ``nasm/energy`` (one host, one clock);
- ``ros2_lost_messages``: messages published minus messages the nodes read (a reader's full
  history replacing its oldest sample counts here); ``ros2_dds_samples_lost``: those DDS itself
  reports lost on the way (its sample-lost status, summed over the readers); ``ros2_reader_peak``:
  the most messages one reader held when the node took them (its history keeps 1,000);
  ``ros2_publish_lag_p99_ms``: how late the robots' process itself sent a tick that was due
  (``websocket_send_lag_p99_ms`` is the websocket robots'; on a machine the nodes keep busy, the
  robots' process waits for a core too); ``ros2_warnings``: episodes a node ended on input it
  could not read; ``ros2_steps_judged`` (robots x steps when none was).

Each message's header is stamped with its tick's time, as a driver stamps its controller's tick,
and the node resamples by that stamp (``stamp = "header"``); the lag starts at its source time
stamp, when it was written.

Then the same episodes from 64 websocket sessions to ``nasm serve`` in a subprocess at the same
pace, in the same recall mode, nothing recorded (``bench_service.paced_fleet``):
``websocket_steps_per_s``, ``websocket_p50_ms`` / ``websocket_p99_ms`` (round trips), and
``ros2_vs_websocket`` = ros2_steps_per_s / websocket_steps_per_s.

    python benchmarks/bench_ros2.py [--robots 64] [--quick]

``--quick``: 4 robots, 40 ticks each, in seconds: the test suite runs it so the script keeps
working; its numbers mean nothing. Needs the ``ros2`` extra.
"""

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import argparse
import asyncio
import gc
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

import bench_service
from bench_service import paced_fleet
from neural_asm.logs.mapping import parse_mapping
from neural_asm.logs.rosbag import topic_groups
from neural_asm.models.answer import StepAnswer
from neural_asm.models.config import FAST
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus, Received
from neural_asm.ros2.judge import load_judge
from neural_asm.ros2.node import Due, Fleet, MonitorNode, topic_type
from neural_asm.ros2.play import Composer
from service_harness import CHANNELS, SESSION, build_model, free_port, start_server, warm_fleet

T = m.STORE.types
RATE = 40.0
FPR = 0.01
LOOPBACK = {"ROS_DOMAIN_ID": str(150 + os.getpid() % 80), "ROS_LOCALHOST_ONLY": "1"}
DRAIN_S = 3.0  # the nodes are done once nothing new was read for this long after the robots stopped


def mapping_doc(steps: int) -> dict[str, Any]:
    """The 25 model channels on a robot's two topics: the seven joints' positions, velocities and
    efforts (joint1..7, ch0..13) and the wrist wrench's force and torque x (ch14..17)."""
    joints = [f"joint{j}" for j in range(1, 8)]
    fields = ([("/joint_states", "position", j) for j in joints] + [("/joint_states", "velocity", j) for j in joints]
              + [("/joint_states", "effort", j) for j in joints]
              + [("/wrench", f"wrench.{f}", None) for f in ("force.x", "force.y", "force.z", "torque.x")])
    channels = [{"name": n, "topic": t, "field": f, "units": "1", "joint": n.startswith("joint"),
                 **({"key": k} if k else {})} for n, (t, f, k) in zip(CHANNELS, fields)]
    return {"timing": {"period_s": 1 / RATE, "steps": steps, "max_gap_s": 0.25},
            "source": {"kind": "rosbag", "split": "gap", "gap_s": 1.0, "stamp": "header"}, "channels": channels}


# ----------------------------------------------------------------------------- the robots' process

def publish(robots: int, episodes_path: Path) -> None:
    """The robots: once every writer is matched and a line arrives on stdin, robot r publishes
    episode r's ticks at its pace, then one more; prints what was published as JSON."""
    episodes = np.load(episodes_path)
    mapping = parse_mapping(mapping_doc(episodes.shape[1]), "the benchmark's mapping")
    bus = Bus()
    groups = topic_groups(mapping)
    topics = [g.source.removeprefix("topic ") for g in groups]
    composers = [Composer(g, topic_type(t, [c.field or "" for c in g.channels])) for g, t in zip(groups, topics)]
    writers = [[bus.writer(f"/robot{r}{t}", c.msgtype) for t, c in zip(topics, composers)] for r in range(robots)]
    ticks = [[[c.message(row[list(g.columns)], 0) for g, c in zip(groups, composers)]
              for row in np.vstack([ep, ep[-1:]])] for ep in episodes[:robots]]
    for writer in (w for ws in writers for w in ws):
        if not writer.wait_for_subscribers(1, 300):
            sys.exit(f"no node subscribed to {writer.topic}")
    print("ready", flush=True)
    sys.stdin.readline()
    period = 1 / RATE
    due = sorted((k * period + r * period / robots, r, k) for r in range(robots) for k in range(len(ticks[r])))
    start, start_ns, lags, published = time.perf_counter(), time.time_ns(), [], 0
    for at, r, k in due:
        time.sleep(max(0.0, start + at - time.perf_counter()))
        lags.append((time.perf_counter() - start - at) * 1e3)
        tick_ns = start_ns + round(at * 1e9)
        for writer, message in zip(writers[r], ticks[r][k]):
            # its header stamped with the tick's time, as a driver stamps its controller's tick (the node
            # resamples by it); its source time stamp (the lag's start) is when it is written
            message.header.stamp = T[m.TIME](sec=tick_ns // 10**9, nanosec=tick_ns % 10**9)
            writer.write(message)
            published += 1
    print(json.dumps({"published": published, "start_ns": start_ns, "publish_lag_p99_ms": float(np.percentile(lags, 99))}),
          flush=True)
    sys.stdin.read()


# ----------------------------------------------------------------------------- the node process

class TimedNode(MonitorNode):
    """A node that notes, for every step it judges, the time from the publication of the message
    that completed it to the verdict, counts the messages it read, and the most one reader held
    at a take (its history keeps ``MONITOR``'s depth: more would be lost)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self.read, self.lags_ns, self.verdicts_ns, self.warnings, self.peak = 0, [], [], [], 0

    def _warn(self, why: str, ep: Any) -> None:  # input it could not read: a WARN
        self.warnings.append(why)
        super()._warn(why, ep)

    def take(self, publications: Any) -> None:
        self.taken = [0] * len(self.readers)
        super().take(publications)
        self.peak = max(self.peak, *self.taken)

    def _sample(self, g: int, t: int, received: Received) -> None:
        self.read += 1
        self.taken[g] += 1
        super()._sample(g, t, received)

    def deliver(self, due: Due, answer: Any) -> None:
        super().deliver(due, answer)  # publishes the step's verdict
        if isinstance(answer, StepAnswer):
            now = time.time_ns()
            self.lags_ns.append(now - due.sent_ns)  # from the message that completed the step
            self.verdicts_ns.append(now)


def measure_ros2(folder: Path, episodes: np.ndarray, robots: int) -> dict[str, float]:
    steps = episodes.shape[1]
    mapping = parse_mapping(mapping_doc(steps), "the benchmark's mapping")
    judge, _ = load_judge(str(folder / "bench.safetensors"), None, FPR, folder)
    bus = Bus(env=LOOPBACK)
    nodes = [TimedNode(bus.under(f"/robot{r}"), mapping, judge, None) for r in range(robots)]
    stop = threading.Event()
    thread = threading.Thread(target=Fleet(bus, nodes).spin, args=(stop, 0.1), daemon=True)
    thread.start()
    np.save(folder / "episodes.npy", episodes)
    child = subprocess.Popen([sys.executable, __file__, "--publish", str(robots), str(folder / "episodes.npy")],
                             env={**os.environ, **LOOPBACK}, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdin is not None
        if child.stdout.readline().strip() != "ready":
            raise RuntimeError("the robots' process did not start")
        for node in nodes:
            for reader in node.readers:
                reader.wait_for_publishers(1, 60)
        child.stdin.write("go\n")
        child.stdin.flush()
        said = json.loads(child.stdout.readline())
        read = -1
        while read != sum(n.read for n in nodes):  # drain what is still on its way
            read = sum(n.read for n in nodes)
            time.sleep(DRAIN_S)
    finally:
        stop.set()
        child.kill()
        child.communicate()
    thread.join()
    period = 1 / RATE
    served = 0.0
    for r, node in enumerate(nodes):
        if node.verdicts_ns:
            span = (node.verdicts_ns[-1] - said["start_ns"]) / 1e9 - r * period / robots  # from its first tick
            served += len(node.verdicts_ns) / max(steps * period, span)
    lags_ms = [lag / 1e6 for n in nodes for lag in n.lags_ns]
    warnings = [w for n in nodes for w in n.warnings]
    return {"ros2_steps_per_s": served, "ros2_steps_judged": len(lags_ms),
            "ros2_lag_p50_ms": float(np.percentile(lags_ms, 50)) if lags_ms else float("nan"),
            "ros2_lag_p95_ms": float(np.percentile(lags_ms, 95)) if lags_ms else float("nan"),
            "ros2_published": said["published"], "ros2_lost_messages": said["published"] - sum(n.read for n in nodes),
            "ros2_dds_samples_lost": sum(n.lost() for n in nodes), "ros2_reader_peak": max(n.peak for n in nodes),
            "ros2_publish_lag_p99_ms": said["publish_lag_p99_ms"], "ros2_warnings": len(warnings),
            "ros2_first_warning": warnings[0] if warnings else ""}


def measure_websocket(folder: Path, episodes: np.ndarray) -> dict[str, float]:
    port = free_port()
    proc = start_server(folder, port, record=False)
    try:
        url = f"ws://127.0.0.1:{port}/stream"
        warm_fleet(url, episodes, 20)
        paced = asyncio.run(paced_fleet(url, episodes, RATE))
    finally:
        proc.terminate()
        proc.wait(30)
    return {"websocket_steps_per_s": paced.steps_per_s, "websocket_p50_ms": paced.p50_ms,
            "websocket_p99_ms": paced.p99_ms, "websocket_dropped_steps": paced.dropped_steps,
            "websocket_send_lag_p99_ms": paced.send_lag_p99_ms}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, default=64, help="robots (namespaces, websocket sessions)")
    parser.add_argument("--quick", action="store_true", help="4 robots, 40 ticks each: checks the script runs")
    parser.add_argument("--publish", nargs=2, metavar=("ROBOTS", "EPISODES"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.publish:
        publish(int(args.publish[0]), Path(args.publish[1]))
        return
    robots = 4 if args.quick else args.robots
    bench_service.FLEET = robots  # the websocket fleet as large as the nodes' (paced_fleet reads it)
    SESSION.update(mode="offline", rate_hz=RATE)  # as the node's monitor: the model is calibrated offline only
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        episodes = build_model(folder, RATE)
        episodes = np.stack([episodes[r % len(episodes)] for r in range(robots)])[:, :40 if args.quick else None]
        gc.collect()
        gc.freeze()
        result = measure_ros2(folder, episodes, robots)
        result.update(measure_websocket(folder, episodes))
    result["ros2_vs_websocket"] = result["ros2_steps_per_s"] / result["websocket_steps_per_s"]
    result.update(robots=robots, rate_hz=RATE, offered_steps_per_s=robots * RATE, steps_per_episode=episodes.shape[1],
                  hidden_size=FAST.hidden_size)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in result.items()}))


if __name__ == "__main__":
    main()
