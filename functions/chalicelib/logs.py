"""Structured JSON logs: one line per request (request id, method, path, status, duration_ms, principal), and
errors with their traceback. The request id comes from API Gateway when there is one and is echoed as X-Request-Id."""
from __future__ import annotations

import json
import logging
import sys
import threading
import time
import traceback
import uuid
from typing import Any

from chalice.app import Request, Response

# Not "drem": Chalice names its own app logger after app_name and sets it to ERROR unless debug is on.
_logger = logging.getLogger("drem.json")
_configured = threading.Lock()
_local = threading.local()


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        line: dict[str, Any] = {"ts": round(record.created, 3), "level": record.levelname.lower(),
                                "msg": record.getMessage()}
        line.update(getattr(record, "fields", {}))
        return json.dumps(line, default=str)


def configure(stream: Any = None) -> None:
    """Send drem's logs as JSON lines to `stream` (stderr by default); idempotent."""
    with _configured:
        if any(getattr(h, "drem_json", False) for h in _logger.handlers):
            return
        handler = logging.StreamHandler(stream or sys.stderr)
        handler.setFormatter(JsonFormatter())
        handler.drem_json = True  # type: ignore[attr-defined]
        _logger.addHandler(handler)
        _logger.setLevel(logging.INFO)
        _logger.propagate = False


def log(level: int, message: str, **fields: Any) -> None:
    configure()
    request_id = current_request_id()
    if request_id and "request_id" not in fields:
        fields["request_id"] = request_id
    _logger.log(level, message, extra={"fields": fields})


def log_exception(message: str, exc: BaseException) -> None:
    log(logging.ERROR, message, error=type(exc).__name__,
        traceback="".join(traceback.format_exception(type(exc), exc, exc.__traceback__)))


def current_request_id() -> str | None:
    state = getattr(_local, "request", None)
    return state["request_id"] if state else None


def note_principal(principal_id: str) -> None:
    state = getattr(_local, "request", None)
    if state is not None:
        state["principal"] = principal_id


def request_path(request: Request) -> str:
    """The path the client asked for (`request.path` is the route pattern, e.g. /static/{name})."""
    original = request.to_original_event() or {}
    return original.get("path") or request.path


def request_log_middleware(event: Request, get_response: Any) -> Response:
    """Chalice HTTP middleware (registered in app.py)."""
    request_id = (event.context or {}).get("requestId") or uuid.uuid4().hex
    _local.request = {"request_id": request_id, "principal": "anonymous"}
    started = time.perf_counter()
    status = 500
    try:
        response = get_response(event)
        status = response.status_code
        response.headers["X-Request-Id"] = request_id
        return response
    finally:
        principal = _local.request["principal"]
        _local.request = None
        log(logging.INFO, "request", request_id=request_id, method=event.method, path=request_path(event),
            route=event.path, status=status,
            duration_ms=round((time.perf_counter() - started) * 1000, 2), principal=principal)
