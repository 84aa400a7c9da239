"""Run the service under uvicorn: in the foreground (``nasm serve``) or in-process.

``start_embedded`` serves on a free loopback port from a background thread and returns
once the app has started (models loaded), so a client with no URL can start its own:

    with start_embedded(Settings(models_dir=...)) as server:
        httpx.get(server.url + "/healthz")
"""

import socket
import threading
import time
from dataclasses import dataclass, field
from types import TracebackType

import uvicorn

from neural_asm.service.app import create_app
from neural_asm.service.settings import Settings


def uvicorn_config(settings: Settings, log_level: str = "info") -> uvicorn.Config:
    return uvicorn.Config(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        log_level=log_level,
        lifespan="on",
        ws_max_size=settings.max_body_bytes,
        # No permessage-deflate: compressing every ~3 kB step reply took a quarter of the
        # event loop's time under 64 sessions, to save bandwidth a robot's link does not lack.
        ws_per_message_deflate=False,
        timeout_graceful_shutdown=5,
    )


@dataclass
class EmbeddedServer:
    url: str
    server: uvicorn.Server
    thread: threading.Thread = field(repr=False)

    def stop(self, timeout_s: float = 10.0) -> None:
        """Graceful shutdown: sessions closed, recordings finished."""
        self.server.should_exit = True
        self.thread.join(timeout_s)

    def __enter__(self) -> "EmbeddedServer":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.stop()


def start_embedded(
    settings: Settings | None = None, log_level: str = "warning", startup_timeout_s: float = 3600.0
) -> EmbeddedServer:
    """Serve on 127.0.0.1 at a free port (``settings.host`` and ``port`` are ignored) from a daemon thread.

    The timeout is long because the first run may train the default model.
    """
    settings = (settings or Settings()).model_copy(update={"host": "127.0.0.1"})
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    server = uvicorn.Server(uvicorn_config(settings.model_copy(update={"port": port}), log_level))
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, name="nasm-embedded", daemon=True)
    thread.start()
    deadline = time.monotonic() + startup_timeout_s
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            server.should_exit = True
            sock.close()
            raise RuntimeError("the embedded service did not start (see its log above)")
        time.sleep(0.02)
    return EmbeddedServer(f"http://127.0.0.1:{port}", server, thread)
