"""One typed settings object, read from ``NASM_*`` environment variables or the CLI."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from neural_asm.models.config import SCORING
from neural_asm.runtime.home import home_path
from neural_asm.recordings.live import GRPC_PORT, WEB_PORT, check_viewer_url
from neural_asm.runtime.net import is_loopback


class Settings(BaseSettings):
    """The service's settings, each also read from its ``NASM_`` environment variable."""

    model_config = SettingsConfigDict(env_prefix="NASM_", extra="ignore")

    host: str = Field("127.0.0.1", description="address to bind; non-loopback requires an API key")
    port: int = Field(8000, ge=0, le=65535, description="TCP port (0: any free port)")
    models_dir: Path = Field(default_factory=lambda: home_path("models"), description="folder of *.safetensors checkpoints")
    default_model: str | None = Field(
        None, description="model used when a session names none; unset: the newest valid checkpoint"
    )
    build_default_model: bool = Field(
        True, description="train the default Panda model on first run when models_dir has none"
    )
    api_key: str | None = Field(None, description="required in the X-API-Key header when set")
    max_sessions: int = Field(256, ge=1, description="cap on open sessions")
    max_sessions_per_client: int = Field(
        64, ge=1, description="cap on one client's open sessions (by API key, else by client address)"
    )
    session_idle_s: float = Field(300.0, gt=0, description="sessions idle this long are closed")
    max_body_bytes: int = Field(64 * 1024, ge=1024, description="larger request bodies get 413")
    recordings_dir: Path = Field(default_factory=lambda: home_path("recordings"), description="where session recordings go")
    record: bool = Field(True, description="write an .rrd and an .mcap for every session")
    live: bool = Field(False, description="show every session in a Rerun viewer as it is scored: spawned where "
                       "there is a display, else served on loopback (gRPC and web viewer; the address is logged)")
    live_url: str | None = Field(None, description="with --live, send sessions to this viewer instead "
                                 "(rerun+http://HOST:PORT/proxy)")
    live_grpc_port: int = Field(GRPC_PORT, ge=1, le=65535, description="with --live, the served viewer's gRPC port "
                                "(another if taken)")
    live_web_port: int = Field(WEB_PORT, ge=1, le=65535, description="with --live, the served web viewer's port "
                               "(another if taken)")
    foxglove: int | None = Field(None, ge=0, le=65535, description="serve every session live to Foxglove on this "
                                 "loopback port (a Foxglove WebSocket server with the MCAP files' topics)")
    metrics: bool = Field(True, description="serve Prometheus metrics at /metrics (behind the API key when set)")
    default_fpr: float = Field(SCORING.default_fpr, gt=0, lt=1, description="per-step false-positive rate of /fault")

    @field_validator("live_url")
    @classmethod
    def _viewer_url(cls, url: str | None) -> str | None:
        return None if url is None else check_viewer_url(url)

    def check_live(self) -> None:
        """The live views show what the recorder writes."""
        if (self.live or self.live_url or self.foxglove is not None) and not self.record:
            raise ValueError("--live and --foxglove show sessions as the recorder writes them: drop --no-record")

    def check_exposure(self) -> None:
        """Refuse to serve beyond this machine without an API key."""
        if not is_loopback(self.host) and not self.api_key:
            raise ValueError(
                f"binding {self.host} exposes the service beyond this machine: "
                "set an API key (NASM_API_KEY or --api-key) or bind 127.0.0.1"
            )
