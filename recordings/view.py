"""A run's Rerun files found from its id, and opened in the Rerun viewer or drawn to a PNG.

A client run ``client-X`` leaves ``client-X.rrd`` and, from the service it streamed to,
``service-client-X-<session>.rrd`` (one per session, more after reconnects); opened together
they are one view. A screenshot needs a display: without one, the viewer runs under
``xvfb-run`` (Debian's ``xvfb``) with the Vulkan renderer, which works in software.

The layout: the viewer makes the blueprint it receives last the active one, so a ``.rbl``
file given after the recordings overrides the one the client's file embeds. That is how a
user's own layout is used (``blueprint``), and how a screenshot shows the episode's end
(``episode_end_blueprint``: the time cursor follows the data) rather than its first second.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from neural_asm.recordings import blueprint as bp
from neural_asm.recordings.paths import APP_ID, DEFAULT_DIR

SCREENSHOT_SIZE = "1600x1000"  # logical points; the PNG may have more pixels (the display's scale)


class RunNotFound(FileNotFoundError):
    pass


def latest_run(folder: Path = DEFAULT_DIR) -> str:
    """The id of the newest client run in ``folder``."""
    runs = sorted(folder.glob("client-*.rrd"), key=lambda p: p.stat().st_mtime)
    if not runs:
        raise RunNotFound(f"no client run (client-*.rrd) in {folder}: run nasm client first, or name a run")
    return runs[-1].stem


def run_files(run: str | Path | None, folder: Path = DEFAULT_DIR) -> list[Path]:
    """The ``.rrd`` files of ``run``: a run id in ``folder``, the path of one of its files, or
    (None) the newest client run in ``folder``."""
    path = Path(latest_run(folder) if run is None else run)
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


def viewer_command(files: list[Path], screenshot: Path | None = None, blueprint: Path | None = None) -> list[str]:
    """The command that opens ``files`` in the Rerun viewer (laid out by ``blueprint`` if
    given), or writes their screenshot."""
    command = [sys.executable, "-m", "rerun", *map(str, files), *([str(blueprint)] if blueprint else [])]
    if screenshot is None:
        return command
    command[3:3] = ["--renderer", "vulkan", "--window-size", SCREENSHOT_SIZE, "--screenshot-to", str(screenshot)]
    if os.environ.get("DISPLAY"):
        return command
    if shutil.which("xvfb-run") is None:
        raise RuntimeError("a screenshot needs a display or xvfb-run (apt-get install xvfb mesa-vulkan-drivers)")
    return ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", *command]


def view(run: str | Path | None, folder: Path = DEFAULT_DIR, screenshot: Path | None = None,
         blueprint: Path | None = None) -> list[Path]:
    """Open the run in the viewer (returns when it is closed) or write its screenshot;
    ``blueprint``: a ``.rbl`` layout to use instead of the recordings' own."""
    files = run_files(run, folder)
    if blueprint is not None and (blueprint.suffix != ".rbl" or not blueprint.is_file()):
        raise RunNotFound(f"no Rerun blueprint file (.rbl) at {blueprint}")
    if screenshot is None:
        subprocess.run(viewer_command(files, blueprint=blueprint), check=True)
        return files
    with tempfile.TemporaryDirectory() as tmp:
        if blueprint is None:
            blueprint = Path(tmp) / "end.rbl"
            bp.episode_end_blueprint().save(APP_ID, blueprint)
        done = subprocess.run(viewer_command(files, screenshot, blueprint), capture_output=True, text=True)  # log only on failure
    if done.returncode != 0 or not screenshot.exists():
        raise RuntimeError(f"the viewer wrote no screenshot to {screenshot}:\n{done.stderr[-2000:]}")
    return files
