"""``nasm client`` and ``python sim/client.py``: the command line of the streaming client; and
``nasm replay``, which streams a robot's logged episodes the same way."""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from enum import Enum
from pathlib import Path

import typer

from neural_asm.client.replay import replay_logs
from neural_asm.client.run import MODES, SHOWCASE_FAULT, SimulatedRun, falling_object, fault_spec, run_client
from neural_asm.client.source import StreamedEpisode, logged
from neural_asm.client.stream import Connection, StreamOptions
from neural_asm.client.transport import TRANSPORTS, ServiceError, ServiceLost
from neural_asm.logs.cli import FORMATS, SKIP_BAD_HELP, data_command, mapping_help, read_logs, write_json
from neural_asm.logs.errors import LogError
from neural_asm.logs.sources import episode_position
from neural_asm.models.recall import RECALL_MODES
from neural_asm.recordings import DEFAULT_DIR
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.live import LiveViewer, open_viewer
from neural_asm.runtime.cli import Command, Group, fail
from neural_asm.runtime.home import home_path
from neural_asm.sim.cli import RATE_HELP, check_rate
from neural_asm.sim.config import CONTROLLERS, SIM
from neural_asm.sim.skills import SKILLS

Skill = Enum("Skill", {s: s for s in SKILLS}, type=str)
Mode = Enum("Mode", {m: m for m in MODES}, type=str)
TransportName = Enum("TransportName", {t: t for t in TRANSPORTS}, type=str)
Controller = Enum("Controller", {c: c for c in CONTROLLERS}, type=str)


def client(
    skill: Skill = typer.Option(SKILLS[0], help="skill to run"),
    tell_skill: bool = typer.Option(False, "--tell-skill", help="tell the service the skill each episode runs "
                                    "(--skill): a skill memory then decides with that skill's course and threshold "
                                    "(default: it infers the skill); a model trained without skills refuses it"),
    seed: int = typer.Option(SIM.seeds.client, help="episode seed (episode i uses seed + i); the default is in no "
                             "training or calibration set"),
    fault_joint: int | None = typer.Option(None, min=1, max=7, help="fault: joint 1..7 (give all three fault options or none)"),
    fault_time: float | None = typer.Option(None, help="fault: time in s, on the 0.5 s grid"),
    fault_overshoot: float | None = typer.Option(None, help="fault: overshoot in degrees"),
    drop: bool = typer.Option(False, "--falling-object", help=f"drop a box on the elbow at {SIM.hit.release_s:g} s, "
                              "during the carry (the correction experiment's hit)"),
    hit_momentum: float | None = typer.Option(None, help=f"the falling box's momentum in kg m/s (default "
                                              f"{SIM.hit.demo_momentum:g}: a "
                                              f"{SIM.hit.demo_momentum / SIM.hit.speed_m_s:g} kg box at "
                                              f"{SIM.hit.speed_m_s:g} m/s); needs --falling-object"),
    controller: Controller = typer.Option(SIM.controller, help="joint controller: stiff position servos (the IK "
                                          "plan, as in the training data) or compliant joint impedance (the memory's "
                                          "recalled plan, monitored by the model calibrated for compliant control)"),
    correct: bool = typer.Option(False, "--correct", help="correct the hit with the memory's prediction error once "
                                 "the monitor flags it; needs --controller compliant"),
    episodes: int | None = typer.Option(None, min=1, help="number of episodes (seeds seed, seed + 1, ...); "
                                        "default: with no fault or falling object, the episode of --seed twice, "
                                        f"normal and with joint {SHOWCASE_FAULT.joint} locked "
                                        f"({SHOWCASE_FAULT.overshoot_deg:+g} deg at {SHOWCASE_FAULT.time_s:g} s), "
                                        "verdicts side by side; else 1"),
    url: str | None = typer.Option(None, help="service URL, e.g. http://127.0.0.1:8000; default: start one "
                                               "in-process on a free port"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="API key (X-API-Key header)"),
    rate: int = typer.Option(int(SIM.timing.observation_hz), "--rate", callback=check_rate,
                             help=RATE_HELP + " Streams every observation; the default model at that rate "
                             "(panda, panda-40hz) is built on first use."),
    realtime: bool = typer.Option(False, "--realtime", help="send each observation at its time in the episode "
                                  "(every 25 ms at 40 Hz), not as fast as the service answers"),
    mode: Mode | None = typer.Option(None, help="recall mode: offline (the paper's setting) or online; default: the "
                                     "model's served mode, offline at 2 Hz and online at 40"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder"),
    reconnect: bool = typer.Option(False, "--reconnect", help="if the service goes away, reconnect and replay"),
    transport: TransportName = typer.Option("ws", help="ws (websocket /stream) or http (/sessions + /fault)"),
    models_dir: Path = typer.Option(home_path("models"), help="models folder of the in-process service"),
    json_out: Path | None = typer.Option(None, "--json", help="also write the summaries as JSON here"),
    live: bool = typer.Option(False, "--live", help="show the episodes in a Rerun viewer as they stream, laid out "
                              "as the files: a viewer spawned where there is a display, else served on loopback "
                              "(the address is printed; served, it stays up after the run until Ctrl-C)"),
    live_url: str | None = typer.Option(None, help="with --live, send to this viewer instead "
                                        "(rerun+http://HOST:PORT/proxy, e.g. a `rerun --serve-grpc` elsewhere)"),
    foxglove: int | None = typer.Option(None, min=0, max=65535, metavar="PORT", help="also serve the episodes live "
                                        "to Foxglove on this loopback port (0: any free one): the MCAP files' topics, "
                                        "so the shipped layout works"),
) -> None:
    """Simulate Panda episodes, stream them to the Neural ASM service and record them."""
    viewer: LiveViewer | None = None
    fox: FoxgloveLive | None = None
    streamed = False
    try:
        if live_url and not live:
            raise ValueError("--live-url needs --live")
        if live:
            viewer = open_viewer(live_url)
            typer.echo(viewer.how)
        if foxglove is not None:
            fox = FoxgloveLive(foxglove)
            typer.echo(fox.how)
        fault = fault_spec(fault_joint, fault_time, fault_overshoot)
        hit = falling_object(drop, hit_momentum)
        run = SimulatedRun(skill.value, seed, fault, hit, episodes or 1, controller.value, correct, rate,
                           showcase=episodes is None and fault is None and hit is None)
        summaries = run_client(run, Connection(url, api_key, transport.value, reconnect),
                               StreamOptions(None if mode is None else mode.value, out,
                                             {"skill": skill.value} if tell_skill else {}, realtime=realtime,
                                             live=viewer, foxglove=fox), models_dir)
        streamed = True
    except (ValueError, ServiceError) as exc:  # a bad option, or the service refused the request
        raise fail(exc) from None
    except ServiceLost as exc:
        raise fail(f"{exc}; nothing was recorded for the episode", 3) from None
    except KeyboardInterrupt:
        typer.echo("interrupted; recordings closed", err=True)
        raise typer.Exit(130) from None
    finally:
        if viewer is not None and not (streamed and viewer.served):
            viewer.close()
        if fox is not None:
            fox.close()
    if json_out is not None:
        json_out.write_text(json.dumps([s.to_dict() for s in summaries], indent=1))
    if viewer is not None and viewer.served:
        _serve_until_interrupted(viewer)
    if any(s.error for s in summaries):
        raise fail("lost the service; the recordings so far are closed and readable", 3)


def _serve_until_interrupted(viewer: LiveViewer) -> None:
    """A served view lives as long as this process: keep it up until the user has looked."""
    typer.echo(f"{viewer.how}\nthe live view stays up until Ctrl-C")
    try:
        while True:  # a sleep, unlike a lock's wait, is interrupted by Ctrl-C
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        viewer.close()


# ``nasm replay --ros2``'s player: (episodes, the node's mapping, namespace, speed) -> messages sent. It is the
# ros2 package's (above this one, which cannot import it), handed over by the ``nasm`` command line as its
# context's object; None outside it.
BusPlayer = Callable[[Sequence[StreamedEpisode], Path, str, float], int]


def replay(
    ctx: typer.Context,
    source: str = typer.Argument(..., help=f"the logs: {FORMATS}"),
    mapping: Path = typer.Option(..., help=mapping_help("SOURCE")),
    url: str | None = typer.Option(None, help="URL of a running service (nasm serve); or give --ros2"),
    model: str | None = typer.Option(None, help="name of the served model to score with (default: the service's default)"),
    episode: list[int] = typer.Option([], help="episode number in the source (repeatable) (default: every episode)"),
    api_key: str | None = typer.Option(None, envvar="NASM_API_KEY", help="API key (X-API-Key header)"),
    mode: str | None = typer.Option(None, help="recall mode: offline, online or plan (a model with a plan memory); "
                                    "default: the model's served mode, offline at 2 Hz and online faster"),
    out: Path = typer.Option(DEFAULT_DIR, help="recordings folder"),
    transport: str = typer.Option("ws", help="ws (websocket /stream) or http (/sessions + /fault)"),
    reconnect: bool = typer.Option(False, "--reconnect", help="if the service goes away, reconnect and replay"),
    skip_bad: bool = typer.Option(False, "--skip-bad", help=SKIP_BAD_HELP),
    json_out: Path | None = typer.Option(None, "--json", help="also write the summaries as JSON here"),
    tell_skill: bool = typer.Option(False, "--tell-skill", help="tell the service each episode's skill, the label "
                                    "the mapping reads (its skill or phase tag): a skill memory then decides with "
                                    "that skill's course and threshold (default: it infers the skill)"),
    ros2: Path | None = typer.Option(None, help="instead of streaming to a service, play the episodes onto the ROS 2 "
                                     "bus at their own pace (as ros2 bag play), as the node that reads this mapping "
                                     "(nasm ros2 --mapping) reads its topics"),
    namespace: str = typer.Option("", help="with --ros2: the robot's namespace the topics are published under "
                                  "(the node's --namespace)"),
    speed: float = typer.Option(1.0, min=0.01, help="with --ros2: times the episodes' own pace"),
) -> None:
    """Stream recorded episodes to a running service exactly as the live robot client does,
    after the same checks as ``nasm score`` against the served model; or, with ``--ros2``, play
    them onto a robot's ROS 2 bus for the monitor node (``nasm ros2``)."""
    if (mode is not None and mode not in RECALL_MODES) or transport not in TRANSPORTS:
        raise fail(f"--mode must be one of {', '.join(RECALL_MODES)} and --transport ws or http; "
                   f"got {mode!r}, {transport!r}")
    if (url is None) == (ros2 is None):
        raise fail("give either --url (a service to stream the episodes to) or --ros2 (a node's mapping: play them onto "
                   "the ROS 2 bus)")
    seqs = read_logs(source, mapping, skip_bad=skip_bad)
    if ros2 is not None:
        player: BusPlayer | None = ctx.obj
        if player is None:
            raise fail("--ros2 is played by the nasm command line: run nasm replay --ros2")
        try:
            picks = [episode_position(seqs, n) for n in episode] if episode else range(len(seqs.data))
        except LogError as exc:
            raise fail(exc) from None
        sent = player([logged(seqs, i) for i in picks], ros2, namespace, speed)
        typer.echo(f"played {sent} messages")
        return
    try:
        summaries = replay_logs(seqs, episode, Connection(url, api_key, transport, reconnect), StreamOptions(mode, out),
                                model, tell_skill)
    except (LogError, ServiceError) as exc:
        raise fail(exc) from None
    except ServiceLost as exc:
        raise fail(exc, 3) from None
    if json_out is not None:
        write_json(json_out, [s.to_dict() for s in summaries])
    if any(s.error for s in summaries):
        raise typer.Exit(3)


replay_command = data_command(replay)
app = typer.Typer(cls=Group, add_completion=False, pretty_exceptions_enable=False)
app.command(cls=Command, help=client.__doc__)(client)

if __name__ == "__main__":
    app()
