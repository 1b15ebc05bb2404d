"""The app server's same-origin door to the storage server: `/_storage/...` is streamed to it unchanged.

The storage server listens on loopback only, yet racers' browsers upload models with presigned POST forms and cars
download them with presigned GETs, from the venue network. Those links point here ({DREM_PUBLIC_URL}/_storage/...,
chalicelib.storage.clients.s3_presigner); this module forwards them byte for byte (Host included: it is part of
what was signed), and the storage server verifies the signature and accepts nothing but presigned S3 requests on
this path (drem_local.durable.guard). Uploads are same-origin, so no CORS is needed anywhere.

Because whatever a racer uploads would be served from the app's own origin, every answer is forced to download as
an opaque file in a sandbox (never rendered as a page that could run script with the app's cookies).
"""
from __future__ import annotations

import http.client
from collections.abc import Callable, Iterable, Iterator
from http import HTTPStatus
from typing import Any
from urllib.parse import urlsplit

from drem_local.chalice_wsgi import raw_target, request_headers
from drem_local.durable.guard import GATEWAY_PATH

_CHUNK = 256 * 1024
_METHODS = ("GET", "HEAD", "POST")
# Hop-by-hop (RFC 9110 7.6.1), plus what must never reach the storage journal (the racer's session cookie).
_DROP_REQUEST = {"connection", "keep-alive", "proxy-connection", "te", "trailer", "upgrade", "expect", "cookie",
                 "authorization", "x-forwarded-for", "forwarded", "transfer-encoding"}
_DROP_RESPONSE = {"connection", "keep-alive", "transfer-encoding", "content-type", "content-disposition",
                  "server", "date", "set-cookie", "content-length"}
_SAFE_RESPONSE_HEADERS = (
    ("Content-Type", "application/octet-stream"),
    ("Content-Disposition", "attachment"),
    ("X-Content-Type-Options", "nosniff"),
    ("Content-Security-Policy", "sandbox; default-src 'none'"),
    ("Cache-Control", "no-store"),
)


def is_gateway_path(path: str) -> bool:
    return path == GATEWAY_PATH or path.startswith(GATEWAY_PATH + "/")


class StorageGateway:
    """WSGI app: `environ`'s request to the storage server and its answer back, both bodies streamed.

    The HTTP server in front (drem_local.http_front) has already refused a body over the gateway's limit from its
    Content-Length, and spooled an accepted one to a temporary file, so nothing here grows with a body's size."""

    def __init__(self, storage_url: str, timeout_s: float = 120.0) -> None:
        target = urlsplit(storage_url)
        assert target.hostname is not None, "the storage URL names a host"
        self.host, self.port, self.timeout_s = target.hostname, target.port, timeout_s

    def __call__(self, environ: dict[str, Any], start_response: Callable[..., Any]) -> Iterable[bytes]:
        method = environ["REQUEST_METHOD"]
        if method not in _METHODS:
            return _plain(start_response, 405, "only presigned downloads (GET) and upload forms (POST) pass here")
        length_text = environ.get("CONTENT_LENGTH") or "0"
        if not length_text.isdigit():
            return _plain(start_response, 400, "Content-Length is not a number")
        length = int(length_text)
        if method != "POST" and length:
            return _plain(start_response, 400, "a download carries no body")
        if method == "POST" and "multipart/form-data" not in environ.get("CONTENT_TYPE", "").lower():
            return _plain(start_response, 403, "only browser upload forms (multipart/form-data) are posted here")
        connection = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout_s)
        try:
            connection.putrequest(method, raw_target(environ), skip_host=True, skip_accept_encoding=True)
            for name, value in request_headers(environ).items():
                if name.lower() not in _DROP_REQUEST and name.lower() != "content-length":
                    connection.putheader(name, value)
            if method == "POST":
                connection.putheader("Content-Length", str(length))
            connection.endheaders()
            _send_body(connection, environ["wsgi.input"], length)
            answer = connection.getresponse()
        except OSError:
            connection.close()
            return _plain(start_response, 502, "drem's storage server is not answering")
        return _relay(start_response, method, answer, connection)


def _send_body(connection: http.client.HTTPConnection, stream: Any, length: int) -> None:
    remaining = length
    while remaining > 0:
        chunk = stream.read(min(_CHUNK, remaining))
        if not chunk:
            break  # the client went away mid-upload; storage sees a short body and refuses it
        connection.send(chunk)
        remaining -= len(chunk)


def _relay(start_response: Callable[..., Any], method: str, answer: http.client.HTTPResponse,
           connection: http.client.HTTPConnection) -> Iterable[bytes]:
    declared = answer.getheader("Content-Length")
    body = None if declared is not None else answer.read()  # moto always declares it; read if it ever does not
    headers = [(name, value) for name, value in answer.getheaders() if name.lower() not in _DROP_RESPONSE]
    headers += list(_SAFE_RESPONSE_HEADERS)
    headers.append(("Content-Length", str(len(body)) if body is not None else str(declared)))
    start_response(f"{answer.status} {answer.reason}", headers)
    if method == "HEAD":
        connection.close()
        return []
    if body is not None:
        connection.close()
        return [body]
    return _streamed(answer, connection)


def _streamed(answer: http.client.HTTPResponse, connection: http.client.HTTPConnection) -> Iterator[bytes]:
    try:
        while chunk := answer.read(_CHUNK):
            yield chunk
    finally:
        connection.close()


def _plain(start_response: Callable[..., Any], status: int, message: str) -> list[bytes]:
    data = (message + "\n").encode()
    start_response(f"{status} {HTTPStatus(status).phrase}", [
        ("Content-Type", "text/plain; charset=utf-8"), ("X-Content-Type-Options", "nosniff"),
        ("Content-Length", str(len(data)))])
    return [data]
