"""Every constant of the reactive-correction experiment in one typed place.

Seeds: the test seeds, the seeds that calibrate the monitor and the seeds on which the hit
family and the correction gains (`SIM.correction`) were chosen are three disjoint ranges of
the held-out block, none of them a demonstration's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from neural_asm.experiments.options import option
from neural_asm.models.config import SCORING
from neural_asm.models.recall import RECALL_MODES
from neural_asm.pipelines.compliant import SERVED_MONITOR, MonitorSeeds
from neural_asm.sim.config import CONTROLLERS, RATES, SIM, CorrectionGains, ElbowHit


CORRECTIONS: tuple[str, ...] = ("none", "corrected")  # every hit without and with the memory's correction


@dataclass(frozen=True)
class CorrectionConfig:
    """A box hits the arm carrying the cube, under stiff and compliant control, with and without the
    memory's correction."""

    n_seeds: int = option(24, "test seeds per hit (skills alternate)", flag="seeds", min=1)
    test_seed: int = option(SIM.seeds.held_out + 1000, "first test seed (a fresh block: any range clear of the "
                            "selection and monitor seeds)", flag="first-seed")
    selection_seeds: tuple[int, int] = (SIM.seeds.held_out, SIM.seeds.held_out + 40)  # gains chosen here
    monitor: MonitorSeeds = MonitorSeeds(per_split=20)  # normal runs calibrating the monitor, per controller
    hit: ElbowHit = SIM.hit  # the box on the elbow during the carry; momentum = mass x speed
    momenta: tuple[float, ...] = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)  # kg m/s
    # Recovered: the cube within SIM.success_tolerance_m of its target AND every joint back
    # within band_deg of the executed plan from deadline_s to the end.
    band_deg: float = 2.0
    deadline_s: float = 6.0
    fpr: float = SCORING.default_fpr  # the monitor's false-positive rate (whole normal episodes)
    mode: str | None = None  # the monitor's recall mode; None: the rate's (`monitor_mode`)
    controllers: tuple[str, ...] = CONTROLLERS
    gains: CorrectionGains = SIM.correction
    gated: bool = True  # the correction engages once the monitor has flagged (False: from the start)
    epochs: int | None = option(None, "override the default network's epochs")
    # The monitor's observation rate (Hz): at 40 a network trained at 40 Hz monitors every tick
    # of the plan the 2 Hz network recalls (`pipelines.compliant.planner_of`).
    rate: float = option(SIM.timing.observation_hz, "the monitor's observations per second: 2 (the paper's skill "
                         "layer) or 40 (every control tick: a network trained at 40 Hz monitors and gates the "
                         "correction at every tick; the 2 Hz network plans)")
    trainings: int = option(1, "trainings (seeds 0, 1, ...): recovery rates are their mean, each training's in "
                            "per_training", min=1)

    def __post_init__(self) -> None:
        if self.rate not in RATES:
            raise ValueError(f"rate must be one of {', '.join(map(str, RATES))} Hz, got {self.rate!r}")
        if self.mode is not None and self.mode not in RECALL_MODES:
            raise ValueError(f"mode must be one of {', '.join(RECALL_MODES)} or None, got {self.mode!r}")
        if self.trainings < 1:
            raise ValueError(f"trainings must be >= 1, got {self.trainings}")
        tests = range(self.test_seed, self.test_seed + self.n_seeds)
        reserved = {"selection": range(*self.selection_seeds),
                    "monitor": range(self.monitor.first, self.monitor.last + 1),
                    "served monitor": range(SERVED_MONITOR.first, SERVED_MONITOR.last + 1)}
        for name, seeds in reserved.items():
            if tests.start < seeds.stop and seeds.start < tests.stop:
                raise ValueError(f"test seeds {tests.start}..{tests.stop - 1} overlap the {name} seeds "
                                 f"{seeds.start}..{seeds.stop - 1}")

    @property
    def monitor_mode(self) -> str:
        """`mode`, else the rate's served one (`ScoringConfig.served_mode`: offline at 2 Hz, online at 40), so that a
        config given another rate monitors as that rate's default does."""
        return SCORING.served_mode(self.rate) if self.mode is None else self.mode

    @property
    def test_seeds(self) -> list[int]:
        return list(range(self.test_seed, self.test_seed + self.n_seeds))

    def with_(self, **changes: Any) -> "CorrectionConfig":
        return replace(self, **changes)


CORRECTION = CorrectionConfig()
