"""A training run recorded to ``.rrd`` and ``.mcap``: the energy per epoch.

    with TrainingRecorder(new_run_id("train")) as rec:
        rec.log_history(model.history)     # or rec.log_epoch(k, e) as training goes
"""

from __future__ import annotations

import time
from pathlib import Path
from types import TracebackType
from typing import Any, Sequence

import numpy as np
import rerun as rr

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings import mcap_schemas as schemas
from neural_asm.recordings.mcap_file import McapFile
from neural_asm.recordings.paths import DEFAULT_DIR, run_paths
from neural_asm.recordings.rerun_file import RrdFile


class TrainingRecorder:
    def __init__(self, run_id: str, folder: str | Path = DEFAULT_DIR, metadata: dict[str, Any] | None = None) -> None:
        self.run_id = run_id
        rrd, mcap = run_paths(folder, run_id)
        self.paths = {"rrd": rrd, "mcap": mcap}
        self.rrd = RrdFile(rrd, run_id, bp.training_blueprint())
        self.rrd.rec.log(bp.TRAIN_ENERGY, rr.SeriesLines(names=["energy"]), static=True)
        self.out = McapFile(mcap)
        self.start_ns = time.time_ns()
        self.out.write(self.out.channel("/metadata", schemas.METADATA), self.start_ns, {"run_id": run_id, **(metadata or {})})
        self.epoch_channel = self.out.channel("/train/energy", schemas.TRAINING)

    def log_epoch(self, epoch: int, energy: float) -> None:
        self.rrd.rec.set_time("epoch", sequence=epoch)
        self.rrd.rec.log(bp.TRAIN_ENERGY, rr.Scalars([energy]))
        self._write_epoch(epoch, energy)
        self.out.flush()

    def log_history(self, history: Sequence[float]) -> None:
        """A whole energy curve at once (one columnar send for Rerun)."""
        energies = np.asarray(history, np.float64)
        epochs = np.arange(len(energies))
        self.rrd.rec.send_columns(
            bp.TRAIN_ENERGY,
            indexes=[rr.TimeColumn("epoch", sequence=epochs)],
            columns=rr.Scalars.columns(scalars=energies),
        )
        for epoch, energy in zip(epochs.tolist(), energies.tolist()):
            self._write_epoch(epoch, energy)
        self.out.flush()

    def _write_epoch(self, epoch: int, energy: float) -> None:
        # One nanosecond per epoch keeps messages ordered; epochs have no wall time here.
        self.out.write(self.epoch_channel, self.start_ns + epoch, {"epoch": epoch, "energy": energy})

    def close(self) -> None:
        try:
            self.rrd.close()
        finally:
            self.out.close()

    def __enter__(self) -> "TrainingRecorder":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
