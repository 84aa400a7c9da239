"""The robot-logs study's config: the paper's sets written as ROS 2 bags and read back."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from neural_asm.experiments.fault_sweep.config import PaperSets
from neural_asm.experiments.options import data_folder, option


@dataclass(frozen=True)
class RobotLogsConfig(PaperSets):
    """The default Neural ASM trained from the native episode files and from ROS 2 bags of them."""

    jitter_s: float = option(0.002, "largest shift of a bag time stamp (s)")
    epochs: int | None = option(None, "override the default model's epochs")
    bags: Path | None = option(None, "folder the bags and their mapping are written into (default: "
                               "robot_logs/bags in the data home)")

    @property
    def bag_dir(self) -> Path:
        return data_folder(self.bags, "robot_logs/bags")
