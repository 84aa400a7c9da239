"""The monitor's verdict where ROS tools look for it: ``/diagnostics`` (``DiagnosticArray``, shown
by ``rqt_robot_monitor``, the diagnostic aggregator and Foxglove without configuration) when the
status changes and twice a second otherwise (ROS asks for at least once a second: a diagnostic
is a component's health, not a data stream), and ``nasm/fault`` (``std_msgs/Bool``) and
``nasm/energy`` (``std_msgs/Float64``) every step."""

from __future__ import annotations

import time
from typing import Any

from neural_asm.models.answer import StepAnswer
from neural_asm.ros2 import messages as m
from neural_asm.ros2.bus import Bus

T = m.STORE.types
STATUS = T[m.DIAGNOSTIC_STATUS]
OK, WARN, ERROR = int(STATUS.OK), int(STATUS.WARN), int(STATUS.ERROR)
NAME = "nasm: fault monitor"
HEARTBEAT_S = 0.5  # the status again when it did not change: ROS tools mark a silent one stale


def _stamp(ns: int) -> Any:
    return T[m.HEADER](stamp=T[m.TIME](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id="")


def answer_values(answer: StepAnswer, episode: int) -> dict[str, str]:
    """A step's verdict as the status's key-values."""
    return {"episode": str(episode), "step": str(answer.step), "energy": f"{answer.energy:.6g}",
            "threshold": f"{answer.threshold:.6g}", "isolated_joint": answer.isolated_joint or "",
            "skill": answer.skill or ""}


class VerdictWriter:
    """The node's publishers. The status (``status()``) is published when its level or message
    changes or a WARN is said, and again by ``heartbeat`` with the newest step's values."""

    def __init__(self, bus: Bus, hardware_id: str) -> None:
        self.hardware_id = hardware_id
        self._diagnostics = bus.writer("/diagnostics", m.DIAGNOSTIC_ARRAY)
        self._fault = bus.writer("nasm/fault", m.BOOL)
        self._energy = bus.writer("nasm/energy", m.FLOAT64)
        self.level, self.message = OK, "waiting for the mapped topics"
        self._values: dict[str, str] | tuple[StepAnswer, int] = {}  # a step's: turned into text when said
        self._said = 0.0

    def status(self) -> Any:
        """The status now, as ``/diagnostics`` carries it."""
        values = answer_values(*self._values) if isinstance(self._values, tuple) else self._values
        return STATUS(level=self.level, name=NAME, message=self.message, hardware_id=self.hardware_id,
                      values=[T[m.KEY_VALUE](key=k, value=v) for k, v in values.items()])

    def say(self, level: int, message: str, values: dict[str, str] | None = None) -> None:
        """Publish a status now (and keep it for the heartbeat)."""
        self.level, self.message, self._values = level, message, values or {}
        self._publish()

    def step(self, answer: StepAnswer, episode: int) -> None:
        """Every step: its fault and energy; its status (ERROR when flagged) if it says something new."""
        self._fault.write(T[m.BOOL](data=bool(answer.fault)))
        self._energy.write(T[m.FLOAT64](data=float(answer.energy)))
        level, message = (ERROR, f"fault: joint {answer.isolated_joint} isolated") if answer.fault else (OK, "normal")
        changed = (level, message) != (self.level, self.message)
        self.level, self.message, self._values = level, message, (answer, episode)
        if changed:
            self._publish()

    def heartbeat(self) -> None:
        """The status again if none was published for ``HEARTBEAT_S``."""
        if time.monotonic() - self._said >= HEARTBEAT_S:
            self._publish()

    def _publish(self) -> None:
        self._diagnostics.write(T[m.DIAGNOSTIC_ARRAY](header=_stamp(time.time_ns()), status=[self.status()]))
        self._said = time.monotonic()
