"""Recordings cut short by a crash, rewritten into valid indexed files, and found after one.

``recover`` rewrites a file in place (through a temporary file, so nothing half-written
is left): an ``.mcap`` keeps every record up to its last whole chunk and gains chunk
indexes, statistics and a summary, like the official ``mcap recover``; an ``.rrd``
keeps every chunk that decodes (``rerun rrd merge --continue-on-error``) and gains its
footer, so it passes ``rerun rrd verify``. Recovering a whole file changes nothing but
the layout of its bytes.

A writer that may be killed leaves an open marker (``<run>.recording.json``) beside its
files while they are open. ``recover_interrupted`` finds the markers of writers that
are gone, recovers their files and replaces each marker with ``<run>.interrupted.json``
saying what was kept: the episode was interrupted.
"""

from __future__ import annotations

import json
import os
import struct
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import StreamReader
from mcap.records import Channel, Footer, Message, Metadata, Schema

from neural_asm.recordings.mcap_file import McapFile
from neural_asm.recordings.readers import repair_rrd

OPEN_MARKER = ".recording.json"
INTERRUPTED_MARKER = ".interrupted.json"
RECOVERY_METADATA = "neural_asm.recovery"


@dataclass(frozen=True)
class Recovered:
    path: str
    was_indexed: bool | None  # an MCAP file already had its summary: it was closed (not told for .rrd)
    messages: int | None  # MCAP messages kept (not told for .rrd)


def _temporary(path: Path) -> Path:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp" + path.suffix)
    os.close(fd)
    return Path(tmp)


def recover_mcap(path: Path, note: dict[str, str] | None = None) -> Recovered:
    """Rewrite an MCAP file with every whole record, its indexes and a recovery note (metadata)."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    body: list[Message | Metadata] = []
    indexed = False
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Schema):
                    schemas.setdefault(record.id, record)
                elif isinstance(record, Channel):
                    channels.setdefault(record.id, record)
                elif isinstance(record, (Message, Metadata)):
                    body.append(record)
                elif isinstance(record, Footer):
                    indexed = record.summary_start != 0  # 0: the provisional end of a file cut short
        except (McapError, EOFError, struct.error, ValueError):
            pass  # the torn end: everything before it is whole
    tmp = _temporary(path)
    try:
        out = McapFile(tmp)
        schema_ids = {i: out.writer.register_schema(s.name, s.encoding, s.data) for i, s in schemas.items()}
        channel_ids = {
            i: out.writer.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), c.metadata)
            for i, c in channels.items()
        }
        kept = 0
        for record in body:
            if isinstance(record, Metadata):
                if record.name != RECOVERY_METADATA:  # a second recovery replaces the first note
                    out.writer.add_metadata(record.name, record.metadata)
            elif record.channel_id in channel_ids:
                out.writer.add_message(channel_ids[record.channel_id], record.log_time, record.data,
                                       record.publish_time, record.sequence)
                kept += 1
        out.writer.add_metadata(RECOVERY_METADATA, {"was_indexed": str(indexed).lower(), "messages": str(kept),
                                                    **(note or {})})
        out.close()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return Recovered(str(path), indexed, kept)


def recover_rrd(path: Path) -> Recovered:
    """Rewrite an ``.rrd`` with every chunk that decodes, and a footer."""
    tmp = _temporary(path)
    try:
        repair_rrd(path, tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return Recovered(str(path), None, None)


def recover(path: str | Path, note: dict[str, str] | None = None) -> Recovered:
    """Recover one ``.mcap`` or ``.rrd`` in place; a ValueError names anything else."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    if path.suffix == ".mcap":
        return recover_mcap(path, note)
    if path.suffix == ".rrd":
        return recover_rrd(path)
    raise ValueError(f"{path}: not a recording (expected .mcap or .rrd)")


def write_json(path: Path, content: dict[str, Any]) -> None:
    """Write through a temporary file, so a crash never leaves half a marker."""
    tmp = _temporary(path)
    try:
        tmp.write_text(json.dumps(content, indent=1))
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def process_start(pid: int) -> str | None:
    """When the kernel started process ``pid`` (clock ticks since boot, field 22 of
    /proc/<pid>/stat), None where there is no /proc. With the PID it names one process: a PID
    alone is reused, as by a restarted container, whose processes count from 1 again."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat[stat.rindex(")") + 2 :].split()[19]  # fields after the command name start at 3


def writer_identity() -> dict[str, Any]:
    """What a marker says of the process writing its files (see ``writing``)."""
    return {"pid": os.getpid(), "pid_started": process_start(os.getpid())}


def writing(opened: dict[str, Any]) -> bool:
    """Whether the process a marker names is alive and is the one that wrote it."""
    pid = opened.get("pid")
    if not isinstance(pid, int) or pid <= 0 or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    started = opened.get("pid_started")
    return started is None or process_start(pid) in (started, None)


def recover_interrupted(folder: Path) -> list[Path]:
    """Recover the files of every writer in ``folder`` that died with them open; returns the markers written."""
    written = []
    for marker in sorted(folder.glob("*" + OPEN_MARKER)):
        try:
            opened = json.loads(marker.read_text())
        except (OSError, ValueError):
            opened = {}
        if writing(opened):
            continue  # another live process is writing these
        run = marker.name[: -len(OPEN_MARKER)]
        note = {"interrupted": "true", "reason": "the writer stopped without closing this episode"}
        results = [asdict(recover(p, note)) for p in (folder / f"{run}.mcap", folder / f"{run}.rrd") if p.is_file()]
        done = folder / f"{run}{INTERRUPTED_MARKER}"
        write_json(done, {**opened, "interrupted": True, "recovered_at": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                          "files": results})
        marker.unlink()
        written.append(done)
    return written
