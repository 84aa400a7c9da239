"""Reading a lab's tables: throughput and peak memory on a parquet of >= 1 GB of voraus-AD's width.

The benchmark writes one parquet in a temporary folder with voraus-AD's 138 columns (``time``,
``sample``, ``anomaly``, ``category``, ... and 22 float columns per joint, 6 joints; samples of
1,000 rows at 100 Hz, row groups of 50,000 rows), then reads it in fresh processes: through
``examples/voraus_ad.toml``'s mapping (26 channels, 100 steps of 10 ms per sample), and, as a
reference, with plain pyarrow (``iter_batches`` of the same columns, nothing else done). The file
is deleted afterwards. Throughput is the file's size over the read's wall time; peak memory the
reading process's maximum resident set.

Last line: one JSON object {tables_mb_per_s, tables_peak_rss_mb, tables_cpu_mb_per_s,
reference_mb_per_s, ratio_to_reference, ...}. Targets: >= 50 MB/s and <= 400 MB.
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
import pyarrow.parquet as pq

MAPPING = Path(__file__).resolve().parents[1] / "examples" / "voraus_ad.toml"
PER_JOINT = ("target_position", "target_velocity", "target_acceleration", "target_torque", "computed_inertia",
             "computed_torque", "motor_position", "motor_velocity", "joint_position", "joint_velocity", "motor_torque",
             "torque_sensor_a", "torque_sensor_b", "motor_iq", "motor_id", "power_motor_el", "power_motor_mech",
             "power_load_mech", "motor_voltage", "supply_voltage", "brake_voltage")
SAMPLE_ROWS, GROUP_ROWS = 1000, 50_000


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


def read_one(path: Path, how: str) -> None:
    """In its own process: read the file, print seconds, CPU seconds, episodes and the peak resident set."""
    t0, cpu0 = time.perf_counter(), time.process_time()
    if how == "mapping":
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
    parser.add_argument("--how", choices=("mapping", "pyarrow"), help=argparse.SUPPRESS)
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
    print(json.dumps({"tables_mb_per_s": round(size_mb / ours["seconds"], 1),
                      "tables_peak_rss_mb": round(ours["peak_rss_mb"], 1),
                      "tables_cpu_mb_per_s": round(size_mb / ours["cpu_seconds"], 1),
                      "reference_mb_per_s": round(size_mb / reference["seconds"], 1),
                      "reference_peak_rss_mb": round(reference["peak_rss_mb"], 1),
                      "ratio_to_reference": round(reference["seconds"] / ours["seconds"], 2),
                      "file_mb": round(size_mb, 1), "columns": 138, "episodes": ours["episodes"],
                      "write_seconds": round(written_s, 1), "load_average_1min": round(os.getloadavg()[0], 2)}))


if __name__ == "__main__":
    main()
