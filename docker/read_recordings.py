"""Read every recording under a folder with the standard readers; exit 1 naming any that fails.

    python read_recordings.py FOLDER [--expect N] [--recovered N]

Each ``.mcap`` is read with the mcap library (``recordings.readers.read_mcap``: every message,
protobuf ones decoded) and must hold messages; each ``.rrd`` must pass ``rerun rrd verify`` and
yield chunks to ``rerun.chunk.RrdReader``. No writer may still have files open (an
``.recording.json`` marker). ``--expect``: at least N files; ``--recovered``: at least N episodes
recovered after a crash (``.interrupted.json`` markers).
"""

import argparse
import subprocess
import sys
from pathlib import Path

from rerun.chunk import RrdReader

from neural_asm.recordings.readers import read_mcap


def problems(path: Path) -> str | None:
    if path.suffix == ".mcap":
        messages = sum(len(v) for v in read_mcap(path).values())
        return None if messages else "no messages"
    verify = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)], capture_output=True, text=True)
    if verify.returncode != 0:
        return f"rerun rrd verify: {(verify.stderr or verify.stdout).strip()[-300:]}"
    return None if any(True for _ in RrdReader(path).stream()) else "no chunks"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--expect", type=int, default=1)
    parser.add_argument("--recovered", type=int, default=0)
    args = parser.parse_args()
    files = sorted(p for p in args.folder.rglob("*") if p.suffix in (".mcap", ".rrd"))
    failed = 0
    for path in files:
        why = problems(path)
        print(f"{'ok  ' if why is None else 'FAIL'} {path.relative_to(args.folder)}" + (f": {why}" if why else ""))
        failed += why is not None
    still_open = sorted(args.folder.rglob("*.recording.json"))
    recovered = sorted(args.folder.rglob("*.interrupted.json"))
    print(f"{len(files)} recordings, {failed} unreadable, {len(still_open)} still open, {len(recovered)} recovered after a crash")
    errors = [f"{failed} unreadable"] * bool(failed) + [f"still open: {[str(p) for p in still_open]}"] * bool(still_open)
    if len(files) < args.expect:
        errors.append(f"expected at least {args.expect} recordings, found {len(files)}")
    if len(recovered) < args.recovered:
        errors.append(f"expected at least {args.recovered} recovered episodes, found {len(recovered)}")
    for e in errors:
        print(f"read_recordings: {e}", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
