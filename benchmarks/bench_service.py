"""Latency and throughput of the service, over real sockets on loopback.

The service runs under uvicorn in a subprocess (so the client does not share its
GIL) with a paper-sized model (H=256, K=100, 25 channels) trained briefly on the
built-in synthetic skills. Measured: /healthz and /predict round trips over HTTP with
one client, websocket steps with one client, and the steps per second of 64 concurrent
websocket sessions (where the runner micro-batches). Prints one JSON object last.

With ``--record`` the service is measured twice in the same run, without recording
(the reference) and with it, and the keys ``*_vs_no_record`` are the ratios (the
machine may be shared: absolute numbers move, same-run ratios less).
``rss_growth_mb_per_1000_sessions`` is the growth of the service's resident memory
(its process and the recorder's) over recorded sessions opened, stepped 15 times and
closed, after a warm-up: the slope through five readings.

    python benchmarks/bench_service.py [--record] [--steps 400] [--sessions 1000]
"""

import runtime  # noqa: F401  (first: one BLAS thread, no display)

import argparse
import os
import asyncio
import json
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import numpy as np
import orjson
import websockets

from models import checkpoint
from models.asm import NeuralASM
from models.config import FAST
from models.synthetic import make_skills
from recordings.recorder import POLL_S

CHANNELS = tuple(f"joint{i}" for i in range(1, 8)) + tuple(f"ch{i}" for i in range(18))


# Online recall: inference (K iterations) on every step, the costlier of the two modes.
SESSION = {"mode": "online"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def percentiles(ms: list[float]) -> tuple[float, float]:
    return float(np.percentile(ms, 50)), float(np.percentile(ms, 99))


def build_model(folder: Path) -> np.ndarray:
    data = make_skills(n_skills=2, repetitions=10, channels=25)
    model = NeuralASM.fit(data.data, CHANNELS, FAST.with_(epochs=60), progress=False)
    model.calibrate(data.data, data.data, SESSION["mode"], 1)
    checkpoint.save(model, folder / "bench.safetensors")
    return data.data


def start_server(folder: Path, port: int, record: bool) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "service.cli", "serve", "--port", str(port), "--models-dir", str(folder),
           "--recordings-dir", str(folder / "rec"), "--log-level", "warning", "--max-sessions", "128",
           "--max-sessions-per-client", "128",
           "--record" if record else "--no-record"]
    proc = subprocess.Popen(cmd)
    deadline = time.monotonic() + 300  # importing torch on a loaded machine can take a while
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if httpx.get(f"http://127.0.0.1:{port}/healthz").status_code == 200:
                return proc
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError(f"service did not start (exit code {proc.poll()})")


def http_latencies(url: str, episodes: np.ndarray, steps: int) -> dict[str, float]:
    out: dict[str, list[float]] = {"healthz": [], "predict": []}
    with httpx.Client(base_url=url) as c:
        for _ in range(steps):
            t = time.perf_counter()
            c.get("/healthz")
            out["healthz"].append((time.perf_counter() - t) * 1e3)
        sid, k = None, 0
        for i in range(steps):
            if k == 0:
                sid = c.post("/sessions", json=SESSION).json()["session_id"]
            body = {"session_id": sid, "observation": episodes[i % len(episodes), k].tolist()}
            t = time.perf_counter()
            r = c.post("/predict", json=body)
            out["predict"].append((time.perf_counter() - t) * 1e3)
            assert r.status_code == 200, r.text
            k = (k + 1) % episodes.shape[1]
            if k == 0:
                c.delete(f"/sessions/{sid}")
    result = {}
    for name, ms in out.items():
        result[f"{name}_p50_ms"], result[f"{name}_p99_ms"] = percentiles(ms[10:])
    return result


async def ws_session(url: str, episodes: np.ndarray, steps: int, seed: int) -> tuple[list[float], list[int]]:
    """One client's steps, each sent after the previous reply. The clients share this process's
    core with each other, so they use orjson: parsing the ~3 kB replies is not the service's time."""
    times, batches = [], []
    async with websockets.connect(url) as ws:
        await ws.recv()
        k = 0
        for i in range(steps):
            if k == 0:
                await ws.send(orjson.dumps({"type": "start", **SESSION}).decode())
                await ws.recv()
            x = episodes[(seed + i) % len(episodes), k].tolist()
            t = time.perf_counter()
            await ws.send(orjson.dumps({"type": "step", "observation": x}).decode())
            reply = orjson.loads(await ws.recv())
            times.append((time.perf_counter() - t) * 1e3)
            batches.append(reply["batch_size"])
            k = (k + 1) % episodes.shape[1]
    return times, batches


def tree_rss_mb(pid: int) -> float:
    """Resident memory of a process and all its descendants (the recorder process)."""
    total, todo = 0.0, [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/statm") as f:
                total += int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except FileNotFoundError:
            continue
    return total


async def recorded_sessions(url: str, episodes: np.ndarray, n: int) -> None:
    """Sessions opened, stepped 15 times and closed, one after another on one connection."""
    async with websockets.connect(url) as ws:
        await ws.recv()
        for i in range(n):
            await ws.send(json.dumps({"type": "start", **SESSION}))
            assert json.loads(await ws.recv())["type"] == "started"
            for x in episodes[i % len(episodes), :15]:
                await ws.send(json.dumps({"type": "step", "observation": x.tolist()}))
                await ws.recv()
            await ws.send(json.dumps({"type": "end"}))
            assert json.loads(await ws.recv())["type"] == "ended"


def settled_rss_mb(pid: int) -> float:
    """After the recorder's once-a-second sweep has freed the closed sessions' Rerun streams."""
    time.sleep(3 * POLL_S)
    return tree_rss_mb(pid)


def rss_growth(url: str, pid: int, episodes: np.ndarray, sessions: int, samples: int = 5) -> float:
    """MB per 1000 sessions: the slope of a line through the RSS read after each of ``samples``
    rounds (one reading alone moves by a few MB with the allocator's and Rerun's pools)."""
    asyncio.run(recorded_sessions(url, episodes, sessions // 4))  # warm-up: pools, caches, lazy imports
    done, rss = [0], [settled_rss_mb(pid)]
    for _ in range(samples - 1):
        asyncio.run(recorded_sessions(url, episodes, sessions // (samples - 1)))
        done.append(done[-1] + sessions // (samples - 1))
        rss.append(settled_rss_mb(pid))
    return float(np.polyfit(done, rss, 1)[0]) * 1000


async def fleet(url: str, episodes: np.ndarray, sessions: int, steps: int) -> tuple[float, float]:
    start = time.perf_counter()
    results = await asyncio.gather(*(ws_session(url, episodes, steps, s) for s in range(sessions)))
    elapsed = time.perf_counter() - start
    batches = [b for _, bs in results for b in bs]
    return sessions * steps / elapsed, float(np.mean(batches))


def measure(folder: Path, episodes: np.ndarray, record: bool, args: argparse.Namespace) -> dict[str, float]:
    port = free_port()
    proc = start_server(folder, port, record)
    try:
        result = http_latencies(f"http://127.0.0.1:{port}", episodes, args.steps)
        ws_url = f"ws://127.0.0.1:{port}/stream"
        ws_times, _ = asyncio.run(ws_session(ws_url, episodes, args.steps, 0))
        result["ws_p50_ms"], result["ws_p99_ms"] = percentiles(ws_times[10:])
        result["fleet_steps_per_s"], result["fleet_mean_batch"] = asyncio.run(
            fleet(ws_url, episodes, 64, args.fleet_steps))
        if record:
            result["rss_growth_mb_per_1000_sessions"] = rss_growth(ws_url, proc.pid, episodes, args.sessions)
    finally:
        proc.terminate()
        proc.wait(30)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=400, help="steps per latency measurement")
    parser.add_argument("--fleet-steps", type=int, default=60, help="steps per session in the fleet")
    parser.add_argument("--sessions", type=int, default=1000, help="recorded sessions for the memory growth")
    parser.add_argument("--record", action="store_true", help="let the service record every session")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        episodes = build_model(folder)
        if args.record:
            reference = measure(folder, episodes, False, args)
            result = measure(folder, episodes, True, args)
            for key in ("fleet_steps_per_s", "predict_p99_ms", "ws_p99_ms"):
                result[f"{key}_no_record"] = reference[key]
                result[f"{key}_vs_no_record"] = result[key] / reference[key]
        else:
            result = measure(folder, episodes, False, args)
    result.update(record=args.record, hidden_size=FAST.hidden_size, inference_steps=FAST.inference_steps)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in result.items()}))


if __name__ == "__main__":
    main()
