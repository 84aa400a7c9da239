"""Checkpoints: one safetensors file holding the weights and a JSON metadata header.

Tensors: ``W_H``, ``W_F``, ``W_C`` (with context channels only), ``W_D`` (with direct pathways only),
``plan.recognition``, ``plan.inputs``, ``plan.readouts`` and ``plan.departures`` (with a plan memory
only, its skills and context channels named in the header), ``precision`` (of the observation channels), ``normaliser.mean``, ``normaliser.std`` and, per
calibration ``<key>`` (e.g. ``offline:1``), ``calibration.<key>.error_std``,
``calibration.<key>.step_thresholds``, when errors are whitened
``calibration.<key>.error_precision`` (absent: channels weighed independently) and, at rates whose
calibrations centre the errors, ``calibration.<key>.error_mean`` (each skill's mean error per step,
the skills named in the calibration's metadata; absent: errors taken as centred). A skill memory
(`neural_asm.models.skill_context`: the network told the skill by its ``skill:<name>`` cue channels) adds
``skill_memory.means`` (each skill's mean course) and, once calibrated, ``skill_memory.courses``,
``skill_memory.spreads.<term>`` and ``skill_memory.told`` (each skill's thresholds), its other settings
in the header's ``skill_memory`` entry. The header entry ``neural_asm`` is a JSON
document with the format version, the TPCConfig, the channel names, each
calibration's thresholds and source, the data provenance, the training energy
curve, the observation rate the model learnt at (``rate_hz``; files without it are 2 Hz),
and a SHA-256 digest of every tensor's name, dtype, shape and bytes, checked on load
so that flipped bytes in the weights are refused rather than served. No pickle is involved;
writes go to a temporary file that replaces the target only once complete, so a crash never
leaves a half-written checkpoint.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from safetensors import SafetensorError
from safetensors.torch import load as st_load
from safetensors.torch import save as st_save

from neural_asm.models.asm import NeuralASM, context_index
from neural_asm.models.calibration import Calibration
from neural_asm.models.config import DEFAULT_RATE_HZ, TPCConfig
from neural_asm.models.normaliser import Normaliser
from neural_asm.models.plan import PlanMemory
from neural_asm.models.skill_calibration import SkillCalibration
from neural_asm.models.skill_context import SkillMemory
from neural_asm.models.tpc import TemporalPC
from neural_asm.runtime.version import __version__

# 2: observation precisions; 3: optional whitening precision matrices; 4: optional W_C and a
# digest; 5: the inference solver in the config; 6: the observation rate (older: 2 Hz) and
# optional W_D (direct pathways); 7: optional mean errors per skill and step in calibrations (a reader
# that ignored them would weigh a 40 Hz model's errors uncentred against centred thresholds); 8: an
# optional plan memory (a reader that ignored it would refuse its "plan" calibration's sessions); 9: an
# optional skill memory (a reader that ignored it would serve its cue channels as observations); 10: a
# skill calibration's optional precision matrices and energy scales (a reader that ignored them would
# hold energies weighed otherwise to thresholds calibrated with them).
FORMAT_VERSION = 10
READABLE_VERSIONS = (2, 3, 4, 5, 6, 7, 8, 9, 10)  # older files simply have no precision matrices, context input, digest, rate,
# W_D or mean errors
HEADER_KEY = "neural_asm"
# No trained weight comes near this; a corrupted exponent byte does (values of 1e28 were seen).
MAX_ABS_WEIGHT = 1e3
PLAN_TENSORS = ("recognition", "inputs", "readouts", "departures")
SKILLS = "skill_memory"  # the prefix of a skill memory's tensors and its header entry


class CheckpointError(ValueError):
    """A checkpoint is missing, corrupt, truncated or does not fit its own metadata."""


def _f64(a: np.ndarray) -> torch.Tensor:
    return torch.from_numpy(np.ascontiguousarray(a, np.float64))


def tensor_digest(tensors: dict[str, torch.Tensor]) -> str:
    """SHA-256 over every tensor's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(tensors):
        t = tensors[name].contiguous()
        h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
        h.update(t.numpy().tobytes())
    return h.hexdigest()


def to_bytes(memory: NeuralASM | SkillMemory) -> bytes:
    """A network, or a skill memory with its network, as checkpoint bytes."""
    model = memory.model if isinstance(memory, SkillMemory) else memory
    tensors = {
        "W_H": model.net.W_H.contiguous(),
        "W_F": model.net.W_F.contiguous(),
        "precision": model.net.precision.contiguous(),
        "normaliser.mean": _f64(model.normaliser.mean),
        "normaliser.std": _f64(model.normaliser.std),
    }
    if model.net.has_context:
        tensors["W_C"] = model.net.W_C.contiguous()
    if model.net.has_direct:
        tensors["W_D"] = model.net.W_D.contiguous()
    if model.plan is not None:
        for name in PLAN_TENSORS:
            tensors[f"plan.{name}"] = _f64(getattr(model.plan, name))
    calibrations = []
    for key, cal in model.calibrations.items():
        fprs = sorted(cal.step_thresholds)
        tensors[f"calibration.{key}.error_std"] = _f64(cal.error_std)
        if cal.error_precision is not None:
            tensors[f"calibration.{key}.error_precision"] = _f64(cal.error_precision)
        if cal.error_mean is not None:
            tensors[f"calibration.{key}.error_mean"] = _f64(cal.error_mean)
        if fprs:
            tensors[f"calibration.{key}.step_thresholds"] = _f64(
                np.stack([cal.step_thresholds[f] for f in fprs])
            )
        calibrations.append(
            {
                "key": key,
                "mode": cal.mode,
                "cue_steps": cal.cue_steps,
                "source": cal.source,
                "skills": list(cal.skills),
                "fprs": fprs,
                "thresholds": [cal.thresholds[f] for f in fprs],
                "episode_thresholds": [cal.episode_thresholds[f] for f in fprs],
            }
        )
    skills = None
    if isinstance(memory, SkillMemory):
        skills, arrays = {"calibration": None}, {"means": memory.means}
        if memory.calibration is not None:
            skills["calibration"], calibrated = memory.calibration.to_parts()
            arrays.update(calibrated)
        tensors.update({f"{SKILLS}.{name}": _f64(a) for name, a in arrays.items()})
    meta = {
        "format_version": FORMAT_VERSION,
        "package_version": __version__,
        "config": model.config.to_dict(),
        "channel_names": list(model.channel_names),
        "context_channels": list(model.context_channels),
        "calibrations": calibrations,
        "provenance": model.provenance,
        "history": model.history,
        "rate_hz": model.rate_hz,
        "plan_skills": None if model.plan is None else list(model.plan.skills),
        "plan_context": None if model.plan is None else list(model.plan.context),
        SKILLS: skills,
        "tensor_sha256": tensor_digest(tensors),
    }
    return st_save(tensors, metadata={HEADER_KEY: json.dumps(meta)})


def save(memory: NeuralASM | SkillMemory, path: str | os.PathLike[str]) -> Path:
    """Write a network or a skill memory atomically: a temporary file in the same folder, then os.replace."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = to_bytes(memory)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_header(data: bytes, where: str) -> dict[str, Any]:
    """The JSON metadata of checkpoint bytes, without building the model."""
    try:
        header_len = int.from_bytes(data[:8], "little")
        header = json.loads(data[8 : 8 + header_len])
        meta = json.loads(header["__metadata__"][HEADER_KEY])
    except (ValueError, KeyError, TypeError, UnicodeDecodeError) as exc:
        raise CheckpointError(f"{where} is not a Neural ASM checkpoint (no readable metadata)") from exc
    if meta.get("format_version") not in READABLE_VERSIONS:
        raise CheckpointError(
            f"{where} has format version {meta.get('format_version')!r}; "
            f"this software reads versions {', '.join(map(str, READABLE_VERSIONS))}"
        )
    return meta


def from_bytes(data: bytes, where: str = "checkpoint") -> NeuralASM:
    """The network of checkpoint bytes (a skill memory's too: `decode` gives the memory as well)."""
    return decode(data, where)[0]


def decode(data: bytes, where: str = "checkpoint") -> tuple[NeuralASM, SkillMemory | None]:
    """The network of checkpoint bytes, and the skill memory it belongs to (None: an ordinary network)."""
    meta = read_header(data, where)
    try:
        tensors = st_load(data)
    except (SafetensorError, ValueError, RuntimeError) as exc:
        raise CheckpointError(f"{where} is corrupt or truncated: {exc}") from exc
    if meta["format_version"] >= 4 and tensor_digest(tensors) != meta.get("tensor_sha256"):
        raise CheckpointError(f"{where} is corrupt: its tensors do not match the digest in its header")
    try:
        # Networks saved before the solver was a setting were trained with gradient descent.
        config = TPCConfig.from_dict({"solver": "gradient", **meta["config"]})
        names = meta["channel_names"]
        net = TemporalPC(len(names), config, context_index(names, meta.get("context_channels", []), config))
        net.load_weights(tensors["W_H"], tensors["W_F"], tensors["precision"], tensors.get("W_C"), tensors.get("W_D"))
        normaliser = Normaliser(tensors["normaliser.mean"].numpy(), tensors["normaliser.std"].numpy())
        plan = None
        if meta.get("plan_skills") is not None:
            plan = PlanMemory(tuple(str(s) for s in meta["plan_skills"]), tuple(int(i) for i in meta["plan_context"]),
                              *(tensors[f"plan.{name}"].numpy() for name in PLAN_TENSORS))
        calibrations = {}
        for c in meta["calibrations"]:
            fprs = [float(f) for f in c["fprs"]]
            steps = tensors.get(f"calibration.{c['key']}.step_thresholds")
            precision = tensors.get(f"calibration.{c['key']}.error_precision")
            mean = tensors.get(f"calibration.{c['key']}.error_mean")
            calibrations[c["key"]] = Calibration(
                mode=c["mode"],
                cue_steps=int(c["cue_steps"]),
                error_std=tensors[f"calibration.{c['key']}.error_std"].numpy(),
                source=c["source"],
                error_precision=None if precision is None else precision.numpy(),
                thresholds=dict(zip(fprs, c["thresholds"])),
                step_thresholds={f: steps[i].numpy() for i, f in enumerate(fprs)},
                episode_thresholds=dict(zip(fprs, c["episode_thresholds"])),
                error_mean=None if mean is None else mean.numpy(),
                skills=tuple(str(k) for k in c.get("skills", [])),
            )
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{where} does not match its own metadata: {exc}") from exc
    if normaliser.mean.shape != (len(names),) or normaliser.std.shape != (len(names),):
        raise CheckpointError(f"{where}: normaliser has {normaliser.mean.shape} values for {len(names)} channels")
    for cal in calibrations.values():
        if cal.error_std.ndim != 2 or cal.error_std.shape[1] != len(names):
            raise CheckpointError(f"{where}: calibration {cal.key} has shape {cal.error_std.shape}")
        if cal.error_mean is not None and cal.error_mean.shape != (len(cal.skills), *cal.error_std.shape):
            raise CheckpointError(f"{where}: calibration {cal.key} has mean errors of shape {cal.error_mean.shape} "
                                  f"for {len(cal.skills)} skill(s) and spreads of shape {cal.error_std.shape}")
        if cal.error_precision is not None and cal.error_precision.shape != (len(cal.error_std), len(names), len(names)):
            raise CheckpointError(
                f"{where}: calibration {cal.key} has precision matrices of shape {cal.error_precision.shape}"
            )
    if not all(torch.isfinite(t).all() for t in tensors.values()):
        raise CheckpointError(f"{where} holds NaN or inf values")
    for name in ("W_H", "W_F", "W_C", "W_D"):
        if name in tensors and tensors[name].numel() and float(tensors[name].abs().max()) > MAX_ABS_WEIGHT:
            raise CheckpointError(f"{where}: {name} holds values beyond +-{MAX_ABS_WEIGHT:g}, not a trained network")
    try:
        model = NeuralASM(net, normaliser, names, calibrations, meta.get("provenance"), meta.get("history"),
                          meta.get("rate_hz", DEFAULT_RATE_HZ), plan)
        skills = meta.get(SKILLS)
        return model, None if skills is None else _skill_memory(model, skills, tensors)
    except (KeyError, TypeError, ValueError) as exc:
        raise CheckpointError(f"{where}: {exc}") from exc


def _skill_memory(model: NeuralASM, meta: dict[str, Any], tensors: dict[str, torch.Tensor]) -> SkillMemory:
    """The skill memory of ``model`` from its tensors and header entry (a ValueError if they do not fit)."""
    arrays = {name[len(SKILLS) + 1:]: t.numpy() for name, t in tensors.items() if name.startswith(f"{SKILLS}.")}
    memory = SkillMemory(model, arrays.pop("means"))
    if meta["calibration"] is not None:
        cal = SkillCalibration.from_parts(meta["calibration"], arrays, memory.skills)
        k, width = len(memory.skills), memory.width
        shapes = [cal.courses.shape, *(s.spread.shape for s in cal.spreads.values())]
        precisions = [s.precision.shape for s in cal.spreads.values() if s.precision is not None]
        if any(len(shape) != 3 or shape[::2] != (k, width) for shape in shapes) or \
                any(len(shape) != 3 or shape[1:] != (width, width) for shape in precisions) or \
                any(t.shape != (k,) for t in cal.told.values()) or \
                (cal.scales is not None and cal.scales.shape != (k,)):
            raise ValueError(f"its skill calibration does not fit {k} skills of {width} channels")
        memory.calibration = cal
    return memory


def read(path: str | os.PathLike[str]) -> bytes:
    path = Path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError as exc:
        raise CheckpointError(f"no checkpoint at {path}") from exc


def load(path: str | os.PathLike[str]) -> NeuralASM:
    return from_bytes(read(path), str(path))


def load_memory(path: str | os.PathLike[str]) -> tuple[NeuralASM, SkillMemory | None]:
    """The network at ``path`` and the skill memory it belongs to (None: an ordinary network)."""
    return decode(read(path), str(path))
