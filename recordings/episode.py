"""One episode (a client run or a service session) recorded to ``.rrd`` and ``.mcap``.

    with EpisodeRecorder("client-...", channel_names, recording_id=rid) as rec:
        rec.log_step(StepRecord(step=k, observation=x, energy=e, ...))
        rec.log_world(WorldRecord(time_s=t, link_positions=p, ee=tcp, cube=c))

Both files are closed when the block exits, normally, on Ctrl-C or on an error.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Iterable, Protocol

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings.live import LiveViewer
from neural_asm.recordings.foxglove_live import FoxgloveLive
from neural_asm.recordings.mcap_file import McapFile
from neural_asm.recordings.mcap_writer import McapEpisode
from neural_asm.recordings.paths import DEFAULT_DIR, run_paths
from neural_asm.recordings.records import StepRecord, WorldRecord
from neural_asm.recordings.rerun_file import RrdFile
from neural_asm.recordings.rerun_writer import RerunEpisode

FORMATS = ("rrd", "mcap")


class _Writer(Protocol):
    def write_step(self, r: StepRecord) -> None: ...
    def write_world(self, w: WorldRecord) -> None: ...
    def flush(self) -> None: ...
    def close(self) -> None: ...


@dataclass(frozen=True)
class View:
    """How an episode is drawn: its step period, which channels are joint angles (drawn observed
    against expected), whether its ``.rrd`` carries the Rerun layout (not in a file of many that
    share one, e.g. a service's sessions: see ``recorder``) and the event log (not when another
    file of the same recording says each event, as the service's does for its clients)."""

    step_period_s: float = 0.5
    joints: tuple[int, ...] = ()
    layout: bool = True
    events: bool = True


@dataclass(frozen=True)
class Live:
    """Where the steps are also sent as they arrive: a Rerun viewer (with its event log whatever
    ``View.events`` says: the viewer may have only this side) and a Foxglove server (the MCAP
    file's messages)."""

    rerun: LiveViewer | None = None
    foxglove: FoxgloveLive | None = None


class EpisodeRecorder:
    def __init__(
        self,
        run_id: str,
        channel_names: Iterable[str],
        *,
        folder: str | Path = DEFAULT_DIR,
        recording_id: str | None = None,
        metadata: dict[str, Any] | None = None,
        formats: Iterable[str] = FORMATS,
        view: View = View(),
        live: Live = Live(),
    ) -> None:
        """An episode's recordings in ``formats`` under ``folder``, drawn as ``view`` says, also
        sent ``live``."""
        names = tuple(channel_names)
        step_period_s, joints, events = view.step_period_s, view.joints, view.events
        formats = tuple(formats)
        unknown = set(formats) - set(FORMATS)
        if unknown:
            raise ValueError(f"unknown recording formats {sorted(unknown)}; known: {FORMATS}")
        self.run_id = run_id
        self.recording_id = recording_id or run_id
        rrd, mcap = run_paths(folder, run_id)
        self.paths: dict[str, Path] = {}
        self._writers: list[_Writer] = []
        try:
            if "rrd" in formats:
                stream = RrdFile(rrd, self.recording_id, bp.episode_blueprint() if view.layout else None)
                self._writers.append(RerunEpisode(stream, names, step_period_s, joints, events))
                self.paths["rrd"] = rrd
            if live.rerun is not None:
                self._writers.append(RerunEpisode(live.rerun.episode(self.recording_id), names, step_period_s,
                                                  joints, step_batch=1))
            run = {"run_id": run_id, "recording_id": self.recording_id, "channel_names": list(names), **(metadata or {})}
            if "mcap" in formats:
                writer = McapEpisode(McapFile(mcap), names, step_period_s)
                self._writers.append(writer)
                self.paths["mcap"] = mcap
                writer.write_metadata(run)
            if live.foxglove is not None:
                writer = McapEpisode(live.foxglove.episode(), names, step_period_s)
                self._writers.append(writer)
                writer.write_metadata(run)
        except BaseException:
            self.close()
            raise

    def log_step(self, record: StepRecord) -> None:
        for w in self._writers:
            w.write_step(record)

    def log_world(self, record: WorldRecord) -> None:
        for w in self._writers:
            w.write_world(record)

    def flush(self) -> None:
        """Push what is buffered to the files, so that a crash cannot lose it."""
        for w in self._writers:
            w.flush()

    def close(self) -> None:
        """Close every file, even if one fails; idempotent."""
        writers, self._writers = self._writers, []
        errors = []
        for w in writers:
            try:
                w.close()
            except Exception as exc:  # close the others before reporting
                errors.append(exc)
        if errors:
            raise errors[0]

    def __enter__(self) -> "EpisodeRecorder":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
