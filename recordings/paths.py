"""Where recordings go and what they are called.

A run id names both files of a run (``<run id>.rrd``, ``<run id>.mcap``). The Rerun
application id is shared by every writer so that files of one recording id (a client
and the service it talked to) merge into one view: ``rerun client.rrd service.rrd``.
"""

from __future__ import annotations

import re
import secrets
import time
from pathlib import Path

from neural_asm.runtime.home import home_path

APP_ID = "neural_asm"
DEFAULT_DIR = home_path("recordings")
_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def new_run_id(kind: str) -> str:
    """A sortable, unique id such as ``client-20250101-120000-1a2b3c``."""
    return f"{safe_name(kind)}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(3)}"


def safe_name(text: str) -> str:
    """A file-name-safe version of an id that may come from a client."""
    return _SAFE.sub("_", text).strip("._") or "run"


def run_paths(folder: str | Path, run_id: str) -> tuple[Path, Path]:
    """The ``.rrd`` and ``.mcap`` paths of a run; creates the folder."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    name = safe_name(run_id)
    return folder / f"{name}.rrd", folder / f"{name}.mcap"
