"""One typed settings object, read from ``NASM_*`` environment variables or the CLI."""

from __future__ import annotations

from pathlib import Path

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

from neural_asm.models.config import SCORING
from neural_asm.runtime.home import home_path
from neural_asm.runtime.net import is_loopback


class Settings(BaseSettings):
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
    metrics: bool = Field(True, description="serve Prometheus metrics at /metrics (behind the API key when set)")
    default_fpr: float = Field(SCORING.default_fpr, gt=0, lt=1, description="per-step false-positive rate of /fault")

    def check_exposure(self) -> None:
        """Refuse to serve beyond this machine without an API key."""
        if not is_loopback(self.host) and not self.api_key:
            raise ValueError(
                f"binding {self.host} exposes the service beyond this machine: "
                "set an API key (NASM_API_KEY or --api-key) or bind 127.0.0.1"
            )
