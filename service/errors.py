"""Client mistakes become 4xx with a message naming the problem; nothing else leaks.

FastAPI's default 422 echoes the offending input back, and a NaN in it makes the
encoder fail with a 500 (NOTES.md): the handler here reports locations and messages
only. A body that is not JSON at all gets a 400.
"""

from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

from neural_asm.service.schemas import Error


class ServiceError(Exception):
    """A request the service understood but cannot honour."""

    status = 400

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


class BadObservation(ServiceError):
    status = 422


class SkillRefused(ServiceError):
    """A skill a session cannot be told: one its model does not know, any for a model without
    skills, or another than the one its session was told."""

    status = 422


class NotCalibrated(ServiceError):
    """A well-formed request for a recall setting or rate the model was not calibrated for."""

    status = 409


class UnknownModel(ServiceError):
    status = 404


class UnknownSession(ServiceError):
    status = 404


class TooManySessions(ServiceError):
    status = 429


class ShuttingDown(ServiceError):
    status = 503


SHOWN = 3  # errors spelled out in the message; all are listed in "errors"


def error_body(detail: str, errors: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    return Error(detail=detail, errors=errors).model_dump(exclude_none=True)


def describe(errors: list[dict[str, Any]]) -> tuple[str, list[dict[str, Any]]]:
    """'field.path: message' for each pydantic error, without the input values."""
    safe = [{"loc": [str(p) for p in e.get("loc", ())], "msg": str(e.get("msg", "")), "type": str(e.get("type", ""))}
            for e in errors]
    lines = [f"{'.'.join(e['loc'][1:] if e['loc'][:1] == ['body'] else e['loc']) or 'body'}: {e['msg']}" for e in safe]
    more = f" (and {len(lines) - SHOWN} more)" if len(lines) > SHOWN else ""
    return "; ".join(lines[:SHOWN]) + more or "invalid request", safe


def undecodable(errors: list[dict[str, Any]]) -> bool:
    return any(e.get("type") == "json_invalid" for e in errors)


def json_problem(errors: list[dict[str, Any]]) -> str:
    """The decoder's own reason (FastAPI puts it in ctx, pydantic in msg); it quotes no input."""
    e = next(e for e in errors if e.get("type") == "json_invalid")
    reason = (e.get("ctx") or {}).get("error") or e.get("msg", "")
    return f"request body is not valid JSON: {reason}"


async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
    raw = list(exc.errors())
    if undecodable(raw):
        return JSONResponse(error_body(json_problem(raw)), status_code=400)
    text, safe = describe(raw)
    return JSONResponse(error_body(text, safe), status_code=422)


async def _service(request: Request, exc: ServiceError) -> JSONResponse:
    return JSONResponse(error_body(exc.detail), status_code=exc.status)


METHODS = ("DELETE", "GET", "HEAD", "OPTIONS", "PATCH", "POST", "PUT")


def allowed_methods(request: Request) -> list[str]:
    """Every method served at the request's path (Starlette's 405 names only the first matching route's)."""
    routes = request.app.router.routes
    return [m for m in METHODS
            if any(r.matches({**request.scope, "method": m})[0] == Match.FULL for r in routes)]


async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    headers = dict(exc.headers or {})
    if exc.status_code == 405:
        headers["Allow"] = ", ".join(allowed_methods(request))
    return JSONResponse(error_body(str(exc.detail)), status_code=exc.status_code, headers=headers)


def install(app: FastAPI) -> None:
    app.add_exception_handler(RequestValidationError, _validation)  # type: ignore[arg-type]
    app.add_exception_handler(ServiceError, _service)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, _http)  # type: ignore[arg-type]


ERROR_RESPONSES: dict[int | str, dict[str, Any]] = {
    400: {"model": Error, "description": "body is not valid JSON"},
    401: {"model": Error, "description": "missing or wrong X-API-Key header"},
    413: {"model": Error, "description": "body larger than the configured limit"},
    422: {"model": Error, "description": "a field is invalid; the message names it"},
}
