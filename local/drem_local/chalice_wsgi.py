"""The Chalice app as a WSGI application, unchanged: each request goes through chalice.local's `LocalGateway`.

`LocalGateway.handle_request(method, path, headers, body)` is what Chalice's own dev server calls per request
(chalice/local.py, `ChaliceRequestHandler._generic_handle`): it builds the API Gateway event, runs the route and
returns the Lambda proxy answer. This module does the same from a WSGI environ, and answers as that handler does
(`_send_http_response*`: Content-Length, Content-Type defaulting to application/json, single and multi-value
headers, a base64 body decoded, a LocalGatewayException as its own status), so routes, cookies, binary bodies and
status codes are what they were. One difference on purpose: `requestContext.identity.sourceIp` is the real client
address the HTTP server reports (REMOTE_ADDR), where chalice.local always says 127.0.0.1 (`LOCAL_SOURCE_IP`).
"""
from __future__ import annotations

import base64
from collections.abc import Callable, Iterable
from http import HTTPStatus
from typing import Any

from chalice.local import LocalGateway, LocalGatewayException

# WSGI puts these two outside the HTTP_ prefix.
_UNPREFIXED = {"CONTENT_TYPE": "Content-Type", "CONTENT_LENGTH": "Content-Length"}


def request_headers(environ: dict[str, Any]) -> dict[str, str]:
    """The request's headers named as a client writes them (Content-Type, X-Amz-Date, ...)."""
    headers: dict[str, str] = {}
    for key, value in environ.items():
        if key.startswith("HTTP_"):
            name = "-".join(part.capitalize() for part in key[5:].split("_"))
        elif key in _UNPREFIXED:
            name = _UNPREFIXED[key]
        else:
            continue
        if value != "" or key.startswith("HTTP_"):
            headers[name] = value
    return headers


def raw_target(environ: dict[str, Any]) -> str:
    """Path and query exactly as the client sent them (waitress: REQUEST_URI), as chalice.local's `self.path`."""
    target = environ.get("REQUEST_URI") or environ.get("RAW_URI")
    if target:
        if target.startswith(("http://", "https://")):  # absolute form: keep only path and query
            target = "/" + target.split("://", 1)[1].partition("/")[2]
        return str(target)
    query = environ.get("QUERY_STRING", "")
    return environ.get("PATH_INFO", "/") + (f"?{query}" if query else "")


class ChaliceWSGI:
    def __init__(self, gateway: LocalGateway) -> None:
        self.gateway = gateway
        _report_client_address(gateway)

    def __call__(self, environ: dict[str, Any], start_response: Callable[..., Any]) -> Iterable[bytes]:
        headers = request_headers(environ)
        length = int(environ.get("CONTENT_LENGTH") or 0)  # the server has the whole body already (or refused it)
        body = environ["wsgi.input"].read(length) if length > 0 else None
        _CLIENT.address = environ.get("REMOTE_ADDR") or "unknown"
        try:
            answer = self.gateway.handle_request(method=environ["REQUEST_METHOD"], path=raw_target(environ),
                                                 headers=headers, body=body)
        except LocalGatewayException as error:
            return _respond(start_response, error.CODE, dict(error.headers), error.body)
        finally:
            _CLIENT.address = None
        out_headers: dict[str, Any] = dict(answer["headers"])
        out_headers.update(answer.get("multiValueHeaders") or {})
        payload = answer.get("body")
        if answer.get("isBase64Encoded") and payload is not None:
            payload = base64.b64decode(payload)
        return _respond(start_response, answer["statusCode"], out_headers, payload)


class _ClientAddress:
    """The address of the request running on this thread (each request runs whole on one worker thread)."""

    def __init__(self) -> None:
        import threading

        self._local = threading.local()

    @property
    def address(self) -> str | None:
        return getattr(self._local, "address", None)

    @address.setter
    def address(self, value: str | None) -> None:
        self._local.address = value


_CLIENT = _ClientAddress()


def _report_client_address(gateway: LocalGateway) -> None:
    """Put the real client address in the event where API Gateway puts it (`requestContext.identity.sourceIp`)."""
    converter = gateway.event_converter
    if getattr(converter, "_drem_source_ip", False):
        return
    create = converter.create_lambda_event

    def create_lambda_event(*args: Any, **kwargs: Any) -> Any:
        event = create(*args, **kwargs)
        if _CLIENT.address:
            event["requestContext"]["identity"]["sourceIp"] = _CLIENT.address
        return event

    converter.create_lambda_event = create_lambda_event  # type: ignore[method-assign]
    converter._drem_source_ip = True  # type: ignore[attr-defined]


def _respond(start_response: Callable[..., Any], status: int, headers: dict[str, Any],
             body: str | bytes | None) -> list[bytes]:
    try:
        reason = HTTPStatus(status).phrase
    except ValueError:
        reason = "Unknown"
    out: list[tuple[str, str]] = []
    if body is None:
        data = b""
    else:
        data = body if isinstance(body, bytes) else body.encode("utf-8")
        out.append(("Content-Type", str(headers.pop("Content-Type", "application/json"))))
    out.append(("Content-Length", str(len(data))))
    for name, value in headers.items():
        if name.lower() in ("content-length", "connection", "transfer-encoding"):
            continue  # the server frames the answer itself
        for one in value if isinstance(value, list) else [value]:
            out.append((name, str(one)))
    start_response(f"{status} {reason}", out)
    return [data]
