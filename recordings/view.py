"""A run's Rerun files found from its id, and opened in the Rerun viewer or drawn to a PNG.

A client run ``client-X`` leaves ``client-X.rrd`` and, from the service it streamed to,
``service-client-X-<session>.rrd`` (one per session, more after reconnects); opened together
they are one view. A screenshot needs a display: without one, the viewer runs under
``xvfb-run`` (Debian's ``xvfb``) with the Vulkan renderer, which works in software.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from recordings.paths import DEFAULT_DIR


class RunNotFound(FileNotFoundError):
    pass


def run_files(run: str | Path, folder: Path = DEFAULT_DIR) -> list[Path]:
    """The ``.rrd`` files of ``run``: a run id in ``folder``, or the path of one of its files."""
    path = Path(run)
    if path.suffix in (".rrd", ".mcap"):
        folder, run_id = path.parent, path.stem
    else:
        run_id = path.name
    if run_id.startswith("service-"):  # a service file: its client's id follows the prefix
        run_id = run_id.removeprefix("service-").rsplit("-", 1)[0]
    files = sorted({*folder.glob(f"{run_id}.rrd"), *folder.glob(f"service-{run_id}-*.rrd")})
    if not files:
        raise RunNotFound(f"no .rrd of run {run_id!r} in {folder}")
    return files


def viewer_command(files: list[Path], screenshot: Path | None = None) -> list[str]:
    """The command that opens ``files`` in the Rerun viewer, or writes their screenshot."""
    command = [sys.executable, "-m", "rerun", *map(str, files)]
    if screenshot is None:
        return command
    command[3:3] = ["--renderer", "vulkan", "--screenshot-to", str(screenshot)]
    if os.environ.get("DISPLAY"):
        return command
    if shutil.which("xvfb-run") is None:
        raise RuntimeError("a screenshot needs a display or xvfb-run (apt-get install xvfb mesa-vulkan-drivers)")
    return ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", *command]


def view(run: str | Path, folder: Path = DEFAULT_DIR, screenshot: Path | None = None) -> list[Path]:
    """Open the run in the viewer (returns when it is closed) or write its screenshot."""
    files = run_files(run, folder)
    if screenshot is None:
        subprocess.run(viewer_command(files), check=True)
        return files
    done = subprocess.run(viewer_command(files, screenshot), capture_output=True, text=True)  # its log only on failure
    if done.returncode != 0 or not screenshot.exists():
        raise RuntimeError(f"the viewer wrote no screenshot to {screenshot}:\n{done.stderr[-2000:]}")
    return files
