"""API-key check: the ``X-API-Key`` header, required whenever a key is configured.

A key is mandatory when the service binds beyond loopback (``Settings.check_exposure``).
``/healthz`` stays open so that orchestrators can probe liveness without secrets; ``/metrics``
takes the key as a bearer token too, the one way Prometheus can send it.
"""

import hashlib
import secrets
from collections.abc import Mapping

from fastapi import HTTPException, Request, Security, status
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from neural_asm.models.answer import API_KEY_HEADER

_header = APIKeyHeader(name=API_KEY_HEADER, auto_error=False, description="required when the server has a key")


def key_ok(expected: str | None, given: str | None) -> bool:
    if not expected:
        return True
    return given is not None and secrets.compare_digest(given.encode(), expected.encode())


def require_api_key(request: Request, key: str | None = Security(_header)) -> None:
    if not key_ok(request.app.state.service.settings.api_key, key):
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, f"missing or wrong {API_KEY_HEADER} header")


_bearer = HTTPBearer(auto_error=False, description="the API key, as Prometheus sends it (GET /metrics only)")


def require_scrape_key(request: Request, key: str | None = Security(_header),
                       bearer: HTTPAuthorizationCredentials | None = Security(_bearer)) -> None:
    """The API key as ``X-API-Key`` or as a bearer token: a scraper can send only the latter."""
    expected = request.app.state.service.settings.api_key
    if not (key_ok(expected, key) or (bearer is not None and key_ok(expected, bearer.credentials))):
        raise HTTPException(status.HTTP_401_UNAUTHORIZED, f"missing or wrong {API_KEY_HEADER} header (or bearer token)")


def client_of(expected: str | None, headers: Mapping[str, str], address: str | None) -> str:
    """Whose session quota a request counts against: its API key when the server has one
    (a digest, never the key), else its address (on loopback every local process is one client)."""
    given = headers.get(API_KEY_HEADER)
    if expected and given:
        return f"key {hashlib.sha256(given.encode()).hexdigest()[:12]}"
    return f"address {address or 'unknown'}"
