"""Latency and throughput of the service, over real sockets on loopback.

The service runs under uvicorn in a subprocess (so the client does not share its
GIL) with a paper-sized model (H=256, K=100, 25 channels) trained briefly on the
built-in synthetic skills. Measured: /healthz and /predict round trips over HTTP with
one client, websocket steps with one client, and the steps per second of 64 concurrent
websocket sessions (where the runner micro-batches), timed once all 64 are connected
(``fleet_connect_ms`` is the connecting). Prints one JSON object last.

The fleet is also run, in the same run, against a bare websocket endpoint under the same
uvicorn and Starlette that answers each message with a fixed reply of a step reply's size
(``echo_fleet_steps_per_s``): ``fleet_vs_echo`` is the share of the transport's own
throughput that the service keeps, a ratio that moves less than absolute numbers when the
machine is shared.

With ``--record`` the service is measured twice in the same run, without recording
(the reference) and with it, and the keys ``*_vs_no_record`` are the ratios (the
machine may be shared: absolute numbers move, same-run ratios less).
``rss_growth_mb_per_1000_sessions`` is the growth of the service's resident memory
(its process and the recorder's) over recorded sessions opened, stepped 15 times and
closed, after a warm-up: the slope through five readings.

With ``--rate 40`` the model learnt 300-step sequences at 40 Hz, every session says that rate,
and the fleet is 64 robots streaming one 300-step episode each at the controller's pace:
robot r sends tick k at k / 40 s plus its phase r / 64 of a tick (independent robots' clocks
are not aligned), or as soon as its previous reply is in if that is later. That offers 2,560
steps/s; ``fleet_steps_per_s`` sums each robot's steps answered per second of its episode
(300 ticks take 7.5 s, longer if its last reply comes later), so it is 2,560 exactly when every
robot kept its pace; ``dropped_steps`` counts the steps answered after the robot's next tick
was due (a monitor that missed the tick), ``fleet_ws_p50_ms``/``fleet_ws_p99_ms`` their round
trips, and ``fleet_send_lag_p99_ms`` how late this process itself sent a tick that was due (its
event loop serves 64 robots: a tick it sends late may be answered late through no fault of the
service's). The
same fleet unpaced (``unpaced_fleet_steps_per_s``, each step sent as soon as the last is
answered) is the most the service takes at that rate.

With ``--live`` (``service_live.py``) the unpaced fleet is run, in ``--rounds`` rounds of rotating
order, against a recording service without metrics, with metrics (``metrics_vs_none``: steps/s
with metrics over without) and with metrics and the live views (``live_vs_files``: with a served
Rerun view and a Foxglove server over files only): the medians of the rounds' ratios, their
ranges as ``*_min``/``*_max``. Then one robot streams an episode at the model's pace while a
Foxglove client subscribed to ``/fault`` stamps each message's arrival:
``live_lag_p50_ms``/``live_lag_p95_ms`` are from the robot's receipt of a step's answer to the
live viewer's receipt of that step (same process, same clock). The Rerun view is fed by the
same recorder messages, sent within ``recordings.live.LIVE_FLUSH_S``; its receipt is not timed.

    python benchmarks/bench_service.py [--record] [--live [--rounds 9]] [--rate 2|40] [--steps 400]
        [--fleet-steps N] [--sessions 1000] [--quick]

``--quick`` measures each thing once on tiny sizes (20 steps, 10-step fleets, 40 recorded
sessions, one round), in seconds rather than minutes: the test suite runs it so the script keeps
working; its numbers mean nothing.
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
import time
from dataclasses import dataclass
from pathlib import Path

import httpx
import numpy as np
import orjson
import websockets
from fastapi import FastAPI, WebSocket, WebSocketDisconnect

from neural_asm.models.config import FAST
from neural_asm.recordings.children import POLL_S
from neural_asm.sim.config import RATES, SIM
from service_harness import (FLEET, SESSION, build_model, free_port, percentiles, process_tree, start_server,
                             stat_of, wait_until_up, warm_fleet, ws_session)
from service_live import measure_live

HERE = Path(__file__).parent
ECHO_PADDING = 3350  # the reply is then ~3.4 kB, a 25-channel step reply's size


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


def tree_rss_mb(pid: int) -> float:
    """Resident memory of a process and all its descendants (the recorder process)."""
    return sum(stat_of(p, "statm", 1) * os.sysconf("SC_PAGE_SIZE") / 2**20 for p in process_tree(pid))


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


@dataclass(frozen=True)
class PacedRobot:
    round_trips_ms: list[float]
    replies_s: list[float]  # when each reply came, after the robot's first tick
    dropped: int  # steps answered after the next tick was due
    send_lags_ms: list[float]  # how late each tick left once due and the previous reply was in:
    # the benchmark's own event loop, not the service


async def paced_session(url: str, episode: np.ndarray, period_s: float, phase_s: float,
                        connected: asyncio.Barrier) -> PacedRobot:
    """One robot streaming ``episode`` at its pace: tick k sent at k periods plus ``phase_s``
    after the fleet's start, or once the previous reply is in if that is later."""
    times, replies, dropped, lags = [], [], 0, []
    async with websockets.connect(url) as ws:
        await ws.recv()
        await ws.send(orjson.dumps({"type": "start", **SESSION}).decode())
        await ws.recv()
        await connected.wait()
        first_tick = time.perf_counter() + phase_s
        answered = first_tick
        for k, x in enumerate(episode.tolist()):
            due = max(first_tick + k * period_s, answered)
            await asyncio.sleep(max(0.0, due - time.perf_counter()))
            t = time.perf_counter()
            lags.append((t - due) * 1e3)
            await ws.send(orjson.dumps({"type": "step", "observation": x}).decode())
            await ws.recv()
            answered = time.perf_counter()
            times.append((answered - t) * 1e3)
            replies.append(answered - first_tick)
            dropped += answered > first_tick + (k + 1) * period_s
    return PacedRobot(times, replies, dropped, lags)


@dataclass(frozen=True)
class PacedFleet:
    steps_per_s: float  # each robot's steps per second of its episode (at least its ticks' span), summed
    dropped_steps: int
    p50_ms: float
    p99_ms: float
    send_lag_p99_ms: float  # how late the benchmark's own loop sent a tick that was due


async def paced_fleet(url: str, episodes: np.ndarray, rate: float) -> PacedFleet:
    """``FLEET`` robots, one episode each, their ticks spread evenly over a period."""
    period = 1.0 / rate
    connected = asyncio.Barrier(FLEET + 1)
    robots = [asyncio.create_task(paced_session(url, episodes[r % len(episodes)], period, r * period / FLEET,
                                                connected)) for r in range(FLEET)]
    await connected.wait()
    results = await asyncio.gather(*robots)
    ms = [t for r in results for t in r.round_trips_ms]
    served = sum(len(r.replies_s) / max(len(r.replies_s) * period, r.replies_s[-1]) for r in results)
    lag = percentiles([t for r in results for t in r.send_lags_ms])[1]
    return PacedFleet(served, sum(r.dropped for r in results), *percentiles(ms), lag)


def echo_app() -> FastAPI:
    """The transport alone: answers every message with a fixed reply of a step reply's size."""
    app = FastAPI()
    reply = orjson.dumps({"type": "step", "batch_size": 1, "padding": "x" * ECHO_PADDING}).decode()

    @app.websocket("/stream")
    async def stream(ws: WebSocket) -> None:
        await ws.accept()
        await ws.send_text(reply)
        try:
            while True:
                await ws.receive_text()
                await ws.send_text(reply)
        except WebSocketDisconnect:
            pass

    return app


def echo_fleet(episodes: np.ndarray, steps: int) -> float:
    """The fleet's steps per second against ``echo_app``, served like the service (uvicorn,
    no per-message compression, a process of its own)."""
    port = free_port()
    cmd = [sys.executable, "-m", "uvicorn", "--factory", "bench_service:echo_app", "--app-dir", str(HERE),
           "--port", str(port), "--ws-per-message-deflate", "false", "--log-level", "warning"]
    proc = subprocess.Popen(cmd)
    try:
        wait_until_up(proc, f"http://127.0.0.1:{port}/docs")
        return warm_fleet(f"ws://127.0.0.1:{port}/stream", episodes, steps).steps_per_s
    finally:
        proc.terminate()
        proc.wait(30)


def measure(folder: Path, episodes: np.ndarray, record: bool, args: argparse.Namespace) -> dict[str, float]:
    port = free_port()
    proc = start_server(folder, port, record)
    try:
        result = http_latencies(f"http://127.0.0.1:{port}", episodes, args.steps)
        ws_url = f"ws://127.0.0.1:{port}/stream"
        ws_times, _ = asyncio.run(ws_session(ws_url, episodes, args.steps, 0))
        result["ws_p50_ms"], result["ws_p99_ms"] = percentiles(ws_times[10:])
        stepped = warm_fleet(ws_url, episodes, args.fleet_steps)
        if args.rate == SIM.timing.observation_hz:
            result.update(fleet_steps_per_s=stepped.steps_per_s, fleet_mean_batch=stepped.mean_batch,
                          fleet_connect_ms=stepped.connect_ms)
        else:  # warmed by the unpaced fleet
            paced = asyncio.run(paced_fleet(ws_url, episodes, args.rate))
            result.update(offered_steps_per_s=FLEET * args.rate, fleet_steps_per_s=paced.steps_per_s,
                          dropped_steps=paced.dropped_steps, fleet_ws_p50_ms=paced.p50_ms,
                          fleet_ws_p99_ms=paced.p99_ms, fleet_send_lag_p99_ms=paced.send_lag_p99_ms,
                          unpaced_fleet_steps_per_s=stepped.steps_per_s)
        if record:
            result["rss_growth_mb_per_1000_sessions"] = rss_growth(ws_url, proc.pid, episodes, args.sessions)
    finally:
        proc.terminate()
        proc.wait(30)
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--steps", type=int, default=400, help="steps per latency measurement")
    parser.add_argument("--fleet-steps", type=int, default=None,
                        help="steps per session in the unpaced fleet (default 150, at 40 Hz one episode: 300)")
    parser.add_argument("--rate", type=int, choices=RATES, default=int(SIM.timing.observation_hz),
                        help="the model's and the sessions' rate (Hz); at 40 the fleet is paced")
    parser.add_argument("--sessions", type=int, default=1000, help="recorded sessions for the memory growth")
    parser.add_argument("--record", action="store_true", help="let the service record every session")
    parser.add_argument("--live", action="store_true", help="measure metrics and the live views against none, and "
                        "the live view's lag")
    parser.add_argument("--rounds", type=int, default=9, help="rounds of the three setups with --live")
    parser.add_argument("--quick", action="store_true",
                        help="tiny sizes (seconds, not minutes): checks the script runs, measures nothing")
    args = parser.parse_args()
    if args.quick:
        args.steps, args.fleet_steps, args.sessions, args.rounds = 20, 10, 40, 1
    if args.fleet_steps is None:
        args.fleet_steps = 150 if args.rate == SIM.timing.observation_hz else SIM.timing.observations(args.rate)
    SESSION["rate_hz"] = args.rate
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        episodes = build_model(folder, args.rate)
        gc.collect()  # the clients run in this process: no full collection over torch's objects
        gc.freeze()  # may pause every robot at once (~150 ms on a 2-core machine)
        if args.live:
            result = measure_live(folder, episodes, args.fleet_steps, args.rate, args.rounds)
        elif args.record:
            reference = measure(folder, episodes, False, args)
            result = measure(folder, episodes, True, args)
            paced = ("fleet_ws_p99_ms", "fleet_send_lag_p99_ms", "unpaced_fleet_steps_per_s") if "dropped_steps" in result else ()
            for key in ("fleet_steps_per_s", "predict_p99_ms", "ws_p99_ms", *paced):
                result[f"{key}_no_record"] = reference[key]
                result[f"{key}_vs_no_record"] = result[key] / reference[key]
            if paced:
                result["dropped_steps_no_record"] = reference["dropped_steps"]
        else:
            result = measure(folder, episodes, False, args)
            result["echo_fleet_steps_per_s"] = echo_fleet(episodes, args.fleet_steps)
            most = result.get("unpaced_fleet_steps_per_s", result["fleet_steps_per_s"])  # both unpaced
            result["fleet_vs_echo"] = most / result["echo_fleet_steps_per_s"]
    result.update(record=args.record or args.live, live=args.live, rate_hz=args.rate, hidden_size=FAST.hidden_size,
                  inference_steps=FAST.inference_steps)
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in result.items()}))


if __name__ == "__main__":
    main()
