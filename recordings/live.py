"""Episodes shown in a Rerun viewer while they run, with the files' layout.

A live view is a viewer's gRPC address (``rerun+http://HOST:PORT/proxy``): one given (a viewer
or ``rerun --serve-grpc`` somewhere else), a native viewer spawned here where there is a
display, or, on a headless machine, the SDK's gRPC server and its web viewer served here on
loopback (open the printed address in a browser, or ``rerun --connect`` the gRPC one; an SSH
tunnel reaches them from another machine). The server keeps what it was sent, so a viewer
connecting late still sees the whole episode.

Each episode is a stream of its own to that address, under the episode's recording id (so a
client's and its service's live streams merge into one view, as their files do), with the
episode layout as its default blueprint. It logs what the files log, sent as it arrives
rather than in the files' batches: within ``LIVE_FLUSH_S`` of the step.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote

import rerun as rr

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings.paths import APP_ID
from neural_asm.recordings.rerun_file import LiveStream

LIVE_FLUSH_S = 0.01  # the SDK's batcher sends what was logged this often (its default waits longer)
GRPC_PORT = 9876  # Rerun's own defaults: `rerun --connect` and the web viewer look there first
WEB_PORT = 9090
LOOPBACK = "127.0.0.1"


def proxy_url(host: str, port: int) -> str:
    return f"rerun+http://{host}:{port}/proxy"


def check_viewer_url(url: str) -> str:
    """``url`` if it is a viewer's gRPC address, else a ValueError showing one."""
    if not url.startswith(("rerun://", "rerun+http://", "rerun+https://")) or not url.endswith("/proxy"):
        raise ValueError(f"a live viewer's address looks like {proxy_url(LOOPBACK, GRPC_PORT)}, got {url!r}")
    return url


def rerun_executable() -> str:
    """The viewer binary the SDK ships. Run directly: ``python -m rerun`` runs it as a child that
    outlives the wrapper when the wrapper is stopped."""
    import rerun_cli

    folder = Path(rerun_cli.__file__).parent
    bundled = folder / "Rerun.app" / "Contents" / "MacOS" / "Rerun"  # macOS wheels
    return str(bundled if bundled.exists() else folder / ("rerun.exe" if sys.platform == "win32" else "rerun"))


def has_display() -> bool:
    """Whether a native viewer window can open here."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _port(preferred: int) -> int:
    """``preferred`` if it is free on loopback, else any free port (another viewer holds it)."""
    for port in (preferred, 0):
        with socket.socket() as s:
            try:
                s.bind((LOOPBACK, port))
            except OSError:
                continue
            return s.getsockname()[1]
    raise OSError("no free port on loopback")


@dataclass
class LiveViewer:
    """Where live episodes go (``url``), and how a person opens it (``how``)."""

    url: str
    how: str
    served: bool = False  # this process serves the viewer: it must outlive the episodes to be watched
    _host: rr.RecordingStream | None = None  # the stream whose sink is the served gRPC server
    _web: subprocess.Popen | None = None  # the web viewer's server

    def episode(self, recording_id: str) -> LiveStream:
        return LiveStream(self.url, recording_id, bp.episode_blueprint(), LIVE_FLUSH_S)

    def close(self) -> None:
        """Stop serving (a served viewer's browser page keeps what it received)."""
        if self._web is not None:
            self._web.terminate()
            try:
                self._web.wait(10)
            except subprocess.TimeoutExpired:  # never left behind
                self._web.kill()
                self._web.wait()
            self._web = None
        if self._host is not None:
            self._host.disconnect()
            self._host = None


def open_viewer(url: str | None = None, grpc_port: int = GRPC_PORT, web_port: int = WEB_PORT,
                display: bool | None = None) -> LiveViewer:
    """The viewer at ``url``; else one spawned here (a display) or served on loopback (none)."""
    if url:
        return LiveViewer(check_viewer_url(url), f"live view sent to the viewer at {url}")
    grpc_port = _port(grpc_port)
    if has_display() if display is None else display:
        rr.spawn(port=grpc_port, connect=False, hide_welcome_screen=True)
        return LiveViewer(proxy_url(LOOPBACK, grpc_port), f"live view in a Rerun viewer (gRPC port {grpc_port})")
    # The server's own stream holds no data; under an application id of its own, so that it does
    # not give the episodes' application a layout before theirs arrives (a viewer keeps the first).
    host = rr.RecordingStream(f"{APP_ID}-server", recording_id="live-server")
    host.set_sinks(rr.GrpcServerSink(bind_ip=LOOPBACK, port=grpc_port))
    url = proxy_url(LOOPBACK, grpc_port)
    web_port = _port(web_port)
    # The SDK's own command serves the web viewer's page on loopback (the SDK's function binds every
    # interface); the page then reads the gRPC server above.
    web = subprocess.Popen([rerun_executable(), "--serve-web", "--bind", LOOPBACK, "--web-viewer-port", str(web_port),
                            url], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    how = (f"live view served (no display here): open http://{LOOPBACK}:{web_port}/?url={quote(url, safe='')} "
           f"in a browser, or run `rerun --connect {url}`")
    return LiveViewer(url, how, served=True, _host=host, _web=web)
