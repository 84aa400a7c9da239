"""Streaming Panda client: simulate an episode, stream it to the Neural ASM service, record it.

    python sim/client.py                                  # one episode, embedded service (= nasm client)
    python sim/client.py --fault-joint 2 --fault-time 3 --fault-overshoot 15
    python sim/client.py --url http://127.0.0.1:8000 --api-key KEY --episodes 5 --reconnect
    python sim/client.py --falling-object --controller compliant --correct   # the reactive-correction demo

Each episode is simulated first (``neural_asm.sim.paper.run_episode``; under ``--controller compliant``
the memory's recalled plan, see ``neural_asm.client.run``), then its 15 observations
are streamed to the service one step at a time over the websocket ``/stream`` (or, with
``--transport http``, ``POST /sessions`` + ``POST /fault``). A live line is printed per
step (energy, threshold, flag, isolated joint) and a summary per episode.

The client talks to the service only over HTTP/websocket. With no ``--url`` it starts the
service in-process on a free loopback port (``neural_asm.service.embedded``), which builds the
default Panda model on first run (a few minutes, with a progress bar).

Every episode is recorded to ``<out>/client-....rrd`` and ``.mcap`` (``recordings``) under
a Rerun recording id that is also given to the service session, so the client's file
(world: arm, tool path, cube; scores) and the service's file merge into one view:
``nasm view client-X`` (or ``rerun client-X.rrd service-client-X-*.rrd`` in the recordings folder
of the data home).

If the service goes away mid-episode the client says so; with ``--reconnect`` it opens a
new session, replays the steps sent so far and carries on. Recordings are closed in all
cases (normal exit, lost service, Ctrl-C, errors) and stay readable.

Exit codes: 0 done, 2 a bad option or the service refused (bad API key, unknown model, ...),
3 the service went away (or could not be reached), 130 Ctrl-C. ``run_client`` is the function behind the
CLI; it returns one ``EpisodeSummary`` per episode.
"""

from neural_asm.client.run import run_client
from neural_asm.client.summary import EpisodeSummary, StepLine

__all__ = ["EpisodeSummary", "StepLine", "run_client"]
