"""The models a service hosts: every ``*.safetensors`` checkpoint in its model folder.

Checkpoints are safetensors (no pickle) whose tensors are checked against the digest
in their header on load; a checkpoint that fails any check is refused, kept out of
service and listed as broken with the reason. A model's name is its file stem. The
default model (used when a session names none) is explicit: the ``default_model``
setting, otherwise the newest valid checkpoint that is not derived from another (a
checkpoint whose provenance names ``derived_from``, e.g. the default model recalibrated for
compliant control, serves only sessions that name it), never a broken one. When the folder
holds none, the default Panda model can be built on first run (training on simulated
demonstrations, with a progress bar); that lives in ``pipelines`` and is imported
only then, so the service runs without the simulator installed.
"""

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from neural_asm.models import checkpoint
from neural_asm.models.asm import NeuralASM
from neural_asm.models.skill_context import SkillMemory
from neural_asm.service.errors import UnknownModel

log = logging.getLogger(__name__)
Origin = Literal["loaded", "built"]


def build_default_model(models_dir: Path) -> Path:
    """Train and calibrate the default Panda model into ``models_dir``."""
    try:
        from neural_asm.pipelines.default_model import ensure_default_model
    except ImportError as exc:
        raise RuntimeError(
            f"no checkpoint in {models_dir} and the default Panda model cannot be built here "
            f"({exc}); train one with `nasm train` or copy a .safetensors file into {models_dir}"
        ) from exc
    return ensure_default_model(models_dir, progress=True)


@dataclass(frozen=True)
class Hosted:
    """Where a checkpoint came from and what it holds; ``model`` is None when it was refused."""

    name: str
    path: Path
    origin: Origin  # built by this service on first run, or loaded from the folder
    modified: float  # the file's mtime: "newest" for the default
    digest: str | None  # SHA-256 of the tensors, from the header (None: unreadable, or a format without one)
    model: NeuralASM | None = None
    error: str | None = None
    told: SkillMemory | None = None  # a skill memory: the network told the skill by a cue (``model`` is its network)


def _host(path: Path, origin: Origin) -> Hosted:
    try:
        data = path.read_bytes()
        modified = path.stat().st_mtime
    except OSError as exc:
        return Hosted(path.stem, path, origin, 0.0, None, error=f"{path} cannot be read: {exc}")
    try:
        digest = checkpoint.read_header(data, str(path)).get("tensor_sha256")
    except checkpoint.CheckpointError:
        digest = None
    try:
        model, told = checkpoint.decode(data, str(path))
        return Hosted(path.stem, path, origin, modified, digest, model, told=told)
    except checkpoint.CheckpointError as exc:
        return Hosted(path.stem, path, origin, modified, digest, error=str(exc))


class ModelRegistry:
    def __init__(self, models_dir: Path, default: str | None = None) -> None:
        self.models_dir = models_dir
        self.configured_default = default
        self.hosted: dict[str, Hosted] = {}

    @property
    def models(self) -> dict[str, NeuralASM]:
        return {name: h.model for name, h in self.hosted.items() if h.model is not None}

    @property
    def broken(self) -> dict[str, str]:
        return {name: h.error for name, h in self.hosted.items() if h.error is not None}

    def load(self, build_default: bool) -> None:
        """Load every checkpoint; broken ones are refused and listed, not fatal."""
        paths = {p: "loaded" for p in sorted(self.models_dir.glob("*.safetensors"))}
        if not paths and build_default:
            try:
                paths = {build_default_model(self.models_dir): "built"}
            except RuntimeError as exc:
                log.warning("%s", exc)
        for path, origin in paths.items():
            hosted = _host(path, origin)  # type: ignore[arg-type]
            self.hosted[hosted.name] = hosted
            if hosted.error:
                log.error("refusing checkpoint %s", hosted.error)
        if self.configured_default and self.configured_default not in self.models:
            log.error("the configured default model %r is %s", self.configured_default,
                      "broken" if self.configured_default in self.broken else "not in " + str(self.models_dir))
        log.info("models loaded from %s: %s; default %s", self.models_dir, sorted(self.models) or "none",
                 self.default_name)

    @property
    def default_name(self) -> str | None:
        """The configured default, else the newest valid checkpoint not derived from another
        (None: no valid default)."""
        if self.configured_default:
            return self.configured_default if self.configured_default in self.models else None
        valid = [h for h in self.hosted.values() if h.model is not None and "derived_from" not in h.model.provenance]
        return max(valid, key=lambda h: (h.modified, h.name)).name if valid else None

    def get(self, name: str | None) -> tuple[str, NeuralASM]:
        """The named model, or the default; a 404 saying why there is none."""
        name = name or self.configured_default or self.default_name
        if name is None:
            raise UnknownModel(
                f"no models loaded from {self.models_dir}; train one with `nasm train` "
                "or start the service with default-model building enabled"
            )
        hosted = self.hosted.get(name)
        if hosted is not None and hosted.error is not None:
            raise UnknownModel(f"model {name!r} was refused: {hosted.error}")
        if hosted is None or hosted.model is None:
            raise UnknownModel(f"no model named {name!r}; available: {sorted(self.models)}")
        return name, hosted.model
