"""`nasm faults --rate 40`: the served monitor at the controller's rate, beside the paper's 2 Hz one.

Each rate's default network (`models.config.RATE_DEFAULTS`) is trained and calibrated on the
same episodes (a 40 Hz episode's every 20th observation is its 2 Hz one, bit for bit), saved as
the checkpoint the service would host, and scored by its sessions' own rule on the same joint
locks and falling objects (`experiments.fault_sweep.served`), in both recall modes.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from experiments.fault_sweep.data import SETS
from experiments.fault_sweep.served import Onsets, evaluate, subsampled
from models import checkpoint
from models.config import RATE_DEFAULTS, TPCConfig
from models.recall import RECALL_MODES
from pipelines.default_model import model_name, provenance_of, train_calibrated
from pipelines.episodes import NormalSets, as_sequences, paper_sets, split_normal
from runtime.parallel import Parallel
from sim.config import SIM

HIT_SETS = ("hits", "hit_twins")
# The recall mode of the headline: online. At 40 Hz offline recall rolls 300 steps forward from
# one cue and drifts from the episode (held-out offline error 1.3 normalised units against 0.2
# online), so a 40 Hz session monitors in online recall; both modes are in `rates`.
HEADLINE_MODE = "online"


def at_rate(normal: NormalSets, rate_hz: float) -> NormalSets:
    return NormalSets(normal.channel_names, *(subsampled(s, rate_hz) for s in
                                              (normal.demos, normal.precision, normal.calibration, normal.normal_test)))


def run_rate_sweep(data_dir: Path, out_dir: Path, rate: float, n_normal: int = 400, epochs: int | None = None,
                   *, parallel: Parallel = Parallel()) -> dict:
    """Train, calibrate, save and score the default network at `rate` and at 2 Hz; the result's
    headline (`detection`, `latency`, ...) is the `rate` network's in `HEADLINE_MODE`."""
    start = time.perf_counter()
    sets = paper_sets(data_dir, SETS + HIT_SETS, n_normal, parallel, rate)
    normal = split_normal(sets["demos"], sets["normal"])
    locks = Onsets.against(as_sequences(sets["faults"]), np.array([e.fault.joint for e in sets["faults"]]),
                           as_sequences(sets["twins"]))
    momenta = np.array([round(e.disturbance.mass_kg * e.disturbance.speed_m_s, 6) for e in sets["hits"]])
    hits = Onsets.against(as_sequences(sets["hits"]), momenta, as_sequences(sets["hit_twins"]))
    by_rate = {}
    for hz in tqdm(dict.fromkeys((rate, SIM.timing.observation_hz)), desc="rates"):
        split = at_rate(normal, hz)
        config: TPCConfig = RATE_DEFAULTS[hz]
        config = config if epochs is None or hz != rate else config.with_(epochs=epochs)
        began = time.perf_counter()
        model = train_calibrated(split.demos, split.precision, split.calibration, split.channel_names, config,
                                 provenance=provenance_of(split, data_dir))
        trained = time.perf_counter() - began
        checkpoint.save(model, out_dir / "models" / f"{model_name(hz)}.safetensors")
        by_rate[f"{hz:g}"] = {"train_and_calibrate_seconds": round(trained, 1), "epochs": config.epochs,
                              "modes": {mode: evaluate(model, mode, split.normal_test, locks, hits)
                                        for mode in RECALL_MODES}}
    headline = by_rate[f"{rate:g}"]["modes"][HEADLINE_MODE]
    return {
        "rate_hz": rate,
        **{key: headline[key] for key in ("detection", "latency", "normal_episodes_flagged", "isolation_at_detection",
                                          "threshold", "fpr", "mode")},
        "episodes": {"demonstrations": len(normal.demos), "normal_precision": len(normal.precision),
                     "normal_calibration": len(normal.calibration), "normal_test": len(normal.normal_test),
                     "lock": len(locks.onset_s), "falling_object": len(hits.onset_s)},
        "onset": "first 40 Hz tick at which the observations differ from the same seed's twin",
        "rates": by_rate,
        "seconds": round(time.perf_counter() - start, 1),
    }


def pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def ms(x: float | None) -> str:
    return "-" if x is None else f"{x:.0f}"


def markdown(result: dict) -> str:
    """One row per rate and recall mode: what its sessions decide."""
    lines = [f"# The served monitor at {result['rate_hz']:g} Hz and at 2 Hz", "",
             "Episode threshold at 1 % of calibration episodes; latency from the first tick the fault or the hit "
             "changes the observations to the first flag (ms, median / 95th percentile).", "",
             "| rate | recall | normal episodes flagged | locks detected | falling object detected | lock latency "
             "| falling-object latency | isolation at detection |",
             "|---|---|---|---|---|---|---|---|"]
    for hz, entry in result["rates"].items():
        for mode, m in entry["modes"].items():
            lat = m["latency"]
            lines.append(f"| {hz} Hz | {mode} | {pct(m['normal_episodes_flagged'])} | {pct(m['detection']['lock'])} "
                         f"| {pct(m['detection']['falling_object'])} "
                         f"| {ms(lat['lock']['median_ms'])} / {ms(lat['lock']['p95_ms'])} "
                         f"| {ms(lat['falling_object']['median_ms'])} / {ms(lat['falling_object']['p95_ms'])} "
                         f"| {pct(m['isolation_at_detection'])} |")
    return "\n".join(lines) + "\n"


def write(result: dict, out_dir: Path) -> None:
    (out_dir / "fault_sweep.json").write_text(json.dumps(result, indent=2))
    (out_dir / "fault_sweep.md").write_text(markdown(result))
