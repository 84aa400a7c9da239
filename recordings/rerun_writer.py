"""An episode to a Rerun ``.rrd``: time series of the model's scores and a 3D world.

Vectors are logged as ONE entity each with their series names logged once, static
(25 entities would cost ~30x more per step; NOTES.md). Two timelines: ``step`` (the
model's observation steps) and ``time`` (episode seconds, for 40 Hz world traces).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from recordings import blueprint as bp
from recordings.records import StepRecord, WorldRecord, joint_indices
from recordings.rerun_file import RrdFile

CUBE_HALF_SIZE = 0.025  # m
LINK_RADIUS = 0.04  # m


class RerunEpisode:
    def __init__(
        self,
        path: Path,
        channel_names: tuple[str, ...],
        recording_id: str,
        step_period_s: float,
    ) -> None:
        self.channel_names = channel_names
        self.joints = joint_indices(channel_names)
        self.step_period_s = step_period_s
        self.ee_path: list[np.ndarray] = []
        self.rrd = RrdFile(path, recording_id, bp.episode_blueprint())
        self._log_series_names()

    def _log_series_names(self) -> None:
        joint_names = [self.channel_names[i] for i in self.joints]
        static = {
            bp.ENERGY: rr.SeriesLines(names=list(bp.ENERGY_SERIES)),
            bp.FLAG: rr.SeriesLines(names=["fault"]),
            bp.ERRORS: rr.SeriesLines(names=list(self.channel_names)),
            bp.OBSERVATION: rr.SeriesLines(names=list(self.channel_names)),
            bp.JOINTS_OBSERVED: rr.SeriesLines(names=[f"{n} observed" for n in joint_names]),
            bp.JOINTS_EXPECTED: rr.SeriesLines(names=[f"{n} expected" for n in joint_names]),
        }
        for path, series in static.items():
            self.rrd.rec.log(path, series, static=True)

    def _set_time(self, time_s: float) -> None:
        self.rrd.rec.set_time("step", sequence=int(time_s / self.step_period_s + 1e-9))
        self.rrd.rec.set_time("time", duration=time_s)

    def write_step(self, r: StepRecord) -> None:
        self._set_time(r.step * self.step_period_s if r.time_s is None else r.time_s)
        log = self.rrd.rec.log
        log(bp.OBSERVATION, rr.Scalars(r.observation))
        if self.joints:
            log(bp.JOINTS_OBSERVED, rr.Scalars(r.observation[self.joints]))
            if r.expected is not None:
                log(bp.JOINTS_EXPECTED, rr.Scalars(r.expected[self.joints]))
        if r.errors is not None:
            log(bp.ERRORS, rr.Scalars(r.errors))
        if r.energy is not None:
            threshold = np.nan if r.threshold is None else r.threshold
            log(bp.ENERGY, rr.Scalars([r.energy, threshold]))
        if r.fault is not None:
            log(bp.FLAG, rr.Scalars([float(r.fault)]))

    def write_world(self, w: WorldRecord) -> None:
        self._set_time(w.time_s)
        log = self.rrd.rec.log
        if w.link_positions is not None:
            log(bp.ARM, rr.LineStrips3D([w.link_positions], radii=LINK_RADIUS))
            log(bp.ARM_JOINTS, rr.Points3D(w.link_positions, radii=LINK_RADIUS * 1.2))
        if w.ee is not None:
            self.ee_path.append(np.asarray(w.ee, np.float64))
            log(bp.EE_PATH, rr.LineStrips3D([np.stack(self.ee_path)], radii=0.005))
        if w.cube is not None:
            log(bp.CUBE, rr.Boxes3D(centers=[w.cube], half_sizes=[[CUBE_HALF_SIZE] * 3]))

    def close(self) -> None:
        self.rrd.close()
