"""The runner: batched steps equal single ones, jobs keep their order, and recording never holds
an answer back."""

import asyncio
import threading

import numpy as np

from neural_asm.models.asm import step_streams
from neural_asm.recordings.recorder import SessionRecording
from neural_asm.service import runner as runner_module
from neural_asm.service.runner import Runner
from neural_asm.service.sessions import Session


def test_batched_step_equals_single_steps(reference, episodes):
    """Streams at different steps and modes, stepped together as the runner does, score and decide as if alone."""
    streams = {(m, i): reference.stream(m, 1, fpr=0.01) for m in ("offline", "online") for i in range(3)}
    singles = {key: reference.stream(key[0], 1) for key in streams}
    for t in range(6):
        for mode in ("offline", "online"):
            # episode i joins at step i, so a batch mixes cue and post-cue streams
            keys = [(mode, i) for i in range(3) if t >= i]
            cue = [k for k in keys if streams[k].t == 0]
            rest = [k for k in keys if k not in cue]
            for group in (cue, rest):
                if group:
                    xs = np.stack([episodes[k[1], t - k[1]] for k in group])
                    results = step_streams([streams[k] for k in group], xs)
                    for k, result in zip(group, results):
                        alone = singles[k].step(episodes[k[1], t - k[1]])
                        assert result.score.step == alone.step
                        np.testing.assert_allclose(result.score.energy, alone.energy, rtol=1e-4)
                        np.testing.assert_allclose(result.score.prediction, alone.prediction, rtol=1e-4, atol=1e-5)
                        threshold = reference.calibration(mode, 1).episode_thresholds[0.01]
                        assert result.decision.threshold == threshold
                        assert result.decision.fault == (result.score.energy > threshold)


def test_runner_jobs_come_after_the_steps_queued_before_them(reference, episodes):
    """What closes a recording must see the session's last step: a job queued behind
    pending steps (an HTTP DELETE racing a /predict) runs once they are computed."""
    runner = Runner()
    session = Session("s", "panda", reference.stream("online", 1, fpr=0.01), "r")

    async def race() -> tuple[int, int, int]:
        step = asyncio.ensure_future(runner.step(session, episodes[0, 0]))
        await asyncio.sleep(0)  # the step is queued, its batch not yet computed
        queued = session.stream.t
        seen_by_job = await runner.call(lambda: session.stream.t)
        return queued, seen_by_job, (await step).score.step

    runner.start()
    try:
        assert asyncio.run(race()) == (0, 1, 0)
    finally:
        runner.stop()


class HeldRecorder:
    """Stands in for the recorder process in front of the runner: keeps the batches it is
    handed, and can be held up (a recorder slower than the server)."""

    generation = 1

    def __init__(self) -> None:
        self.batches: list = []
        self.free = threading.Event()

    def write(self, batch) -> None:
        self.free.wait(timeout=30)
        self.batches.append(batch)


def test_recorded_steps_are_answered_at_once_handed_over_together_and_bounded(reference, episodes, monkeypatch):
    """Steps are answered without waiting for the recorder; their records reach it in fewer
    messages than steps, each once and in order, before a job queued after them; and once
    UNHANDED_MAX records wait behind a held-up recorder, further recorded steps wait too."""
    monkeypatch.setattr(runner_module, "UNHANDED_MAX", 8)
    recorder = HeldRecorder()
    runner = Runner(recorder)  # type: ignore[arg-type]
    sessions = []
    for i in range(4):
        session = Session(f"s{i}", "panda", reference.stream("online", 1, fpr=0.01), "r")
        session.recording = SessionRecording(f"key{i}", {}, recorder.generation, recorder)  # type: ignore[arg-type]
        sessions.append(session)

    async def round_(t: int) -> list:
        return [asyncio.ensure_future(runner.step(s, episodes[i, t])) for i, s in enumerate(sessions)]

    async def run() -> tuple[int, bool, int]:
        for t in range(3):  # 4 records with the held-up worker (the first hand-over), 8 waiting for it
            done, _ = await asyncio.wait(await round_(t), timeout=10)
            assert len(done) == 4
            await asyncio.sleep(2 * runner_module.HANDOVER_PERIOD_S)
        waiting = await round_(3)
        done, _ = await asyncio.wait(waiting, timeout=0.5)
        recorder.free.set()
        await asyncio.wait(waiting, timeout=10)
        answered_after = all(f.done() and f.exception() is None for f in waiting)
        await runner.call(lambda: None)  # queued after every record
        return len(done), answered_after, sum(len(b.keys) for b in recorder.batches)

    runner.start()
    try:
        answered_while_held, answered_after, handed = asyncio.run(run())
    finally:
        recorder.free.set()
        runner.stop()
    assert answered_while_held == 0 and answered_after
    assert handed == 16 and len(recorder.batches) < 16
    for i in range(4):
        steps = [step for b in recorder.batches for key, step in zip(b.keys, b.steps) if key == f"key{i}"]
        assert steps == list(range(4))
