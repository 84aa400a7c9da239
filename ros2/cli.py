"""``nasm ros2``: the monitor node on a robot's ROS 2 bus (``ros2.node``); and the player behind
``nasm replay --ros2`` (``ros2.play``), which the command line hands to the client's replay command."""

from __future__ import annotations

import signal
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from neural_asm.client.transport import ServiceError, ServiceLost
from neural_asm.logs.errors import LogError
from neural_asm.logs.mapping import load_mapping
from neural_asm.recordings import DEFAULT_DIR
from neural_asm.runtime.cli import fail
from neural_asm.runtime.home import home_path

if TYPE_CHECKING:
    from neural_asm.client.source import StreamedEpisode


def ros2(
    mapping: Path = typer.Option(..., help="channel mapping (.toml/.yaml) naming the topics, fields and episodes"),
    model: str | None = typer.Option(None, help="a checkpoint's path, or a model's name in --models-dir (with "
                                     "--url: a model the service hosts, default its default)"),
    namespace: list[str] = typer.Option([], help="the robot's namespace, e.g. /robot1: the mapping's topics are read "
                                        "under it (/joint_states as /robot1/joint_states), and nasm/fault, nasm/energy "
                                        "published; repeat it to watch many robots from one process"),
    url: str | None = typer.Option(None, help="judge with a running service (nasm serve) instead of in-process"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="the service's API key (X-API-Key header)"),
    fpr: float = typer.Option(0.01, min=0.0, max=1.0, help="false-positive rate of the fault threshold"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder: one Rerun and one MCAP file per episode"),
    models_dir: Path = typer.Option(home_path("models"), help="where a model's name is looked up"),
) -> None:
    """Monitor a robot on its ROS 2 bus: read the mapping's topics, judge each step and publish
    the verdict on /diagnostics, nasm/fault and nasm/energy."""
    try:
        from neural_asm.ros2.bus import Bus
        from neural_asm.ros2.judge import load_judge
        from neural_asm.ros2.node import Fleet, MonitorNode
    except ImportError as exc:
        raise fail(f"nasm ros2 needs the ros2 extra (pip install 'neural-asm[ros2]'): {exc}") from None
    try:
        judge, names = load_judge(model, url, fpr, models_dir, api_key)
        found = load_mapping(mapping)
        if names != found.channel_names:
            raise LogError(f"the mapping gives channels {list(found.channel_names)} but the model expects {list(names)}")
        if len(set(namespace)) < len(namespace):
            raise LogError(f"--namespace: each robot once (given {', '.join(namespace)})")
        bus = Bus()
        nodes = [MonitorNode(bus.under(n), found, judge, out) for n in namespace or [""]]
    except (LogError, ValueError, OSError, ServiceError, ServiceLost) as exc:
        raise fail(exc) from None
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    robots = f" under {', '.join(namespace)}" if namespace else ""
    typer.echo(f"nasm ros2: monitoring {', '.join(g.source for g in nodes[0].groups)}{robots} in ROS domain "
               f"{bus.domain_id}")
    try:
        Fleet(bus, nodes).spin(stop)
    except KeyboardInterrupt:
        pass


def play(episodes: Sequence[StreamedEpisode], mapping: Path, namespace: str, speed: float) -> int:
    """``nasm replay --ros2``: play logged ``episodes`` onto the bus at ``speed`` times their own pace,
    as the node reading ``mapping`` under ``namespace`` reads them; the messages sent."""
    try:
        from neural_asm.ros2.bus import Bus
        from neural_asm.ros2.play import Pace, play_episodes
    except ImportError as exc:
        raise fail(f"nasm replay --ros2 needs the ros2 extra (pip install 'neural-asm[ros2]'): {exc}") from None
    try:
        return play_episodes(Bus(namespace), episodes, load_mapping(mapping), Pace(speed), typer.echo)
    except (LogError, ValueError) as exc:
        raise fail(exc) from None
