"""The websocket fleet through HAProxy (docker/haproxy.cfg) against one replica direct, and
what losing a replica mid-fleet costs.

In one run, on loopback, every service recording its sessions: the 64-session fleet of
``bench_service.py`` against one service process directly (the reference), then through
HAProxy with the project's configuration in front of N replicas (``balancer_vs_direct`` =
steps/s through the balancer / steps/s direct). Then a fleet through the balancer during which
one replica is killed (SIGKILL, with its recorder) once half of the fleet's steps are answered:
``lost_steps_surviving`` counts the steps the
sessions of the other replicas did not get answered (target 0); the killed replica's clients
reconnect through the balancer and carry on in a new session from the step they were at
(``reconnected_sessions``; ``lost_steps_killed``: their steps never answered). The killed
replica is then restarted on its recordings folder: ``killed_recordings_recovered`` episodes
recovered at start, ``killed_recordings_readable`` if every file of that folder reads (mcap
reader, ``rerun rrd verify``). Needs ``haproxy`` (Debian: apt-get install haproxy).

    python benchmarks/bench_balancer.py --via-balancer 2 [--fleet-steps 150] [--kill-steps 300] [--quick]

``--quick``: 10-step fleets and a 20-step fleet losing its replica, in seconds rather than
minutes: the test suite runs it so the script keeps working; its numbers mean nothing.
"""

import neural_asm.runtime  # noqa: F401  (first: one BLAS thread, no display)

import argparse
import asyncio
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import orjson
import websockets

from service_harness import SESSION, build_model, free_port, wait_until_up, warm_fleet
from neural_asm.recordings.live import rerun_executable
from neural_asm.recordings.readers import read_mcap
from neural_asm.sim.config import SIM

HAPROXY_CFG = Path(__file__).resolve().parent.parent / "docker" / "haproxy.cfg"
SESSIONS = 64


def start_replica(folder: Path, name: str, port: int) -> subprocess.Popen:
    """A service process in a process group of its own (its recorder dies with it, as in a container)."""
    cmd = [sys.executable, "-m", "neural_asm.service.cli", "serve", "--port", str(port), "--models-dir", str(folder),
           "--recordings-dir", str(folder / "rec" / name), "--log-level", "warning", "--max-sessions", "128",
           "--max-sessions-per-client", "128", "--record"]
    proc = subprocess.Popen(cmd, start_new_session=True)
    wait_until_up(proc, f"http://127.0.0.1:{port}/healthz")
    return proc


def stop(proc: subprocess.Popen) -> None:
    proc.terminate()
    proc.wait(60)


def start_balancer(folder: Path, ports: list[int], port: int) -> subprocess.Popen:
    """HAProxy with docker/haproxy.cfg, its DNS-discovered replicas replaced by fixed addresses."""
    haproxy = shutil.which("haproxy") or sys.exit("bench_balancer: haproxy not found (apt-get install haproxy)")
    lines = HAPROXY_CFG.read_text().splitlines()
    servers = [f"    server replica{i} 127.0.0.1:{p}" for i, p in enumerate(ports, 1)]
    cfg = [ln for ln in lines if not ln.strip().startswith("server-template")] + servers
    assert len(cfg) == len(lines) - 1 + len(servers), "docker/haproxy.cfg has no server-template line"
    (folder / "haproxy.cfg").write_text("\n".join(cfg) + "\n")
    env = {**os.environ, "NASM_BALANCER_BIND": f"127.0.0.1:{port}", "NASM_REPLICAS": "unused:1"}
    proc = subprocess.Popen([haproxy, "-db", "-f", str(folder / "haproxy.cfg")], env=env, stdout=sys.stderr)
    wait_until_up(proc, f"http://127.0.0.1:{port}/healthz")
    return proc


@dataclass
class Client:
    replicas: list[str] = field(default_factory=list)  # the replica of each of its connections
    answered: int = 0


@dataclass
class Halfway:
    """The fleet's answered steps, and an event set once half of ``total`` are in."""

    total: int
    answered: int = 0
    reached: asyncio.Event = field(default_factory=asyncio.Event)

    def add(self) -> None:
        self.answered += 1
        if 2 * self.answered >= self.total:
            self.reached.set()


async def session(url: str, episodes: np.ndarray, steps: int, seed: int, go: asyncio.Event,
                  connected: asyncio.Barrier, halfway: Halfway, attempts: int = 10) -> Client:
    """One session stepping ``steps`` times; when its connection is lost, a new connection through
    the balancer and a new session that carries on from the step it was at."""
    c = Client()
    k, first = 0, True
    for _ in range(attempts):
        try:
            async with websockets.connect(url, open_timeout=10) as ws:
                response = getattr(ws, "response", None)
                c.replicas.append(response.headers.get("X-Replica", "?") if response else "?")
                await ws.recv()
                await ws.send(orjson.dumps({"type": "start", **SESSION}).decode())
                assert orjson.loads(await ws.recv())["type"] == "started"
                if first:
                    first = False
                    await connected.wait()
                    await go.wait()
                while k < steps:
                    x = episodes[(seed + k) % len(episodes), k % episodes.shape[1]].tolist()
                    await ws.send(orjson.dumps({"type": "step", "observation": x}).decode())
                    reply = orjson.loads(await ws.recv())
                    assert reply.get("type") == "step", reply
                    c.answered += 1
                    halfway.add()
                    k += 1
                return c
        except (websockets.ConnectionClosed, websockets.InvalidStatus, OSError, TimeoutError):
            await asyncio.sleep(0.5)  # the balancer sees a dead replica within two 1 s health checks
    return c


async def fleet_with_a_kill(url: str, episodes: np.ndarray, steps: int, victim: subprocess.Popen,
                            victim_name: str) -> list[Client]:
    connected, go, halfway = asyncio.Barrier(SESSIONS + 1), asyncio.Event(), Halfway(SESSIONS * steps)
    tasks = [asyncio.create_task(session(url, episodes, steps, s, go, connected, halfway)) for s in range(SESSIONS)]
    await connected.wait()
    go.set()
    t = time.monotonic()
    await halfway.reached.wait()  # mid-fleet
    os.killpg(victim.pid, signal.SIGKILL)
    victim.wait()
    print(f"bench_balancer: killed {victim_name} {time.monotonic() - t:.1f} s into the fleet", file=sys.stderr)
    return list(await asyncio.gather(*tasks))


def readable(markers: list[Path]) -> bool:
    """Every file of the recovered episodes reads: the mcap reader, ``rerun rrd verify``."""
    for marker in markers:
        run = marker.name.removesuffix(".interrupted.json")
        for path in marker.parent.glob(f"{run}.*"):
            if path.suffix == ".mcap" and not read_mcap(path):
                return False
            verify = [rerun_executable(), "rrd", "verify", str(path)]
            if path.suffix == ".rrd" and subprocess.run(verify, capture_output=True).returncode != 0:
                return False
    return bool(markers)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--via-balancer", type=int, default=2, metavar="N", help="replicas behind the balancer")
    parser.add_argument("--fleet-steps", type=int, default=150, help="steps per session in the measured fleets")
    parser.add_argument("--kill-steps", type=int, default=300, help="steps per session in the fleet losing a replica")
    parser.add_argument("--quick", action="store_true",
                        help="tiny fleets (seconds, not minutes): checks the script runs, measures nothing")
    args = parser.parse_args()
    if args.quick:
        args.fleet_steps, args.kill_steps = 10, 20
    if args.via_balancer < 2:
        sys.exit("bench_balancer: --via-balancer needs at least 2 replicas (one is killed)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        episodes = build_model(folder, SIM.timing.observation_hz)  # the paper's 2 Hz, 15-step episodes

        port = free_port()
        direct = start_replica(folder, "direct", port)
        try:
            direct_fleet = warm_fleet(f"ws://127.0.0.1:{port}/stream", episodes, args.fleet_steps)
        finally:
            stop(direct)

        names = [f"replica{i}" for i in range(1, args.via_balancer + 1)]
        ports = [free_port() for _ in names]
        replicas = {n: start_replica(folder, n, p) for n, p in zip(names, ports)}
        lb_port = free_port()
        balancer = start_balancer(folder, ports, lb_port)
        url = f"ws://127.0.0.1:{lb_port}/stream"
        try:
            via = warm_fleet(url, episodes, args.fleet_steps)
            victim = names[0]
            clients = asyncio.run(fleet_with_a_kill(url, episodes, args.kill_steps, replicas[victim], victim))
            replicas[victim] = start_replica(folder, victim, ports[0])  # recovers its recordings at start
            recovered = sorted((folder / "rec" / victim).glob("*.interrupted.json"))
        finally:
            for proc in [balancer, *replicas.values()]:
                if proc.poll() is None:
                    stop(proc)
        surviving = [c for c in clients if c.replicas[0] != victim]
        killed = [c for c in clients if c.replicas[0] == victim]
        result = {
            "replicas": args.via_balancer,
            "direct_fleet_steps_per_s": direct_fleet.steps_per_s,
            "balancer_fleet_steps_per_s": via.steps_per_s,
            "balancer_vs_direct": via.steps_per_s / direct_fleet.steps_per_s,
            "sessions_on_killed": len(killed),
            "sessions_surviving": len(surviving),
            "lost_steps_surviving": sum(args.kill_steps - c.answered for c in surviving),
            "reconnects_surviving": sum(len(c.replicas) - 1 for c in surviving),
            "reconnected_sessions": sum(len(c.replicas) > 1 for c in killed),
            "lost_steps_killed": sum(args.kill_steps - c.answered for c in killed),
            "killed_recordings_recovered": len(recovered),
            "killed_recordings_readable": readable(recovered),
            "sessions": SESSIONS,
            "fleet_steps": args.fleet_steps,
        }
    print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in result.items()}))


if __name__ == "__main__":
    main()
