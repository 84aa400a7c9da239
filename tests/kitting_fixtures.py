"""Tables the tests make themselves: Baxter-kitting-shaped folders (segment CSVs, Python 2 label
pickles naming genpy times, whole runs) and a voraus-AD-shaped parquet. Synthetic numbers only."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

COLUMNS = ["robotiq_force_sensor.wrench.force.norm", "robotiq_force_sensor.wrench.torque.norm",
           "baxter_enpoint_pose.twist.linear.norm", "baxter_enpoint_pose.twist.angular.norm",
           "tactile_static_data.left.std", "tactile_static_data.right.std"]
START = 1_526_716_000.0
PERIOD = 0.05


def ros_time(secs_f: float, memo: int) -> str:
    """A genpy Time as Python 2's pickle protocol 0 writes it (copy_reg._reconstructor, state [secs, nsecs])."""
    secs, nsecs = int(secs_f), int(round((secs_f - int(secs_f)) * 1e9))
    return (f"ccopy_reg\n_reconstructor\np{memo}\n(cgenpy.rostime\nTime\np{memo + 1}\nc__builtin__\nobject\n"
            f"p{memo + 2}\nNtp{memo + 3}\nRp{memo + 4}\n(lp{memo + 5}\nI{secs}\naI{nsecs}\nab")


def label_pickle(label: str, t: float) -> bytes:
    return f"(S'{label}'\np0\n{ros_time(t, 1)}tp7\n.".encode()


def anomaly_list_pickle(items: list[tuple[str, float]]) -> bytes:
    body, memo = "(lp0\n", 1
    for label, t in items:
        body += f"(S'{label}'\np{memo}\n{ros_time(t, memo + 1)}tp{memo + 8}\na"
        memo += 9
    return (body + ".").encode()


def tag_ranges_pickle(phases: list[tuple[int, float, float]]) -> bytes:
    body, memo = "(lp0\n", 1
    for tag, a, b in phases:
        body += f"(I{tag}\n({ros_time(a, memo)}{ros_time(b, memo + 6)}tp{memo + 12}\ntp{memo + 13}\na"
        memo += 14
    return (body + ".").encode()


def skill_curve(skill: int, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 6) a skill's normal course: each skill its own force and speed profile."""
    s = np.linspace(0, 1, n)[:, None]
    base = np.array([2.0 + skill, 0.2, 0.02, 0.03, 20.0 + 2 * skill, 15.0])
    shape = np.sin(np.pi * s * (1 + skill % 3)) * np.array([1.0, 0.1, 0.05, 0.05, 2.0, 1.0])
    return base + shape + 0.02 * rng.standard_normal((n, 6)) * base


def write_csv(path: Path, t: np.ndarray, values: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["," + ",".join(COLUMNS)] + [f"{ti:.2f}," + ",".join(f"{v:.6f}" for v in row) for ti, row in zip(t, values)]
    path.write_text("\n".join(lines) + "\n")


def stamp(i: int) -> str:
    return f"2018y05m{19 + i // 40:02d}d{10 + (i // 4) % 10:02d}H{i % 60:02d}M03S"


def write_kitting(root: Path, runs: int = 12, skills: tuple[int, ...] = (3, 4, 5), seed: int = 0,
                  anomalous_every: int = 3) -> Path:
    """A Baxter-shaped folder: each run one normal segment per skill (every ``anomalous_every``-th
    run's last skill anomalous instead: a force step at its onset) and the whole run."""
    rng = np.random.default_rng(seed)
    for i in range(runs):
        run = f"experiment_at_{stamp(i)}"
        t0 = START + 1000 * i
        whole_t, whole_v, phases, anomalies = [], [], [], []
        for k, skill in enumerate(skills):
            n = int(rng.integers(60, 90))
            t = t0 + PERIOD * np.arange(n)
            v = skill_curve(skill, n, rng)
            anomalous = i % anomalous_every == 0 and k == len(skills) - 1
            if anomalous:
                onset = int(n * 0.5)
                v[onset:, 0] += 6.0
                v[onset:, 4] -= 8.0
                name = f"No.0 unsuccessful skill from {run}"
                folder = root / "unsuccessful_skills" / f"skill {skill}" / name
                (folder).mkdir(parents=True, exist_ok=True)
                (folder / "anomaly_label_and_signal_time.pkl").write_bytes(label_pickle("no_object", float(t[onset])))
                anomalies.append(("no_object", float(t[onset])))
            else:
                name = f"No.0 successful skill from {run}"
                folder = root / "successful_skills" / f"skill {skill}" / name
            write_csv(folder / f"{name}.csv", t, v)
            phases.append((skill, float(t[0]), float(t[-1])))
            whole_t.append(t)
            whole_v.append(v)
            t0 = float(t[-1]) + PERIOD
        whole = root / "whole_experiment" / run
        write_csv(whole / f"{run}.csv", np.concatenate(whole_t), np.concatenate(whole_v))
        (whole / "tag_ranges.pkl").write_bytes(tag_ranges_pickle(phases + [(-1, t0, t0 + 1)]))
        (whole / "anomaly_signals.pkl").write_bytes(anomaly_list_pickle(anomalies) if anomalies else b"")
    return root


VORAUS_JOINT_COLUMNS = ("joint_position", "joint_velocity", "motor_torque", "motor_iq")


def write_voraus(path: Path, samples: int = 12, steps: int = 110, seed: int = 0, row_group: int = 500) -> Path:
    """A voraus-AD-shaped parquet: ``time``, ``sample``, ``anomaly``, ``category`` (12: normal),
    the mapped per-joint columns and the robot's voltage and current; every fourth sample an anomaly."""
    rng = np.random.default_rng(seed)
    cols: dict[str, list[np.ndarray]] = {}
    for k in range(samples):
        anomalous = k % 4 == 3
        s = np.linspace(0, 1, steps)
        row = {"time": np.arange(steps) * 0.01, "sample": np.full(steps, k), "anomaly": np.full(steps, anomalous),
               "category": np.full(steps, (k % 3) if anomalous else 12), "setting": np.full(steps, 1),
               "action": (s > 0.5).astype(np.int64), "active": np.ones(steps, np.int64),
               "robot_voltage": 48 + 0.1 * rng.standard_normal(steps), "robot_current": 2 + 0.1 * rng.standard_normal(steps)}
        for j in range(1, 7):
            for c, name in enumerate(VORAUS_JOINT_COLUMNS):
                value = np.sin(2 * np.pi * s + j + c) + 0.01 * rng.standard_normal(steps)
                if anomalous and name == "motor_torque":
                    value = value + 2.0 * (s > 0.4)
                row[f"{name}_{j}"] = value
        for name, value in row.items():
            cols.setdefault(name, []).append(value)
    table = pa.table({name: np.concatenate(parts) for name, parts in cols.items()})
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path, row_group_size=row_group)
    return path


SKILL_NAMES = ("3", "4", "5")
SKILL_CHANNELS = tuple(f"c{i}" for i in range(6))


def skill_runs(n: int, seed: int, skills: tuple[str, ...] = SKILL_NAMES, steps: int = 40
               ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` normal runs (steps, 6) of each skill, and each run's skill."""
    rng = np.random.default_rng(seed)
    return np.stack([skill_curve(int(s), steps, rng) for s in skills for _ in range(n)]), np.repeat(skills, n)


def told_memory():
    """A public SkillMemory told its skills by a cue, on 10 runs a skill, calibrated on 10 more."""
    from neural_asm import SkillMemory
    from neural_asm.models.config import FAST

    x, y = skill_runs(10, 0)
    memory = SkillMemory.fit(x, SKILL_CHANNELS, y, preset=FAST.with_(hidden_size=32, epochs=40), progress=False,
                             skill_cue=True)
    precision, skills = skill_runs(10, 1)
    memory.calibrate(precision, skills=skills)
    return memory


def served_models(folder: Path, memory) -> Path:
    """``folder`` holding the skill memory (``kitting``) beside a network trained without skills (``plain``)."""
    from neural_asm import SkillMemory
    from neural_asm.models.config import FAST

    memory.save(folder / "kitting.safetensors")
    plain = SkillMemory.fit(skill_runs(2, 2)[0], SKILL_CHANNELS, preset=FAST.with_(hidden_size=8, epochs=2),
                            progress=False)
    plain.calibrate(skill_runs(2, 3)[0])
    plain.save(folder / "plain.safetensors")
    return folder
