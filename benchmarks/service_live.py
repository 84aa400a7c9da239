"""The cost of the service's metrics and live views, and the live view's lag (``bench_service.py --live``).

Three recording services run side by side: without metrics, with metrics, and with metrics and
both live views (a served Rerun view and a Foxglove server). The unpaced fleet steps each in
turn, in rounds whose order rotates: a round's three runs are seconds apart, and a shared
machine's load drifts over a run. ``metrics_vs_none`` and ``live_vs_files`` are the medians of
the rounds' throughput ratios, with their ranges (``*_min``, ``*_max``) beside them. Throughput
on a shared machine moves by 10-20 % from run to run whatever is measured, so the services' own
CPU time per step (the server and its recorder and live view processes,
``service_cpu_ms_per_step_*``) is given too: ``*_cpu_vs_*`` is the share of CPU per step the
reference spends, the cost that remains on a machine with no core to spare.
"""

import asyncio
import subprocess
import time
from pathlib import Path

import numpy as np
import orjson
import websockets

from service_harness import FLEET, SESSION, WARM_STEPS, free_port, start_server, tree_cpu_s, warm_fleet

SETUPS = {"none": ("--no-metrics",), "metrics": ("--metrics",), "live": ("--metrics",)}
# (what is compared, against what) -> (setup, reference setup): keys "<a>_vs_<b>" and "<a>_cpu_vs_<b>"
RATIOS = {("metrics", "none"): ("metrics", "none"), ("live", "files"): ("live", "metrics")}
NAMES = {"no_metrics": "none", "metrics": "metrics", "live": "live"}  # the keys' names for the setups


def live_flags() -> tuple[str, ...]:
    """Both live views, served on free loopback ports (no display here, or a viewer would pop up)."""
    return ("--live", "--live-grpc-port", str(free_port()), "--live-web-port", str(free_port()),
            "--foxglove", str(free_port()))


def start(folder: Path, setup: str) -> tuple[subprocess.Popen, str, tuple[str, ...]]:
    """A service of ``setup``, its websocket address and its live views' flags."""
    port, views = free_port(), live_flags() if setup == "live" else ()
    return start_server(folder, port, True, SETUPS[setup] + views), f"ws://127.0.0.1:{port}/stream", views


async def live_lag(url: str, foxglove_url: str, episode: np.ndarray, period_s: float) -> list[float]:
    """One robot at its pace; ms from its receipt of each answer to a Foxglove client's receipt of
    that step on ``/fault``."""
    answered: dict[int, float] = {}
    arrived: dict[int, float] = {}
    async with websockets.connect(foxglove_url, subprotocols=["foxglove.sdk.v1"]) as fox, \
            websockets.connect(url) as ws:
        await ws.recv()
        await ws.send(orjson.dumps({"type": "start", **SESSION}).decode())
        await ws.recv()
        channel = None
        while channel is None:  # the session's channels, advertised once its recorder opened them
            message = await fox.recv()
            if isinstance(message, str) and (op := orjson.loads(message))["op"] == "advertise":
                channel = next((c["id"] for c in op["channels"] if c["topic"] == "/fault"), None)
        await fox.send(orjson.dumps({"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel}]}).decode())
        await asyncio.sleep(0.5)  # subscribed before the first step

        async def listen() -> None:
            while len(arrived) < len(episode):
                message = await fox.recv()
                if isinstance(message, bytes) and message[0] == 1:
                    arrived[orjson.loads(message[13:])["step"]] = time.perf_counter()

        listener = asyncio.create_task(listen())
        start = time.perf_counter()
        for k, x in enumerate(episode.tolist()):
            await asyncio.sleep(max(0.0, start + k * period_s - time.perf_counter()))
            await ws.send(orjson.dumps({"type": "step", "observation": x}).decode())
            answered[orjson.loads(await ws.recv())["step"]] = time.perf_counter()
        await asyncio.wait_for(listener, 30)
    return [(arrived[k] - answered[k]) * 1e3 for k in answered]


def measure_live(folder: Path, episodes: np.ndarray, fleet_steps: int, rate_hz: float,
                 rounds: int) -> dict[str, float]:
    """Fleet steps/s and the services' CPU per step in each setup, round by round, and their
    paired ratios; then the lag."""
    servers = {setup: start(folder, setup) for setup in SETUPS}
    rates: dict[str, list[float]] = {setup: [] for setup in SETUPS}
    cpu_ms: dict[str, list[float]] = {setup: [] for setup in SETUPS}
    order = list(SETUPS)
    try:
        for r in range(rounds):
            for setup in order[r % len(order):] + order[:r % len(order)]:
                proc, url, _ = servers[setup]
                before = tree_cpu_s(proc.pid)
                rates[setup].append(warm_fleet(url, episodes, fleet_steps).steps_per_s)
                cpu_ms[setup].append((tree_cpu_s(proc.pid) - before) * 1e3 / (FLEET * (fleet_steps + WARM_STEPS)))
        proc, url, views = servers["live"]
        lags = asyncio.run(live_lag(url, f"ws://127.0.0.1:{views[-1]}", episodes[0], 1.0 / rate_hz))
    finally:
        for proc, _, _ in servers.values():
            proc.terminate()
        for proc, _, _ in servers.values():
            proc.wait(30)
    result = {f"fleet_steps_per_s_{name}": float(np.median(rates[setup])) for name, setup in NAMES.items()}
    result |= {f"service_cpu_ms_per_step_{name}": float(np.median(cpu_ms[setup])) for name, setup in NAMES.items()}
    for (name, against), (setup, reference) in RATIOS.items():
        key, ratios = f"{name}_vs_{against}", np.asarray(rates[setup]) / np.asarray(rates[reference])
        result |= {key: float(np.median(ratios)), f"{key}_min": float(ratios.min()), f"{key}_max": float(ratios.max())}
        result[f"{name}_cpu_vs_{against}"] = float(np.median(cpu_ms[reference]) / np.median(cpu_ms[setup]))
    return {**result, "live_rounds": rounds, "live_lag_p50_ms": float(np.percentile(lags, 50)),
            "live_lag_p95_ms": float(np.percentile(lags, 95)), "live_lag_steps": len(lags)}
