"""Reading a lab's tables: throughput and peak memory on a parquet of >= 1 GB of voraus-AD's width,
and on >= 1 GB of per-sensor trial folders.

The benchmark writes one parquet in a temporary folder with voraus-AD's 138 columns (``time``,
``sample``, ``anomaly``, ``category``, ... and 22 float columns per joint, 6 joints; samples of
1,000 rows at 100 Hz, row groups of 50,000 rows), then reads it in fresh processes: through
``examples/voraus_ad.toml``'s mapping (26 channels, 100 steps of 10 ms per sample), and, as a
reference, with plain pyarrow (``iter_batches`` of the same columns, nothing else done). The file
is deleted afterwards. Throughput is the file's size over the read's wall time; peak memory the
reading process's maximum resident set.

Then it writes trial folders until they hold as much: each a minute of a robot's three sensors,
one CSV each at its own rate and on its own clock (wrench.csv, 6 forces and torques at 1 kHz,
time in ms; joints.csv, 7 joint angles at 500 Hz, time in s; pose.csv, 3 coordinates at 100 Hz,
ISO-8601 time), and reads them in a fresh process through a mapping of ``[[table.parts]]``
(16 channels, 2,500 steps of 20 ms per trial), then deletes them.

Last line: one JSON object {tables_mb_per_s, tables_peak_rss_mb, tables_cpu_mb_per_s,
reference_mb_per_s, ratio_to_reference, parts_mb_per_s, parts_peak_rss_mb, parts_cpu_mb_per_s,
...}. Targets: >= 50 MB/s and <= 400 MB for both.
Run: python benchmarks/bench_tables.py (``--gb`` sets the file's size; ``--quick`` writes one row
group of 5,000 rows, read in seconds: the test suite runs it so the script keeps working, its
numbers mean nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

MAPPING = Path(__file__).resolve().parents[1] / "examples" / "voraus_ad.toml"
PER_JOINT = ("target_position", "target_velocity", "target_acceleration", "target_torque", "computed_inertia",
             "computed_torque", "motor_position", "motor_velocity", "joint_position", "joint_velocity", "motor_torque",
             "torque_sensor_a", "torque_sensor_b", "motor_iq", "motor_id", "power_motor_el", "power_motor_mech",
             "power_load_mech", "motor_voltage", "supply_voltage", "brake_voltage")
SAMPLE_ROWS, GROUP_ROWS = 1000, 50_000
# a trial's parts: file, rate (Hz), its time column and unit, its columns
PARTS = (("wrench.csv", 1000, "t_ms", "ms", ("fx", "fy", "fz", "tx", "ty", "tz")),
         ("joints.csv", 500, "t", "s", tuple(f"q{j}" for j in range(1, 8))),
         ("pose.csv", 100, "stamp", "iso", ("x", "y", "z")))
TRIAL_S, PERIOD_S, STEPS = 60.0, 0.02, 2500
T0 = 1_700_000_000.0


def write_parquet(path: Path, gb: float, group_rows: int = GROUP_ROWS) -> None:
    """Row groups of random numbers until the file holds ``gb`` GB."""
    rng = np.random.default_rng(0)
    names = ["robot_voltage", "robot_current", "io_current", "system_current"] + [
        f"{c}_{j}" for j in range(1, 7) for c in PER_JOINT]
    schema = pa.schema([("index", pa.int64()), ("time", pa.float64()), ("sample", pa.int64()), ("anomaly", pa.bool_()),
                        ("category", pa.int64()), ("setting", pa.int64()), ("action", pa.int64()), ("active", pa.int64())]
                       + [(n, pa.float64()) for n in names])
    row = 0
    with pq.ParquetWriter(path, schema, compression="snappy") as writer:
        while not path.exists() or path.stat().st_size < gb * 1e9:
            i = row + np.arange(group_rows)
            sample = i // SAMPLE_ROWS
            cols = [i, (i % SAMPLE_ROWS) * 0.01, sample, sample % 10 == 9, np.where(sample % 10 == 9, sample % 12, 12),
                    np.ones(group_rows, np.int64), (i % SAMPLE_ROWS > 500).astype(np.int64), np.ones(group_rows, np.int64)]
            cols += list(rng.standard_normal((len(names), group_rows)))
            writer.write_table(pa.Table.from_arrays([pa.array(c) for c in cols], schema=schema))
            row += group_rows


def write_trials(root: Path, gb: float) -> float:
    """Trial folders of three parts (``PARTS``) until they hold ``gb`` GB; their size in MB. Each
    part starts up to 50 ms after the trial's start, on its own clock."""
    rng = np.random.default_rng(0)
    size, k = 0, 0
    while size < gb * 1e9:
        folder = root / f"trial_{k:04d}"
        folder.mkdir(parents=True)
        for name, hz, time_column, unit, columns in PARTS:
            t = T0 + 100.0 * k + rng.uniform(0, 0.05) + np.arange(int(TRIAL_S * hz)) / hz
            stamps = {"ms": pa.array(t * 1e3), "s": pa.array(t),
                      "iso": pa.array(np.datetime_as_string((t * 1e6).astype("datetime64[us]"), timezone="UTC"))}
            table = pa.table({time_column: stamps[unit], **{c: rng.standard_normal(len(t)) for c in columns}})
            pacsv.write_csv(table, folder / name)
            size += (folder / name).stat().st_size
        k += 1
    return size / 1e6


def parts_mapping() -> dict:
    parts = [{"files": name, "time_column": time_column, "time_unit": unit, "columns": list(columns)}
             for name, _, time_column, unit, columns in PARTS]
    channels = [{"name": c, "units": "1", "column": c} for *_, columns in PARTS for c in columns]
    return {"timing": {"period_s": PERIOD_S, "steps": STEPS}, "table": {"parts": parts, "skill": {"value": "trial"}},
            "channels": channels}


def read_one(path: Path, how: str) -> None:
    """In its own process: read the file, print seconds, CPU seconds, episodes and the peak resident set."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    if how == "parts":
        from neural_asm.logs.mapping import parse_mapping
        from neural_asm.logs.sources import read_mapped

        episodes = len(read_mapped(path, parse_mapping(parts_mapping(), "the trials' mapping")).data)
    elif how == "mapping":
        from neural_asm.logs.sources import load_log_sequences

        episodes = len(load_log_sequences(path, MAPPING).data)
    else:
        from neural_asm.logs.mapping import load_mapping

        m = load_mapping(MAPPING)
        columns = ["time", "sample", "category"] + [c.column for c in m.channels]
        episodes = 0
        for batch in pq.ParquetFile(path).iter_batches(batch_size=65_536, columns=columns):
            episodes += len(np.unique(batch.column("sample").to_numpy()))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "cpu_seconds": cpu, "episodes": episodes, "peak_rss_mb": peak_mb}))


def _measure(path: Path, how: str) -> dict:
    out = subprocess.run([sys.executable, __file__, "--read", str(path), "--how", how], check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gb", type=float, default=1.0, help="size of the parquet file (GB)")
    parser.add_argument("--quick", action="store_true",
                        help="one row group of 5,000 rows (seconds, not minutes): checks the script runs, measures "
                        "nothing")
    parser.add_argument("--read", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--how", choices=("mapping", "pyarrow", "parts"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.read:
        read_one(args.read, args.how)
        return
    with tempfile.TemporaryDirectory(prefix="bench_tables_") as tmp:
        path = Path(tmp) / "voraus_like.parquet"
        t0 = time.perf_counter()
        write_parquet(path, 0.001, 5000) if args.quick else write_parquet(path, args.gb)
        written_s = time.perf_counter() - t0
        size_mb = path.stat().st_size / 1e6
        ours, reference = _measure(path, "mapping"), _measure(path, "pyarrow")
    with tempfile.TemporaryDirectory(prefix="bench_parts_") as tmp:
        t0 = time.perf_counter()
        parts_mb = write_trials(Path(tmp), 0.001 if args.quick else args.gb)  # quick: one trial
        parts_written_s = time.perf_counter() - t0
        parts = _measure(Path(tmp), "parts")
    print(json.dumps({"tables_mb_per_s": round(size_mb / ours["seconds"], 1),
                      "tables_peak_rss_mb": round(ours["peak_rss_mb"], 1),
                      "tables_cpu_mb_per_s": round(size_mb / ours["cpu_seconds"], 1),
                      "reference_mb_per_s": round(size_mb / reference["seconds"], 1),
                      "reference_peak_rss_mb": round(reference["peak_rss_mb"], 1),
                      "ratio_to_reference": round(reference["seconds"] / ours["seconds"], 2),
                      "file_mb": round(size_mb, 1), "columns": 138, "episodes": ours["episodes"],
                      "write_seconds": round(written_s, 1),
                      "parts_mb_per_s": round(parts_mb / parts["seconds"], 1),
                      "parts_peak_rss_mb": round(parts["peak_rss_mb"], 1),
                      "parts_cpu_mb_per_s": round(parts_mb / parts["cpu_seconds"], 1),
                      "parts_mb": round(parts_mb, 1), "parts_episodes": parts["episodes"],
                      "parts_write_seconds": round(parts_written_s, 1),
                      "load_average_1min": round(os.getloadavg()[0], 2)}))


if __name__ == "__main__":
    main()
