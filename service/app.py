"""The FastAPI application: routers, error handlers, body limit and lifespan.

    app = create_app(Settings(models_dir=Path("my_models")))

The lifespan starts the recorder process (which first recovers what a crash left in the
recordings folder), the inference runner, loads the models (building the default one on
first run when allowed) and closes idle sessions in the background; on shutdown it
closes every session, waits for its recordings to be finished, and stops both.
"""

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

from fastapi import FastAPI

from neural_asm.runtime.version import __version__
from neural_asm.service import errors
from neural_asm.service.limits import BodyLimit
from neural_asm.service.metrics import CountHttpErrors
from neural_asm.service.routers import health, inference, metrics, models, sessions, stream
from neural_asm.service.settings import Settings
from neural_asm.service.state import ServiceState


def create_app(settings: Settings | None = None) -> FastAPI:
    settings = settings or Settings()
    settings.check_exposure()
    settings.check_live()
    state = ServiceState(settings)

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        await state.startup()
        expiry = asyncio.create_task(state.expire_idle_forever())
        try:
            yield
        finally:
            expiry.cancel()
            await state.shutdown()

    app = FastAPI(
        title="Neural ASM service",
        version=__version__,
        description="Hosts trained Neural ASM models and scores streamed robot observations: "
        "next-step predictions, per-channel prediction errors, energy and fault flags.",
        lifespan=lifespan,
    )
    app.state.service = state
    errors.install(app)
    for module in (health, models, sessions, inference, stream):
        app.include_router(module.router)
    app.add_middleware(BodyLimit, max_bytes=settings.max_body_bytes)
    if state.metrics is not None:
        app.include_router(metrics.router)
        app.add_middleware(CountHttpErrors, metrics=state.metrics)  # outermost: counts the body limit's 413 too
    if not settings.api_key:
        _openapi_without_key(app)
    return app


def _openapi_without_key(app: FastAPI) -> None:
    """A server without a key accepts every request: its OpenAPI declares no key and no 401."""
    full = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = full()
            schema.get("components", {}).pop("securitySchemes", None)
            for operations in schema["paths"].values():
                for operation in operations.values():
                    operation.pop("security", None)
                    operation.get("responses", {}).pop("401", None)
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
