"""Neural ASM: Neural Associative Skill Memories.

A temporal predictive coding network learns a robot's skills from demonstrations with local
Hebbian rules, recognises which skill is running, predicts the rest and flags faults by its
prediction-error energy.

    import neural_asm as nasm

    memory = nasm.SkillMemory.fit(demos)        # (N, T, D) array or Sequences
    memory.calibrate(normal)                    # normal episodes it was not trained on
    monitor = memory.monitor(fpr=0.01)
    verdict = monitor.step(observation)         # verdict.fault, verdict.isolated_joint

The names below are the public API; they are imported on first use, so that
``import neural_asm`` stays light (the simulator, torch and the service load only when asked).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from neural_asm import runtime as _runtime  # noqa: F401  (first: one BLAS thread, no display)
from neural_asm.runtime.version import __version__

if TYPE_CHECKING:
    from neural_asm.client.session import ServiceClient, ServiceSession
    from neural_asm.client.transport import ServiceError, ServiceLost
    from neural_asm.logs.errors import LogError
    from neural_asm.logs.sources import load_log_sequences as read_logs
    from neural_asm.memory import Monitor, SkillMemory
    from neural_asm.models.answer import StepAnswer
    from neural_asm.models.checkpoint import CheckpointError
    from neural_asm.models.config import PRESETS, TPCConfig
    from neural_asm.models.cross_fit import CrossFit
    from neural_asm.models.scoring import SequenceScore
    from neural_asm.models.sequences import Sequences
    from neural_asm.pipelines.episodes import simulate_sequences, simulated_episodes
    from neural_asm.service.embedded import start_embedded as start_service
    from neural_asm.service.settings import Settings as ServiceSettings
    from neural_asm.sim.episode import Episode
    from neural_asm.sim.faults import FaultSpec
    from neural_asm.sim.paper import run_episode

# public name -> (module, attribute)
_EXPORTS: dict[str, tuple[str, str]] = {
    "SkillMemory": ("neural_asm.memory", "SkillMemory"),
    "Monitor": ("neural_asm.memory", "Monitor"),
    "StepAnswer": ("neural_asm.models.answer", "StepAnswer"),
    "CrossFit": ("neural_asm.models.cross_fit", "CrossFit"),
    "Sequences": ("neural_asm.models.sequences", "Sequences"),
    "SequenceScore": ("neural_asm.models.scoring", "SequenceScore"),
    "TPCConfig": ("neural_asm.models.config", "TPCConfig"),
    "PRESETS": ("neural_asm.models.config", "PRESETS"),
    "CheckpointError": ("neural_asm.models.checkpoint", "CheckpointError"),
    "run_episode": ("neural_asm.sim.paper", "run_episode"),
    "Episode": ("neural_asm.sim.episode", "Episode"),
    "FaultSpec": ("neural_asm.sim.faults", "FaultSpec"),
    "simulate_sequences": ("neural_asm.pipelines.episodes", "simulate_sequences"),
    "simulated_episodes": ("neural_asm.pipelines.episodes", "simulated_episodes"),
    "read_logs": ("neural_asm.logs.sources", "load_log_sequences"),
    "LogError": ("neural_asm.logs.errors", "LogError"),
    "ServiceSettings": ("neural_asm.service.settings", "Settings"),
    "start_service": ("neural_asm.service.embedded", "start_embedded"),
    "ServiceClient": ("neural_asm.client.session", "ServiceClient"),
    "ServiceSession": ("neural_asm.client.session", "ServiceSession"),
    "ServiceError": ("neural_asm.client.transport", "ServiceError"),
    "ServiceLost": ("neural_asm.client.transport", "ServiceLost"),
}

__all__ = ["__version__", *_EXPORTS]


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module 'neural_asm' has no attribute {name!r}")
    module, attribute = _EXPORTS[name]
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value  # the next look-up is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
