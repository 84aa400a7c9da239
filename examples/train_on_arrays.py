"""Train a skill memory on your own arrays, calibrate it, and find the fault in a faulty one.

    python examples/train_on_arrays.py

Two skills of three channels (two joints and a gripper), 20 steps each, made up here with
numpy: use your own (N, T, D) arrays instead. A joint that stops moving half-way is flagged
at the step where it departs from what the memory expects, and the joint is named.
"""

import numpy as np

import neural_asm as nasm

CHANNELS = ("joint1", "joint2", "gripper")
STEPS = 20


def repetitions(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` noisy repetitions of each of two skills: (2n, STEPS, 3) and each one's skill."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, STEPS)[None, :, None]
    shapes = {"reach": (np.array([0.8, -0.5, 0.0]), np.array([0.6, 0.9, 1.0])),
              "place": (np.array([-0.4, 0.7, 1.0]), np.array([0.9, -0.6, -1.0]))}
    data, skills = [], []
    for skill, (start, travel) in shapes.items():
        gain = 1 + 0.03 * rng.standard_normal((n, 1, 3))
        data.append(start + travel * gain * np.sin(np.pi / 2 * t) + 0.01 * rng.standard_normal((n, STEPS, 3)))
        skills += [skill] * n
    return np.concatenate(data), np.array(skills)


def main() -> None:
    demos, skills = repetitions(20, seed=0)
    memory = nasm.SkillMemory.fit(demos, CHANNELS, skills, progress=False)
    normal, _ = repetitions(20, seed=1)  # normal runs the memory was not trained on
    memory.calibrate(normal)

    faulty = repetitions(1, seed=2)[0][0].copy()
    faulty[10:, 1] = faulty[10, 1]  # joint2 stops at step 10
    monitor = memory.monitor(fpr=0.01)
    verdicts = [monitor.step(x) for x in faulty]
    flagged = [v for v in verdicts if v.fault]
    if not flagged:
        raise SystemExit("the stopped joint was not flagged")
    first = flagged[0]
    print(f"faulty run: flagged at step {first.step} (the joint stopped at step 10), isolated joint "
          f"{first.isolated_joint}, energy {first.energy:.1f} against threshold {first.threshold:.1f}")

    clean = memory.monitor(fpr=0.01)
    print(f"normal run: {sum(clean.step(x).fault for x in normal[1])} of {STEPS} steps flagged")


if __name__ == "__main__":
    main()
