"""Reading a robot's bags: throughput and peak memory on a bag of >= 1 GB, MCAP and sqlite3.

The benchmark writes one ROS 2 bag per storage with ``rosbags`` (1 kHz
sensor_msgs/msg/JointState of 7 joints, 500 Hz geometry_msgs/msg/WrenchStamped, an
``/episode`` marker every 30 s) in a temporary folder, reads each back through a channel
mapping in a fresh process (13 channels, 50 steps of 0.5 s per episode, log-time stamps), and
deletes the bags. A bag's size is its storage file's; the throughput is that size over the
read's wall time, the peak memory the reading process's maximum resident set.

Last line: one JSON object {logs_mb_per_s, logs_peak_rss_mb (the worse storage's), mcap: {...},
sqlite3: {...}}; each storage also gives logs_cpu_mb_per_s (size over the reader's CPU time:
what an idle core reaches when other work shares the machine). Targets: >= 50 MB/s and <= 400 MB. Run: python benchmarks/bench_logs.py
(``--gb`` sets the bag size; ``--stamp header`` reads header stamps, which decodes every message;
``--quick`` writes one episode, read in seconds: the test suite runs it so the script keeps
working, its numbers mean nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

JOINTS = [f"panda_joint{i}" for i in range(1, 8)]
JOINT_HZ, WRENCH_HZ, EPISODE_S = 1000, 500, 30
STEPS, PERIOD_S = 50, 0.5
START_NS = 1_700_000_000 * 10**9
STORAGES = ("mcap", "sqlite3")


def mapping(stamp: str) -> dict:
    channels = [{"name": f"joint{i + 1}", "topic": "/joint_states", "field": "position", "key": k, "units": "rad",
                 "joint": True} for i, k in enumerate(JOINTS)]
    channels += [{"name": f"{part[0]}{axis}", "topic": "/ee_wrench", "field": f"wrench.{part}.{axis}",
                  "units": "N" if part == "force" else "N m"} for part in ("force", "torque") for axis in "xyz"]
    return {"timing": {"period_s": PERIOD_S, "steps": STEPS, "max_gap_s": 0.1},
            "episodes": {"split": "marker", "marker_topic": "/episode", "label_topic": "/episode", "stamp": stamp},
            "channels": channels}


def write_bags(folder: Path, gigabytes: float) -> dict[str, Path]:
    """One bag per storage with the same messages, each serialised once for both; until the MCAP
    file reaches ``gigabytes``."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    writers = {s: Writer(folder / s, version=9, storage_plugin=StoragePlugin[s.upper()]) for s in STORAGES}
    conns: dict[str, dict[str, object]] = {}
    for s, w in writers.items():
        w.open()
        conns[s] = {t: w.add_connection(t, k, typestore=store) for t, k in (
            ("/joint_states", "sensor_msgs/msg/JointState"), ("/ee_wrench", "geometry_msgs/msg/WrenchStamped"),
            ("/episode", "std_msgs/msg/String"))}

    def header(ns: int) -> object:
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
                                        frame_id="panda_link0")

    def vector(v: np.ndarray) -> object:
        return T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))

    target = gigabytes * 1e9
    mcap = folder / "mcap" / "mcap.mcap"
    episode, rng = 0, np.random.default_rng(0)
    while True:
        start = START_NS + episode * EPISODE_S * 10**9
        marker = store.serialize_cdr(T["std_msgs/msg/String"](data=f"skill{episode % 3}"), "std_msgs/msg/String")
        rows = [(start, "/episode", marker)]
        t = np.arange(EPISODE_S * JOINT_HZ) / JOINT_HZ
        q = np.sin(t[:, None] * (0.2 + 0.1 * np.arange(7)) + episode) + 0.001 * rng.standard_normal((len(t), 7))
        for k in range(len(t)):
            ns = start + k * (10**9 // JOINT_HZ)
            msg = T["sensor_msgs/msg/JointState"](header=header(ns), name=JOINTS, position=q[k], velocity=q[k] * 0.1,
                                                  effort=q[k] * 10)
            rows.append((ns, "/joint_states", store.serialize_cdr(msg, "sensor_msgs/msg/JointState")))
            if k % (JOINT_HZ // WRENCH_HZ) == 0:
                w = T["geometry_msgs/msg/Wrench"](force=vector(q[k, :3] * 5), torque=vector(q[k, 3:6]))
                msg = T["geometry_msgs/msg/WrenchStamped"](header=header(ns), wrench=w)
                rows.append((ns, "/ee_wrench", store.serialize_cdr(msg, "geometry_msgs/msg/WrenchStamped")))
        for s, w in writers.items():
            for ns, topic, raw in rows:
                w.write(conns[s][topic], ns, raw)  # type: ignore[arg-type]
        episode += 1
        if mcap.exists() and mcap.stat().st_size >= target:
            break
    for w in writers.values():
        w.close()
    return {s: folder / s for s in STORAGES}


def read_one(bag: Path, mapping_file: Path) -> None:
    """In its own process: read the bag, print seconds, episodes and the peak resident set."""
    from neural_asm.logs.sources import load_log_sequences

    t0, cpu0 = time.perf_counter(), time.process_time()
    seqs = load_log_sequences(bag, mapping_file)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "episodes": len(seqs.data), "peak_rss_mb": peak_mb,
                      "warnings": len(seqs.warnings)}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gb", type=float, default=1.0, help="size of each bag (GB)")
    parser.add_argument("--stamp", choices=("log", "header"), default="log")
    parser.add_argument("--quick", action="store_true",
                        help="one episode per bag (seconds, not minutes): checks the script runs, measures nothing")
    parser.add_argument("--read", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--mapping", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.read:
        read_one(args.read, args.mapping)
        return
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory(prefix="bench_logs_") as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        bags = write_bags(folder, 0.0 if args.quick else args.gb)  # always at least one episode
        written_s = time.perf_counter() - t0
        mapping_file = folder / "mapping.yaml"
        mapping_file.write_text(yaml.safe_dump(mapping(args.stamp)))
        for storage, bag in bags.items():
            size_mb = sum(p.stat().st_size for p in bag.iterdir() if p.suffix in (".mcap", ".db3")) / 1e6
            out = subprocess.run([sys.executable, __file__, "--read", str(bag), "--mapping", str(mapping_file)],
                                 check=True, capture_output=True, text=True)
            run = json.loads(out.stdout.strip().splitlines()[-1])
            results[storage] = {"logs_mb_per_s": round(size_mb / run["seconds"], 1),
                                # what one otherwise idle core reaches; the wall-clock figure suffers from other load
                                "logs_cpu_mb_per_s": round(size_mb / run["cpu_seconds"], 1),
                                "logs_peak_rss_mb": round(run["peak_rss_mb"], 1), "bag_mb": round(size_mb, 1),
                                "read_seconds": round(run["seconds"], 1), "episodes": run["episodes"],
                                "warnings": run["warnings"]}
            print(storage, json.dumps(results[storage]), flush=True)
    print(json.dumps({"logs_mb_per_s": min(r["logs_mb_per_s"] for r in results.values()),
                      "logs_peak_rss_mb": max(r["logs_peak_rss_mb"] for r in results.values()),
                      "stamp": args.stamp, "write_seconds": round(written_s, 1),
                      "load_average_1min": round(os.getloadavg()[0], 2), **results}))


if __name__ == "__main__":
    main()
