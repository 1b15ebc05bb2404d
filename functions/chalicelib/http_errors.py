"""The one place that turns errors into HTTP responses.

JSON (`{"error": {"code", "message", "field", "fields", "requestId"}}`) for API paths, Bearer callers and clients that
ask for JSON; an HTML error page for browsers. A browser GET that needs a sign-in is sent to /login instead.
"""
from __future__ import annotations

from typing import Any
from urllib.parse import quote

from chalice import Response
from chalice.app import Request
from pydantic import ValidationError

from chalicelib import logs
from chalicelib.core import errors as e
from chalicelib.htmx import is_htmx
from drem_web import render

# Most specific first: the first isinstance match wins.
_STATUS: tuple[tuple[type[Exception], int], ...] = (
    (e.InvalidInput, 400),
    (e.NotAuthenticated, 401),
    (e.AccountNotReady, 403),
    (e.Forbidden, 403),
    (e.NotFound, 404),
    (e.Conflict, 409),
    (e.PayloadTooLarge, 413),
    (e.RateLimited, 429),
    (e.UpstreamError, 502),
    (e.StorageDiskFull, 507),
    (e.ServiceUnavailable, 503),
)

_TITLES = {400: "Check your input", 401: "Please sign in", 403: "Not allowed", 404: "Not found", 409: "Conflict",
           413: "Too large", 429: "Too many requests", 500: "Something went wrong", 502: "A service failed",
           503: "Temporarily unavailable", 507: "drem's disk needs attention"}


def status_for(exc: Exception) -> int:
    if isinstance(exc, ValidationError):
        return 400
    for error_type, status in _STATUS:
        if isinstance(exc, error_type):
            return status
    return 500


def validation_fields(exc: ValidationError) -> dict[str, str]:
    """{"field.path": "what is wrong"} for each pydantic error, so messages name the field."""
    fields: dict[str, str] = {}
    for error in exc.errors(include_url=False):
        name = ".".join(str(part) for part in error.get("loc", ())) or "body"
        fields.setdefault(name, error.get("msg", "is invalid"))
    return fields


def describe(exc: Exception) -> tuple[str, str | None, dict[str, str]]:
    """(message, field, fields) safe to show a user."""
    if isinstance(exc, ValidationError):
        fields = validation_fields(exc)
        return "; ".join(f"{name}: {msg}" for name, msg in fields.items()), next(iter(fields), None), fields
    if isinstance(exc, e.DremError):
        return exc.message, exc.field, ({exc.field: exc.message} if exc.field else {})
    return "An unexpected error occurred. It has been logged.", None, {}


def wants_json(request: Request | None) -> bool:
    if request is None:
        return True
    headers = request.headers
    if request.path.startswith("/api/") or "authorization" in headers:
        return True
    accept = headers.get("accept") or ""
    return "application/json" in accept and "text/html" not in accept


def to_response(exc: Exception, request: Request | None) -> Response:
    response = _error_response(exc, request)
    if isinstance(exc, e.RateLimited) and exc.retry_after:
        response.headers["Retry-After"] = str(exc.retry_after)
    return response


def retry_after_headers(exc: Exception | None) -> dict[str, str]:
    """Retry-After for a form page that shows a RateLimited error next to its field."""
    if isinstance(exc, e.RateLimited) and exc.retry_after:
        return {"Retry-After": str(exc.retry_after)}
    return {}


def _error_response(exc: Exception, request: Request | None) -> Response:
    status = status_for(exc)
    request_id = logs.current_request_id()
    if status == 500:
        logs.log_exception("unhandled error", exc)
    message, field, fields = describe(exc)
    if wants_json(request):
        headers: dict[str, str | list[str]] = {"WWW-Authenticate": "Bearer"} if status == 401 else {}
        body: dict[str, Any] = {"code": type(exc).__name__ if status != 500 else "InternalError",
                                "message": message, "field": field, "fields": fields, "requestId": request_id}
        return Response(body={"error": body}, status_code=status, headers=headers)
    if status == 401 and request is not None and request.method == "GET" and not is_htmx(request):
        # `next` is the app's own path; the sign-in form sends the browser back to it under the base path.
        login = f"/login?next={quote(logs.request_path(request), safe='/')}"
        return Response(body="", status_code=303, headers={"Location": render.url(login)})
    return render.page("error", status=status, title=_TITLES.get(status, "Error"), message=message,
                       status_code=status, request_id=request_id)

