"""An episode to a Rerun ``.rrd``: time series of the model's scores and a 3D world.

Vectors are logged as ONE entity each with their series names logged once, static
(25 entities would cost ~30x more per step). Steps are buffered and sent as columns
(``send_columns``) every ``STEP_BATCH`` steps, or sooner when flushed: one call per entity
instead of one per step (at 16 steps a send, the calls were still most of the cost). Rerun's
batcher writes them to the file within a fraction of a second, and ``flush`` waits until it
has; a crash loses the steps not yet flushed.
Two timelines: ``step`` (the model's observation steps) and ``time`` (episode seconds,
for 40 Hz world traces).

Fault events are logged as their step arrives, not with its batch: from the step a fault is
detected, the event log says so and, in a file that also has the world (a client's), a red
sphere marks the isolated joint on the arm.
"""

from __future__ import annotations

from collections import defaultdict
from functools import lru_cache
import numpy as np
import rerun as rr

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings import drawing
from neural_asm.recordings.records import StepRecord, WorldRecord, Workcell
from neural_asm.recordings.rerun_file import RrdFile

STEP_BATCH = 40  # steps per columnar send at most: a second at 40 Hz, more than a 2 Hz episode


@lru_cache(maxsize=8)
def _series_styles(channel_names: tuple[str, ...], joint_names: tuple[str, ...]) -> dict[str, rr.AsComponents]:
    """The static names and styles of each time-series entity, built once per channel set (a
    recorder opens a file per session)."""
    return {
        bp.ENERGY: rr.SeriesLines(names=list(bp.ENERGY_SERIES)),
        bp.MARGIN: rr.SeriesLines(names=list(bp.MARGIN_SERIES), colors=[[31, 119, 180], [214, 39, 40]],
                                  widths=[2.0, 1.0]),
        bp.FLAG: rr.SeriesLines(names=["fault"], colors=[[214, 39, 40]], interpolation_mode="StepAfter"),
        bp.ERRORS: rr.SeriesLines(names=list(channel_names)),
        bp.OBSERVATION: rr.SeriesLines(names=list(channel_names)),
        bp.JOINTS_OBSERVED: rr.SeriesLines(names=[f"{n} observed" for n in joint_names], widths=2.0),
        bp.JOINTS_EXPECTED: rr.SeriesPoints(names=[f"{n} expected" for n in joint_names], markers="cross",
                                            marker_sizes=4.0),
    }


class RerunEpisode:
    def __init__(
        self,
        stream: RrdFile,
        channel_names: tuple[str, ...],
        step_period_s: float,
        joints: tuple[int, ...] = (),
        events: bool = True,
        step_batch: int = STEP_BATCH,
    ) -> None:
        """Logs to ``stream`` (a file, or a live viewer's stream); steps are sent every
        ``step_batch`` steps or when ``send_steps`` is called."""
        self.channel_names = channel_names
        self.events = events  # log fault events as text (False: another file of the recording does)
        self.joints = list(joints)
        self.step_period_s = step_period_s
        self.ee_path: list[np.ndarray] = []
        self.pending: list[StepRecord] = []
        self.pending_events: list[tuple[float, str, str]] = []  # (time, text, level), sent with the steps
        self.flagged_joint: str | None = None  # the isolated joint while the episode is flagged
        self.flagged = False
        self.links: np.ndarray | None = None  # the arm's latest link positions
        self.marked = False  # the faulty-joint marker is drawn
        self.workcell: Workcell | None = None  # the one drawn
        self.peak_errors = np.zeros(len(channel_names))
        self.step_batch = step_batch
        self.rrd = stream
        joint_names = tuple(channel_names[i] for i in self.joints)
        for entity, series in _series_styles(channel_names, joint_names).items():
            self.rrd.rec.log(entity, series, static=True)

    def _set_time(self, time_s: float) -> None:
        self.rrd.rec.set_time("step", sequence=int(time_s / self.step_period_s + 1e-9))
        self.rrd.rec.set_time("time", duration=time_s)

    def write_step(self, r: StepRecord) -> None:
        self.pending.append(r)
        if r.fault is not None:
            self._log_event(r, r.step * self.step_period_s if r.time_s is None else r.time_s)
        if len(self.pending) >= self.step_batch:
            self.send_steps()

    def send_steps(self) -> None:
        """Send the buffered steps, one column batch per entity, and their events."""
        self._send_events()
        if not self.pending:
            return
        rows: dict[str, tuple[list[float], list[np.ndarray]]] = defaultdict(lambda: ([], []))

        def add(path: str, time_s: float, values: np.ndarray | list[float]) -> None:
            rows[path][0].append(time_s)
            rows[path][1].append(np.asarray(values, np.float64))

        for r in self.pending:
            t = r.step * self.step_period_s if r.time_s is None else r.time_s
            add(bp.OBSERVATION, t, r.observation)
            if self.joints:
                add(bp.JOINTS_OBSERVED, t, r.observation[self.joints])
                if r.expected is not None:
                    add(bp.JOINTS_EXPECTED, t, r.expected[self.joints])
            if r.errors is not None:
                add(bp.ERRORS, t, r.errors)
                self.peak_errors = np.maximum(self.peak_errors, np.abs(r.errors))
            if r.energy is not None:
                add(bp.ENERGY, t, [r.energy, np.nan if r.threshold is None else r.threshold])
                if r.margin is not None:
                    add(bp.MARGIN, t, [r.margin, 0.0])
            if r.fault is not None:
                add(bp.FLAG, t, [float(r.fault)])
        if len(self.pending) == 1:  # a live step: one log call per entity costs a tenth of a column send
            self.pending = []
            self._set_time(t)
            for path, (_, values) in rows.items():
                self.rrd.rec.log(path, rr.Scalars(values[0]))
            return
        self.pending = []
        indexes: dict[tuple[float, ...], list[rr.TimeColumn]] = {}  # entities with the same steps share them
        for path, (times, values) in rows.items():
            if (key := tuple(times)) not in indexes:
                indexes[key] = self._time_columns(np.asarray(times))
            self.rrd.rec.send_columns(path, indexes=indexes[key], columns=rr.Scalars.columns(scalars=np.stack(values)))

    def _log_event(self, r: StepRecord, t: float) -> None:
        """A line in the event log, and the joint marked, when the episode is first flagged and
        when the isolated joint changes."""
        if not r.fault or (self.flagged and r.isolated_joint == self.flagged_joint):
            return
        if self.events:  # a log call per event costs as much as a column send of many
            if not self.flagged:
                text = (f"fault detected at step {r.step}: energy {r.energy:.4g} > threshold {r.threshold:.4g}; "
                        f"isolated joint: {r.isolated_joint or 'none'}")
            else:
                text = f"step {r.step}: isolated joint now {r.isolated_joint or 'none'}"
            self.pending_events.append((t, text, "WARN" if not self.flagged else "INFO"))
        self.flagged, self.flagged_joint = True, r.isolated_joint
        if self.links is not None:  # the marker moves at the event's time
            self._set_time(t)
            self._mark_faulty_joint()

    def _send_events(self) -> None:
        if not self.pending_events:
            return
        seconds = np.asarray([t for t, _, _ in self.pending_events])
        texts = [text for _, text, _ in self.pending_events]
        levels = [level for _, _, level in self.pending_events]
        self.pending_events = []
        self.rrd.rec.send_columns(bp.EVENTS, indexes=self._time_columns(seconds),
                                  columns=rr.TextLog.columns(text=texts, level=levels))

    def _time_columns(self, seconds: np.ndarray) -> list[rr.TimeColumn]:
        """The step and time timelines of rows at ``seconds``."""
        return [rr.TimeColumn("step", sequence=(seconds / self.step_period_s + 1e-9).astype(np.int64)),
                rr.TimeColumn("time", duration=seconds)]

    def _faulty_row(self) -> int | None:
        """The link-position row of the isolated joint (row i + 1 for the i-th joint channel)."""
        if self.flagged_joint not in self.channel_names:
            return None
        channel = self.channel_names.index(self.flagged_joint)
        return self.joints.index(channel) + 1 if channel in self.joints else None

    def _mark_faulty_joint(self) -> None:
        """The marker on the isolated joint; cleared when the flagged steps isolate none it can draw."""
        if self.links is None:
            return
        row = self._faulty_row()
        if row is not None and row < len(self.links):
            self.rrd.rec.log(bp.FAULTY_JOINT, rr.Points3D([self.links[row]], radii=drawing.FAULT_MARKER_RADIUS,
                                                          colors=[drawing.FAULTY],
                                                          labels=[f"{self.flagged_joint}: fault"]))
            self.marked = True
        elif self.marked:
            self.rrd.rec.log(bp.FAULTY_JOINT, rr.Clear(recursive=False))
            self.marked = False

    def _show_largest_errors(self) -> None:
        """Of the error view's channels, keep visible the ones with the largest peaks."""
        shown = np.zeros(len(self.channel_names), bool)
        shown[np.argsort(-self.peak_errors, kind="stable")[:bp.SHOWN_ERRORS]] = True
        self.rrd.rec.log(bp.ERRORS, rr.SeriesLines(names=list(self.channel_names), visible_series=shown), static=True)

    def write_world(self, w: WorldRecord) -> None:
        self._set_time(w.time_s)
        log = self.rrd.rec.log
        cell = w.workcell
        if cell is not None and cell != self.workcell:
            self.workcell = cell
            center, half_size = drawing.table_top(cell.table_center, cell.table_half_size)
            log(bp.TABLE, rr.Boxes3D(centers=[center], half_sizes=[half_size], colors=[drawing.TABLE],
                                     fill_mode="solid"), static=True)
        if w.link_positions is not None:
            self.links = np.asarray(w.link_positions, np.float64)
            log(bp.ARM, rr.LineStrips3D([self.links], radii=drawing.LINK_RADIUS, colors=[drawing.ARM]))
            log(bp.ARM_JOINTS, rr.Points3D(self.links, radii=drawing.LINK_RADIUS * 1.2, colors=[drawing.ARM]))
            if self.flagged:
                self._mark_faulty_joint()
        if w.ee is not None:
            self.ee_path.append(np.asarray(w.ee, np.float64))
            log(bp.EE_PATH, rr.LineStrips3D([np.stack(self.ee_path)], radii=0.005))
        if cell is not None and w.cube is not None:
            log(bp.CUBE, rr.Boxes3D(centers=[w.cube], half_sizes=[[cell.cube_half_size] * 3], colors=[drawing.CUBE],
                                    fill_mode="solid"))
        if cell is not None and w.box is not None:
            log(bp.BOX, rr.Boxes3D(centers=[w.box], half_sizes=[cell.box_half_size], colors=[drawing.BOX],
                                   fill_mode="solid"))

    def flush(self) -> None:
        """Send the buffered steps and wait until they are in the file (not for a live view)."""
        self.send_steps()
        self.rrd.flush()

    def close(self) -> None:
        try:
            self.send_steps()
            self._show_largest_errors()
        finally:
            self.rrd.close()
