"""Label files kept as Python pickles (the Baxter kitting runs): read without running their code.

Unpickling calls whatever a pickle names, so these files are read by an unpickler that admits
only what a ROS label file holds: strings, numbers, lists, tuples, and ROS times and durations
(``genpy.rostime.Time``/``Duration``, rebuilt as ``RosTime`` here, never imported), made the way
Python 2 pickled them (``copy_reg._reconstructor`` over ``object``). Any other class or
function is refused with one line naming it and the file.

Shapes read here: ``(label, Time)`` (an anomalous segment's label and onset), a list of such
pairs (a whole run's anomalies), and a list of ``(tag, (Time, Time))`` (which skill when).
"""

from __future__ import annotations

import io
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from neural_asm.logs.errors import LogError

_ROS_TIMES = {("genpy.rostime", "Time"), ("genpy.rostime", "Duration"), ("genpy", "Time"), ("genpy", "Duration"),
              ("rospy.rostime", "Time"), ("rospy.rostime", "Duration")}
_RECONSTRUCTORS = {("copy_reg", "_reconstructor"), ("copyreg", "_reconstructor")}
_OBJECT = {("__builtin__", "object"), ("builtins", "object")}


class RosTime:
    """A stand-in for genpy's Time and Duration: seconds and nanoseconds, nothing else."""

    __slots__ = ("secs", "nsecs")

    def __init__(self, secs: int = 0, nsecs: int = 0) -> None:
        self.secs, self.nsecs = secs, nsecs

    def __setstate__(self, state: Any) -> None:
        if isinstance(state, dict):
            state = [state.get("secs"), state.get("nsecs")]
        if not (isinstance(state, (list, tuple)) and len(state) == 2 and all(type(v) is int for v in state)):
            raise pickle.UnpicklingError(f"a ROS time's state must be [secs, nsecs], got {state!r}")
        self.secs, self.nsecs = state

    def to_sec(self) -> float:
        return self.secs + self.nsecs * 1e-9


def _reconstruct(cls: Any, base: Any, state: Any) -> RosTime:
    """copy_reg._reconstructor, for a ROS time over ``object`` only."""
    if cls is not RosTime or base is not object or state is not None:
        raise pickle.UnpicklingError("copy_reg._reconstructor is admitted for ROS times over object only")
    return RosTime()


class _Guarded(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        key = (module, name)
        if key in _ROS_TIMES:
            return RosTime
        if key in _RECONSTRUCTORS:
            return _reconstruct
        if key in _OBJECT:
            return object
        raise pickle.UnpicklingError(f"refused {module}.{name}: a label file holds labels and ROS times only")


def load_labels(path: Path) -> Any:
    """The file's content with ROS times as ``RosTime``; None for an empty file (some runs'
    anomaly lists are empty files); a LogError naming the file for anything else."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise LogError(f"cannot read the label file {path}: {exc.strerror or exc}") from None
    if not raw:
        return None
    try:
        return _Guarded(io.BytesIO(raw), encoding="latin1").load()
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError, KeyError) as exc:
        raise LogError(f"label file {path}: {exc}") from None


def _label(value: Any, path: Path) -> str:
    if isinstance(value, bytes):
        value = value.decode("latin1")
    if not isinstance(value, str) or not value:
        raise LogError(f"label file {path}: the label must be a text, got {value!r}")
    return value


def _time(value: Any, path: Path) -> float:
    if not isinstance(value, RosTime):
        raise LogError(f"label file {path}: expected a ROS time, got {type(value).__name__}")
    return value.to_sec()


@dataclass(frozen=True)
class Anomaly:
    label: str
    time_s: float  # on the recording's clock (ROS time, s)


def read_anomaly(path: Path) -> Anomaly:
    """A segment's ``(label, Time)``."""
    content = load_labels(path)
    if not (isinstance(content, tuple) and len(content) == 2):
        got = f"a tuple of {len(content)}" if isinstance(content, tuple) else type(content).__name__
        raise LogError(f"label file {path}: expected (label, time), got {got}")
    return Anomaly(_label(content[0], path), _time(content[1], path))


def read_anomalies(path: Path) -> list[Anomaly]:
    """A run's list of ``(label, Time)``; an empty file is an empty list."""
    content = load_labels(path)
    if content is None:
        return []
    if not isinstance(content, list) or not all(isinstance(p, tuple) and len(p) == 2 for p in content):
        raise LogError(f"label file {path}: expected a list of (label, time) pairs")
    return [Anomaly(_label(a, path), _time(t, path)) for a, t in content]


@dataclass(frozen=True)
class Phase:
    tag: int  # the skill's number; 0 between skills, -1 at the end
    start_s: float
    end_s: float


def read_phases(path: Path) -> list[Phase]:
    """A run's ``[(tag, (start, end)), ...]``: which skill when."""
    content = load_labels(path)
    if not isinstance(content, list):
        raise LogError(f"label file {path}: expected a list of (tag, (start, end))")
    phases = []
    for item in content:
        if not (isinstance(item, tuple) and len(item) == 2 and type(item[0]) is int
                and isinstance(item[1], tuple) and len(item[1]) == 2):
            raise LogError(f"label file {path}: expected (tag, (start, end)), got {item!r}")
        phases.append(Phase(item[0], _time(item[1][0], path), _time(item[1][1], path)))
    return phases
