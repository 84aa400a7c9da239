"""Recordings of every run: Rerun ``.rrd`` files for eyes, MCAP files for tools.

- ``episode.EpisodeRecorder``: one episode or service session, to both formats;
- ``training.TrainingRecorder``: energy per epoch of a training run;
- ``readers``: read values back (tests, analysis);
- ``paths``: run ids and the git-ignored output folder.

Every writer is a context manager that closes its files on normal exit, Ctrl-C and
errors. After a hard crash (SIGKILL, power loss) what was written stays readable:

- ``.mcap``: messages go into 4 KiB chunks flushed as they fill, so a kill loses the
  chunk being filled and the rest reads with ``readers.read_mcap`` or mcap's
  ``NonSeekingReader`` (both stop at the torn chunk) or is repaired with the MCAP CLI:
  ``mcap recover broken.mcap -o fixed.mcap``.
- ``.rrd``: Rerun streams to the file as it goes; ``rerun rrd verify FILE`` checks it
  and ``rerun rrd merge --continue-on-error FILE -o fixed.rrd`` keeps what decodes.
"""

from recordings.episode import EpisodeRecorder
from recordings.paths import APP_ID, DEFAULT_DIR, new_run_id, run_paths
from recordings.training import TrainingRecorder

__all__ = ["APP_ID", "DEFAULT_DIR", "EpisodeRecorder", "TrainingRecorder", "new_run_id", "run_paths"]
