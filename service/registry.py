"""The models a service hosts: every ``*.safetensors`` checkpoint in its model folder.

Checkpoints are safetensors (no pickle). A model's name is its file stem. When the
folder holds none, the default Panda model can be built on first run (training on
simulated demonstrations, with a progress bar); that lives in ``pipelines`` and is
imported only then, so the service runs without the simulator installed.
"""

import logging
from pathlib import Path

from models import checkpoint
from models.asm import NeuralASM
from service.errors import UnknownModel

log = logging.getLogger("service.registry")


def build_default_model(models_dir: Path) -> Path:
    """Train and calibrate the default Panda model into ``models_dir``."""
    try:
        from pipelines.default_model import ensure_default_model
    except ImportError as exc:
        raise RuntimeError(
            f"no checkpoint in {models_dir} and the default Panda model cannot be built here "
            f"({exc}); train one with `nasm train` or copy a .safetensors file into {models_dir}"
        ) from exc
    return ensure_default_model(models_dir, progress=True)


class ModelRegistry:
    def __init__(self, models_dir: Path, default: str | None = None) -> None:
        self.models_dir = models_dir
        self.configured_default = default
        self.models: dict[str, NeuralASM] = {}
        self.broken: dict[str, str] = {}

    def load(self, build_default: bool) -> None:
        """Load every checkpoint; broken ones are reported, not fatal."""
        paths = sorted(self.models_dir.glob("*.safetensors"))
        if not paths and build_default:
            try:
                paths = [build_default_model(self.models_dir)]
            except RuntimeError as exc:
                log.warning("%s", exc)
        for path in paths:
            try:
                self.models[path.stem] = checkpoint.load(path)
            except checkpoint.CheckpointError as exc:
                self.broken[path.stem] = str(exc)
                log.warning("skipping %s", exc)
        log.info("models loaded from %s: %s", self.models_dir, sorted(self.models) or "none")

    @property
    def default_name(self) -> str | None:
        if self.configured_default:
            return self.configured_default
        return next(iter(self.models), None)

    def get(self, name: str | None) -> tuple[str, NeuralASM]:
        name = name or self.default_name
        if name is None or name not in self.models:
            if not self.models:
                raise UnknownModel(
                    f"no models loaded from {self.models_dir}; train one with `nasm train` "
                    "or start the service with default-model building enabled"
                )
            what = f"no model named {name!r}" if name else "no default model"
            raise UnknownModel(f"{what}; available: {sorted(self.models)}")
        return name, self.models[name]
