"""Recordings of every run: Rerun ``.rrd`` files for eyes, MCAP files for tools.

- ``episode.EpisodeRecorder``: one episode or service session, to both formats;
- ``training.TrainingRecorder``: energy per epoch of a training run;
- ``recorder.RecorderProcess``: a service's sessions, written by a process of their own;
- ``readers``: read values back (tests, analysis);
- ``paths``: run ids and the git-ignored output folder.
- ``foxglove_scene``: the world as Foxglove scene messages; ``layouts/neural_asm.json``:
  a Foxglove layout for the MCAP files.

Every writer is a context manager that closes its files on normal exit, Ctrl-C and
errors. After a kill (SIGKILL) what was written stays readable:

- ``.mcap``: messages go into 16 KiB chunks; each flush writes the new chunks followed by
  a provisional end (data end, footer, magic), so a file cut by a kill is a valid MCAP
  file without indexes that mcap's ``make_reader`` reads to its last whole chunk.
- ``.rrd``: steps are sent to Rerun in batches of up to 40 and flushed (a service's recorder
  process also flushes every second); a cut file has no footer and fails
  ``rerun rrd verify`` though its chunks read.
- ``nasm recordings recover FILE...`` (``recover.recover``) rewrites either kind into a
  valid, indexed file; a service does this on start for the episodes a crash
  interrupted (``recorder``, ``recover.recover_interrupted``).
"""

from neural_asm.recordings.episode import EpisodeRecorder
from neural_asm.recordings.paths import APP_ID, DEFAULT_DIR, new_run_id, run_paths
from neural_asm.recordings.training import TrainingRecorder

__all__ = ["APP_ID", "DEFAULT_DIR", "EpisodeRecorder", "TrainingRecorder", "new_run_id", "run_paths"]
