"""The served monitor on the joint locks and the falling object, at its own observation rate.

What a session of the service decides, measured: each episode's energies held to the
checkpoint's episode threshold at the default false-positive rate by the service's own rule
(`models.fault.flag_steps`); the share of held-out normal episodes it flags; the locks and hits it
flags at or after their onset; how long after the onset the first flag comes, and how long after
the first tick at which the fault is visible; which joint it isolates there
(`models.fault.isolated_joint`, what the served decision names).

An episode's onset is the first 40 Hz tick at which its observations differ from its twin's (the
same seed without the fault or the hit; before it the two are identical bit for bit), so latency
is counted from the first moment anything could have seen it, at either rate: a 2 Hz monitor's
step k is at k / 2 s. Some faults change the observations by less than their normal spread for
a while (a lock's slow overshoot): their visible onset is the first 40 Hz tick at which some
channel departs from the twin by more than `experiments.twins.VISIBLE_K` normal standard
deviations (per skill, tick and channel over the held-out precision episodes, the rule of the
other benchmarks' oracles), and the latency is also counted from there (`from_visible`). How many
faults stay within the served monitor's own one-step spread in every channel for the first
`QUIET_S` after their onset (`quiet_100ms`) bounds the latency's percentiles from below.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from neural_asm.experiments.twins import first_visible_steps, onset_steps, whitened_deviation
from neural_asm.models.asm import NeuralASM
from neural_asm.models.config import SCORING
from neural_asm.models.calibration import conformal_episode_threshold
from neural_asm.models.fault import flag_steps, is_fault, isolated_joint, threshold_for
from neural_asm.models.scoring import step_rows
from neural_asm.models.sequences import Sequences

THRESHOLD = "episode"  # the service's default threshold kind
RESPLITS = 1000
QUIET_S = 0.1  # the latency target: how long after its onset a fault counts as quiet


@dataclass(frozen=True)
class Onsets:
    """Episodes of one kind (locks or hits) at 40 Hz, what each one was (the locked joint, the
    hit's momentum), their onset times and when each becomes visible."""

    episodes: Sequences  # at 40 Hz
    label: np.ndarray  # (N,) the locked joint (1..7) or the momentum (kg m/s)
    onset_s: np.ndarray  # (N,) first tick differing from the twin, in seconds
    visible_s: np.ndarray  # (N,) first tick departing from the twin by > VISIBLE_K normal sd, in seconds (nan: never)
    departure: np.ndarray  # (N, T, D) |episode - twin| at 40 Hz, in the channels' units

    @classmethod
    def against(cls, episodes: Sequences, label: np.ndarray, twins: Sequences, normal: Sequences) -> "Onsets":
        """Pair `episodes` with `twins` by seed (an episode whose twin the simulator refused is left
        out); `normal`, held-out normal episodes at the same rate, say what departure is visible."""
        index = {int(s): i for i, s in enumerate(twins.seeds)}
        keep = np.array([int(s) in index for s in episodes.seeds])
        episodes = episodes.take(keep)
        paired = twins.data[[index[int(s)] for s in episodes.seeds]]
        deviation = whitened_deviation(episodes.data, paired, episodes.labels, normal.data, normal.labels)
        visible = first_visible_steps(deviation)
        return cls(episodes, np.asarray(label)[keep], onset_steps(episodes.data, paired) / episodes.rate_hz,
                   np.where(visible >= 0, visible / episodes.rate_hz, np.nan), np.abs(episodes.data - paired))


def subsampled(seqs: Sequences, rate_hz: float) -> Sequences:
    """`seqs` observed at a lower `rate_hz`: every k-th observation (a 40 Hz episode's every 20th
    is its 2 Hz twin's, bit for bit)."""
    stride = round(seqs.rate_hz / rate_hz)
    if stride < 1 or not np.isclose(seqs.rate_hz / stride, rate_hz):
        raise ValueError(f"{rate_hz:g} Hz is not {seqs.rate_hz:g} Hz divided by a whole number")
    return Sequences(seqs.data[:, ::stride], seqs.labels, seqs.channel_names, seqs.seeds, seqs.provenance, rate_hz)


def percentiles_ms(seconds: np.ndarray) -> dict[str, float | None]:
    if not len(seconds):
        return {"median_ms": None, "p95_ms": None}
    return {"median_ms": round(float(np.median(seconds)) * 1e3, 1),
            "p95_ms": round(float(np.quantile(seconds, 0.95)) * 1e3, 1)}


def each_ms(seconds: np.ndarray) -> list[float | None]:
    """Every episode's latency in ms, None where it was not flagged (JSON has no NaN)."""
    return [None if np.isnan(v) else round(float(v) * 1e3, 1) for v in seconds]


@dataclass(frozen=True)
class Flagged:
    """The served decisions on one set: the first flag at or after each onset."""

    detected: np.ndarray  # (N,) bool
    first: np.ndarray  # (N,) step of the first flag at or after the onset (-1: none)
    latency_s: np.ndarray  # (N,) first flag's time - onset (nan: not detected)
    weighted_errors: np.ndarray  # (N, T, D) what isolation ranks


def flagged(model: NeuralASM, mode: str, data: np.ndarray, onset_s: np.ndarray, fpr: float) -> Flagged:
    """Score whole episodes as sessions would, and find each one's first flag from its onset on."""
    calibration = model.calibration(mode, 1)
    score = model.score(data, mode, 1)
    flags, _ = flag_steps(score.energy, calibration, fpr, THRESHOLD)
    times = np.arange(data.shape[1]) / model.rate_hz
    after = flags & (times[None] >= onset_s[:, None] - 1e-9)
    detected = after.any(axis=1)
    first = np.where(detected, after.argmax(axis=1), -1)
    latency = np.where(detected, times[first] - onset_s, np.nan)
    weighted = calibration.weigh(score.errors)
    return Flagged(detected, first, latency, weighted)


def from_visible(result: Flagged, onsets: Onsets, rate_hz: float) -> dict[str, float | int | None]:
    """Latency from each fault's visible onset to its first flag (at or after the onset), over the
    detected faults that become visible: what a monitor can be held to. Negative where the monitor
    flagged a departure still within the normal spread (counted in `flagged_before_visible`);
    faults that never become visible are counted in `never_visible` and left out."""
    visible = ~np.isnan(onsets.visible_s)
    counted = result.detected & visible
    seconds = result.first[counted] / rate_hz - onsets.visible_s[counted]
    return {**percentiles_ms(seconds), "flagged_before_visible": int((seconds < 0).sum()),
            "never_visible": int((~visible).sum())}


def quiet(model: NeuralASM, mode: str, onsets: Onsets, window_s: float = QUIET_S) -> int:
    """How many faults change no channel by more than the served one-step spread (the calibration's,
    in normalised units) at any of the model's observations in the `window_s` after their onset.
    A monitor that weighs one-step errors by those spreads sees them there within its normal
    noise: they bound the latency's percentiles from below."""
    stride = round(onsets.episodes.rate_hz / model.rate_hz)
    departure = onsets.departure[:, ::stride] / model.normaliser.std
    spread = step_rows(model.calibration(mode, 1).error_std, departure.shape[1])
    times = np.arange(departure.shape[1]) / model.rate_hz
    window = (times[None] >= onsets.onset_s[:, None] - 1e-9) & (times[None] <= onsets.onset_s[:, None] + window_s + 1e-9)
    above = (departure > spread[None]).any(axis=2)
    return int((~(above & window).any(axis=1)).sum())


def latency_ms(result: Flagged, onsets: Onsets, rate_hz: float, quiet_100ms: int) -> dict:
    """Percentiles of the latency from the onset, with those from the visible onset beside them and
    the count of faults quiet for `QUIET_S` (`quiet`)."""
    return {**percentiles_ms(result.latency_s[result.detected]), "from_visible": from_visible(result, onsets, rate_hz),
            "quiet_100ms": quiet_100ms}


def flagged_over_resplits(calibration_peaks: np.ndarray, test_peaks: np.ndarray, fpr: float,
                          resplits: int = RESPLITS, seed: int = 0) -> float:
    """The share of normal episodes the served rule flags on average over random re-splits of the
    calibration and test episodes into sets of the same sizes: one split's test share varies
    (at 150 and 150 episodes and 1 %, from 0 to ~3 %); this is what the rule flags in expectation."""
    peaks = np.concatenate([calibration_peaks, test_peaks])
    n = len(calibration_peaks)
    rng = np.random.default_rng(seed)
    shares = []
    for _ in range(resplits):
        order = rng.permutation(len(peaks))
        threshold = conformal_episode_threshold(peaks[order[:n]], fpr)
        shares.append(float(is_fault(peaks[order[n:]], threshold).mean()))
    return float(np.mean(shares))


def evaluate(model: NeuralASM, mode: str, normal_test: Sequences, locks: Onsets, hits: Onsets,
             normal_calibration: Sequences | None = None, fpr: float = SCORING.default_fpr) -> dict:
    """The served monitor's numbers for one recall mode; `locks` and `hits` at 40 Hz are
    subsampled to the model's rate. Given the calibration episodes the model's threshold came
    from, also the share of normal episodes flagged over re-splits of them and the test episodes."""
    def at_rate(s: Sequences) -> np.ndarray:
        return subsampled(s, model.rate_hz).data

    calibration = model.calibration(mode, 1)
    normal_energy = model.score(at_rate(normal_test), mode, 1).energy
    normal_flags, _ = flag_steps(normal_energy, calibration, fpr, THRESHOLD)
    resplit = None
    if normal_calibration is not None:
        calibration_peaks = model.score(at_rate(normal_calibration), mode, 1).energy.max(axis=1)
        resplit = flagged_over_resplits(calibration_peaks, normal_energy.max(axis=1), fpr)
    lock = flagged(model, mode, at_rate(locks.episodes), locks.onset_s, fpr)
    hit = flagged(model, mode, at_rate(hits.episodes), hits.onset_s, fpr)
    rows = np.flatnonzero(lock.detected)
    isolated = isolated_joint(lock.weighted_errors[rows, lock.first[rows]], model.channel_names) + 1
    return {
        "mode": mode,
        "rate_hz": model.rate_hz,
        "fpr": fpr,
        "threshold": threshold_for(calibration, fpr, 0, THRESHOLD),
        "normal_episodes_flagged": float(normal_flags.any(axis=1).mean()),
        "normal_episodes_flagged_resplits": resplit,
        "normal_episodes": len(normal_test),
        "detection": {
            "lock": float(lock.detected.mean()),
            "falling_object": float(hit.detected.mean()),
            "falling_object_by_momentum": {f"{m:g}": float(hit.detected[hits.label == m].mean())
                                           for m in np.unique(hits.label)},
        },
        "episodes": {"lock": len(lock.detected), "falling_object": len(hit.detected)},
        "latency": {"lock": latency_ms(lock, locks, model.rate_hz, quiet(model, mode, locks)),
                    "falling_object": latency_ms(hit, hits, model.rate_hz, quiet(model, mode, hits))},
        "latency_ms_each": {"lock": each_ms(lock.latency_s), "falling_object": each_ms(hit.latency_s)},
        "isolation_at_detection": float((isolated == locks.label[rows]).mean()) if len(rows) else 0.0,
    }
