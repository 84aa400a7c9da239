"""The service's health in Prometheus' terms: what an operations stack scrapes at ``GET /metrics``.

Every name starts ``nasm_``. Counters and the latency histogram are updated as things happen
(a step costs three updates, a few microseconds); the gauges (sessions open, the recorder's
backlog, records dropped, steps the live view skipped, checkpoints refused) are read from the
service's state at each scrape. Labels are model names and status codes only: never a session id, a client address or
anything a client sent, so the page tells an operator how the service does, not what its
clients stream. Each app has a registry of its own (tests and benchmarks run several in one
process).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

from prometheus_client import CollectorRegistry, Counter, Histogram, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

if TYPE_CHECKING:
    from neural_asm.service.state import ServiceState

# Seconds from a step's arrival to its answer: the micro-batch's wait and the relaxation
# (a step takes 0.05-5 ms on loopback; a robot at 40 Hz has 25 ms).
LATENCY_BUCKETS_S = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0)


class _StateGauges(Collector):
    """The gauges read at scrape time from the service's state."""

    def __init__(self, state: ServiceState) -> None:
        self.state = state

    def collect(self) -> Iterator[GaugeMetricFamily]:
        state = self.state
        yield GaugeMetricFamily("nasm_sessions_open", "sessions open now", value=len(state.sessions))
        recorder = state.recorder
        backlog = None if recorder is None else recorder.backlog()
        yield GaugeMetricFamily("nasm_recorder_queue_depth",
                                "messages waiting for the recorder process (it holds at most a bounded few; "
                                "NaN: not recording, or the platform cannot tell)",
                                value=float("nan") if backlog is None else backlog)
        dropped = state.runner.dropped_records + (0 if recorder is None else recorder.dropped_records)
        yield CounterMetricFamily("nasm_records_dropped", "scored steps whose records were lost (the recorder "
                                  "process died or refused them); the steps were answered all the same",
                                  value=dropped)
        yield CounterMetricFamily("nasm_live_steps_dropped", "scored steps the live Rerun view skipped because it "
                                  "fell behind (the files have them)",
                                  value=0 if recorder is None else recorder.live_dropped_steps)
        yield GaugeMetricFamily("nasm_checkpoints_refused", "checkpoints of the models folder refused at load "
                                "(failed a check; listed as broken by GET /models)", value=len(state.registry.broken))


class Metrics:
    """The instruments the service updates, in a registry of their own."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.sessions_opened = Counter("nasm_sessions_opened", "sessions opened", ["model"], registry=self.registry)
        self.steps = Counter("nasm_steps", "observations scored", ["model"], registry=self.registry)
        self.flags = Counter("nasm_flags", "steps flagged as a fault", ["model"], registry=self.registry)
        self.step_latency = Histogram("nasm_step_latency_seconds", "from a step's arrival to its answer",
                                      ["model"], buckets=LATENCY_BUCKETS_S, registry=self.registry)
        self.ws_errors = Counter("nasm_websocket_errors", "error answers on the websocket stream, by status",
                                 ["status"], registry=self.registry)
        self.http_errors = Counter("nasm_http_errors", "HTTP responses with a 4xx or 5xx status, by status",
                                   ["status"], registry=self.registry)
        self._per_model: dict[str, tuple[Callable[[], None], Callable[[], None], Callable[[float], None]]] = {}

    def watch(self, state: ServiceState) -> None:
        """Read the gauges from ``state`` at every scrape."""
        self.registry.register(_StateGauges(state))

    def session_opened(self, model: str) -> None:
        self.sessions_opened.labels(model).inc()

    def step(self, model: str, flagged: bool, started: float) -> None:
        """A step of ``model`` answered; ``started`` is its ``time.perf_counter()`` on arrival."""
        instruments = self._per_model.get(model)
        if instruments is None:  # the labelled children, looked up once per model
            instruments = (self.steps.labels(model).inc, self.flags.labels(model).inc,
                           self.step_latency.labels(model).observe)
            self._per_model[model] = instruments
        count, flag, observe = instruments
        count()
        if flagged:
            flag()
        observe(time.perf_counter() - started)

    def ws_error(self, status: int) -> None:
        self.ws_errors.labels(str(status)).inc()

    def exposition(self) -> bytes:
        return generate_latest(self.registry)


class CountHttpErrors:
    """ASGI middleware: every HTTP response of status >= 400 counted by status, whichever layer
    sent it (the body limit's 413, the auth's 401, a handler's 4xx, an unhandled 500)."""

    def __init__(self, app: ASGIApp, metrics: Metrics) -> None:
        self.app = app
        self.metrics = metrics

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        answered = False

        async def counting(message: Message) -> None:
            nonlocal answered
            if message["type"] == "http.response.start":
                answered = True
                if message["status"] >= 400:
                    self.metrics.http_errors.labels(str(message["status"])).inc()
            await send(message)

        try:
            await self.app(scope, receive, counting)
        except Exception:
            if not answered:  # the server answers 500 for it
                self.metrics.http_errors.labels("500").inc()
            raise
