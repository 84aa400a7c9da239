"""What the service benchmarks share: the model they serve, a server in a subprocess on a free
loopback port, and a fleet of websocket clients stepping at once (``bench_service.py``)."""

import asyncio
import os
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
import orjson
import websockets

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import FAST
from neural_asm.models.synthetic import make_skills
from neural_asm.sim.config import SIM

CHANNELS = tuple(f"joint{i}" for i in range(1, 8)) + tuple(f"ch{i}" for i in range(18))
FLEET = 64  # sessions stepping at once
WARM_STEPS = 20  # steps per session of the fleet that warms a server before one is measured

# Online recall: inference (K iterations) on every step, the costlier of the two modes; the
# sessions say the model's rate (`main` sets it).
SESSION: dict = {"mode": "online"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def percentiles(ms: list[float]) -> tuple[float, float]:
    return float(np.percentile(ms, 50)), float(np.percentile(ms, 99))


def build_model(folder: Path, rate: float) -> np.ndarray:
    """Train the benchmark's model on synthetic episodes of ``rate``'s length (15 or 300 steps)."""
    data = make_skills(n_skills=2, repetitions=10, channels=25, steps=SIM.timing.observations(rate))
    model = NeuralASM.fit(data.data, CHANNELS, FAST.with_(epochs=60), progress=False, rate_hz=rate)
    model.calibrate(data.data, data.data, SESSION["mode"], 1)
    checkpoint.save(model, folder / "bench.safetensors")
    return data.data


def start_server(folder: Path, port: int, record: bool, extra: tuple[str, ...] = ()) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "neural_asm.service.cli", "serve", "--port", str(port), "--models-dir", str(folder),
           "--recordings-dir", str(folder / "rec"), "--log-level", "warning", "--max-sessions", "128",
           "--max-sessions-per-client", "128",
           "--record" if record else "--no-record", *extra]
    proc = subprocess.Popen(cmd)
    wait_until_up(proc, f"http://127.0.0.1:{port}/healthz")
    return proc


def wait_until_up(proc: subprocess.Popen, url: str) -> None:
    deadline = time.monotonic() + 300  # importing torch on a loaded machine can take a while
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            if httpx.get(url).status_code == 200:
                return
        except httpx.TransportError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError(f"server did not start (exit code {proc.poll()})")


async def ws_session(
    url: str, episodes: np.ndarray, steps: int, seed: int, connected: asyncio.Barrier | None = None
) -> tuple[list[float], list[int]]:
    """One client's steps, each sent after the previous reply (the first once every client of
    ``connected`` is connected). The clients share this process's core with each other, so
    they use orjson: parsing the ~3 kB replies is not the service's time."""
    times, batches = [], []
    async with websockets.connect(url) as ws:
        await ws.recv()
        if connected is not None:
            await connected.wait()
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


@dataclass(frozen=True)
class Fleet:
    steps_per_s: float  # from the moment every session is connected
    mean_batch: float
    connect_ms: float  # opening the connections, all at once


async def fleet(url: str, episodes: np.ndarray, sessions: int, steps: int) -> Fleet:
    """``sessions`` clients stepping episodes at once. Timed once all are connected: a robot
    keeps its connection, and 64 handshakes at once would otherwise weigh on a short run."""
    connected = asyncio.Barrier(sessions + 1)
    start = time.perf_counter()
    clients = [asyncio.create_task(ws_session(url, episodes, steps, s, connected)) for s in range(sessions)]
    await connected.wait()
    stepping = time.perf_counter()
    results = await asyncio.gather(*clients)
    elapsed = time.perf_counter() - stepping
    batches = [b for _, bs in results for b in bs]
    return Fleet(sessions * steps / elapsed, float(np.mean(batches)), (stepping - start) * 1e3)


def warm_fleet(url: str, episodes: np.ndarray, steps: int) -> Fleet:
    """64 sessions, measured after a 20-step fleet has warmed the server (its first sessions,
    the allocator's pools)."""
    asyncio.run(fleet(url, episodes, FLEET, WARM_STEPS))
    return asyncio.run(fleet(url, episodes, FLEET, steps))


def process_tree(pid: int) -> list[int]:
    """A process and all its descendants alive now (the recorder and live view processes)."""
    tree, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except FileNotFoundError:
            continue
        tree.append(p)
    return tree


def stat_of(pid: int, name: str, field: int) -> int:
    """Field ``field`` of ``/proc/PID/NAME`` (0 once the process is gone)."""
    try:
        with open(f"/proc/{pid}/{name}") as f:
            return int(f.read().split()[field])
    except FileNotFoundError:
        return 0


def tree_cpu_s(pid: int) -> float:
    """CPU seconds (user and system) used so far by a process and its live descendants."""
    total = 0
    for p in process_tree(pid):
        try:
            with open(f"/proc/{p}/stat") as f:
                fields = f.read().rsplit(")", 1)[1].split()  # after the command's name
        except FileNotFoundError:
            continue
        total += int(fields[11]) + int(fields[12])  # utime, stime
    return total / os.sysconf("SC_CLK_TCK")
