"""The either-of-two rival (experiments/varied/pairs.py) on constructed energies: OR semantics at
the served threshold, and a pair chosen on the validation faults alone."""

from __future__ import annotations

import numpy as np
import pytest

from neural_asm.experiments.methods import Method
from neural_asm.experiments.varied.data import FaultSet, VariedBenchmark
from neural_asm.experiments.varied.pairs import best_pair, choose, combined, scale
from neural_asm.experiments.varied.outcomes import VALIDATION, after_onset, outcomes
from neural_asm.models.calibration import Thresholds
from neural_asm.models.sequences import Sequences

T, ONSET, SPIKE = 12, 4, 6.0  # steps, every fault's onset, a fault's peak in units of its detector's scale
SIZES = {"precision": 150, "calibration": 300, "test": 100, "ood": 40, "faults": 20, VALIDATION: 20}


def _normal(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.chisquare(3, (n, T))


def _energies(rng: np.random.Generator, caught: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Normal-like energies on every set; the faults in ``caught`` (set -> (F,) bool) spike at
    SPIKE times the detector's scale two steps after their onset."""
    e = {key: _normal(rng, n) for key, n in SIZES.items()}
    s = scale(e)
    for key, rows in caught.items():
        e[key][rows, ONSET + 2] = SPIKE * s
    return e


def _halves(first: bool) -> np.ndarray:
    rows = np.arange(20) < 10
    return rows if first else ~rows


def _fault_set(n: int) -> FaultSet:
    return FaultSet(_sequences(n), _sequences(n), np.array(["lock"] * n), np.full(n, ONSET), np.full(n, ONSET),
                    np.ones(n, bool), np.array(["deviating"] * n))


def _sequences(n: int) -> Sequences:
    return Sequences(np.zeros((n, T, 1)), np.array(["push"] * n), ("x",))


def _bench(validation: FaultSet) -> VariedBenchmark:
    return VariedBenchmark(**vars(_fault_set(SIZES["faults"])), context="observed", channel_names=("x",),
                           context_channels=np.array([], int), demos=_sequences(4),
                           precision=_sequences(SIZES["precision"]), calibration=_sequences(SIZES["calibration"]),
                           test=_sequences(SIZES["test"]), ood=_sequences(SIZES["ood"]),
                           test_success=np.ones(SIZES["test"], bool), ood_success=np.ones(SIZES["ood"], bool),
                           dropped={}, validation=validation)


@pytest.fixture
def rivals() -> dict[str, dict[str, np.ndarray]]:
    """A and B each catch half the validation faults, C none; on the test faults B and C each
    catch half and A none: A or B is the pair on validation, B or C would be on the test faults."""
    rng = np.random.default_rng(0)
    return {"a": _energies(rng, {VALIDATION: _halves(True)}),
            "b": _energies(rng, {VALIDATION: _halves(False), "faults": _halves(True)}),
            "c": _energies(rng, {"faults": _halves(False)})}


def test_the_combined_energies_flag_exactly_above_the_served_threshold(rivals):
    rivals["a"]["test"][:3, 5] = 50.0 * scale(rivals["a"])  # three normal test episodes far beyond a's scale
    c = combined(rivals["a"], rivals["b"])
    o = outcomes(c, np.full(SIZES["faults"], ONSET))["episode"]
    thr = Thresholds.of(c["calibration"], 0.01).episode
    np.testing.assert_array_equal(o.normal_flagged, c["test"].max(axis=1) > thr)
    np.testing.assert_array_equal(o.detected, (after_onset(c["faults"], np.full(SIZES["faults"], ONSET)) > thr).any(1))
    assert o.normal_flagged[:3].all() and not o.normal_flagged.all()  # the comparison decided something
    # OR semantics at any level t: the pair is above t exactly where A is above t s_A or B above t s_B
    sa, sb = scale(rivals["a"]), scale(rivals["b"])
    for t in (0.5, 1.0, thr):
        np.testing.assert_array_equal(c["test"] > t, (rivals["a"]["test"] > t * sa) | (rivals["b"]["test"] > t * sb))


def test_the_pair_flags_every_validation_fault_either_member_flags(rivals):
    validation = _fault_set(SIZES[VALIDATION])
    alone = {name: outcomes({**rivals[name], "faults": rivals[name][VALIDATION]}, validation.onset)["episode"].detected
             for name in ("a", "b")}
    assert alone["a"].sum() == alone["b"].sum() == 10 and not (alone["a"] & alone["b"]).any()  # complementary
    c = combined(rivals["a"], rivals["b"])
    pair = outcomes({**c, "faults": c[VALIDATION]}, validation.onset)["episode"].detected
    np.testing.assert_array_equal(pair, alone["a"] | alone["b"])
    assert pair.all()


def test_the_pair_is_chosen_on_validation_faults_only(rivals):
    validation = _fault_set(SIZES[VALIDATION])
    chosen, record = choose(rivals, validation)
    assert chosen == ("a", "b") and record["chosen"] == ["a", "b"]
    assert record["validation_detection"] == {"a | b": 1.0, "a | c": 0.5, "b | c": 0.5}
    assert record["validation_visible"] == 20 and set(record["scales"]) == {"a", "b"}
    assert record["validation_detection_alone"] == {"a": 0.5, "b": 0.5, "c": 0.0}
    assert record["tied_on_detection"] == ["a | b"]
    # chosen on the test faults, the pair would be b or c
    on_test = {name: {**e, VALIDATION: e["faults"]} for name, e in rivals.items()}
    assert choose(on_test, _fault_set(SIZES["faults"]))[0] == ("b", "c")
    # the test faults' energies do not move the choice
    rng = np.random.default_rng(1)
    shuffled = {name: {**e, "faults": rng.permutation(e["faults"]) * 3.0} for name, e in rivals.items()}
    assert choose(shuffled, validation) == (chosen, record)
    # scored as a rival on the test faults, where it catches only b's half
    entry, rules = best_pair(rivals, {n: Method(n, n.upper(), False, lambda x, _: x) for n in rivals},
                             _bench(validation))
    assert entry["or_pair"] == record and entry["or_pair"]["chosen"] == list(chosen)
    assert not entry["is_neural_asm"] and entry["held_out_mse"] is None
    assert entry["episode"]["detection"] == 0.5 and rules["episode"].detected[:10].all()


def test_ties_go_to_the_higher_auroc_then_to_the_order():
    """a catches every validation fault with either partner; c's two loud calibration episodes
    (below the served rank, so the threshold stays) rank above some faults: a or b is kept though
    a or c comes first."""
    rng = np.random.default_rng(2)
    a = _energies(rng, {VALIDATION: np.ones(20, bool)})
    b, c = _energies(rng, {}), _energies(rng, {})
    c["calibration"][:2, 3] = 3 * SPIKE * scale(c)
    validation = _fault_set(SIZES[VALIDATION])
    chosen, record = choose({"a": a, "c": c, "b": b}, validation)
    assert record["validation_detection"]["a | c"] == record["validation_detection"]["a | b"] == 1.0
    assert record["validation_auroc"]["a | c"] < record["validation_auroc"]["a | b"] == 1.0
    assert chosen == ("a", "b") and record["tied_on_detection"] == ["a | c", "a | b"]
    assert choose({"a": a, "b": b, "c": b}, validation)[0] == ("a", "b")  # a full tie: the first pair
