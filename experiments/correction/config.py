"""Every constant of the reactive-correction experiment in one typed place.

Seeds: the test seeds, the seeds that calibrate the monitor and the seeds on which the hit
family and the correction gains (`SIM.correction`) were chosen are three disjoint ranges of
the held-out block, none of them a demonstration's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from sim.config import CONTROLLERS, SIM, CorrectionGains


@dataclass(frozen=True)
class CorrectionConfig:
    n_seeds: int = 24  # test seeds per hit, skills alternating
    test_seed: int = SIM.seeds.held_out + 1000  # first test seed
    selection_seeds: tuple[int, int] = (SIM.seeds.held_out, SIM.seeds.held_out + 40)  # gains chosen here
    monitor_seed: int = SIM.seeds.held_out + 500  # normal episodes calibrating the monitor
    monitor_seeds: int = 20  # per split (precisions, thresholds)
    served_monitor_seeds: int = 50  # per split, for the compliant monitor the service hosts (served.py)
    # The hit (sim.disturbances.elbow_hit): a box dropped from 5 cm above the elbow at 2 m/s
    # during the carry, heavier and heavier; momentum = mass x speed.
    momenta: tuple[float, ...] = (10.0, 20.0, 30.0, 40.0, 60.0, 80.0)  # kg m/s
    speed_m_s: float = 2.0
    demo_momentum: float = 40.0  # the client demo's hit (nasm client --falling-object): the compliant arm alone
    # drops the cube on one skill there, and the correction places it (README)
    drop_height_m: float = 0.05
    release_s: float = 4.0  # the carry: the cube is in the hand from 2.5 s to 6.0 s
    # Recovered: the cube within SIM.success_tolerance_m of its target AND every joint back
    # within band_deg of the executed plan from deadline_s to the end.
    band_deg: float = 2.0
    deadline_s: float = 6.0
    fpr: float = 0.01  # the monitor's false-positive rate (whole normal episodes)
    monitor_mode: str = "offline"
    controllers: tuple[str, ...] = CONTROLLERS
    gains: CorrectionGains = SIM.correction
    gated: bool = True  # the correction engages once the monitor has flagged (False: from the start)
    epochs: int | None = None  # None: the FAST preset's

    def __post_init__(self) -> None:
        tests = range(self.test_seed, self.test_seed + self.n_seeds)
        reserved = {"selection": range(*self.selection_seeds),
                    "monitor": range(self.monitor_seed, self.monitor_seed + 2 * self.served_monitor_seeds)}
        for name, seeds in reserved.items():
            if tests.start < seeds.stop and seeds.start < tests.stop:
                raise ValueError(f"test seeds {tests.start}..{tests.stop - 1} overlap the {name} seeds "
                                 f"{seeds.start}..{seeds.stop - 1}")

    @property
    def test_seeds(self) -> list[int]:
        return list(range(self.test_seed, self.test_seed + self.n_seeds))

    def with_(self, **changes: Any) -> "CorrectionConfig":
        return replace(self, **changes)


CORRECTION = CorrectionConfig()
