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
from http.server import BaseHTTPRequestHandler
from urllib.parse import urlsplit

from drem_local.durable.guard import GATEWAY_PATH

_CHUNK = 256 * 1024
_METHODS = ("GET", "HEAD", "POST")
# Hop-by-hop (RFC 9110 7.6.1), plus what must never reach the storage journal (the racer's session cookie).
_DROP_REQUEST = {"connection", "keep-alive", "proxy-connection", "te", "trailer", "upgrade", "expect", "cookie",
                 "authorization", "x-forwarded-for", "forwarded"}
_DROP_RESPONSE = {"connection", "keep-alive", "transfer-encoding", "content-type", "content-disposition",
                  "server", "date", "set-cookie"}
_SAFE_RESPONSE_HEADERS = (
    ("Content-Type", "application/octet-stream"),
    ("Content-Disposition", "attachment"),
    ("X-Content-Type-Options", "nosniff"),
    ("Content-Security-Policy", "sandbox; default-src 'none'"),
    ("Cache-Control", "no-store"),
)


def is_gateway_path(path: str) -> bool:
    return path == GATEWAY_PATH or path.startswith(GATEWAY_PATH + "/")


def forward(handler: BaseHTTPRequestHandler, storage_url: str, timeout_s: float = 120.0) -> None:
    """Send `handler`'s request to the storage server and its answer back, streaming both bodies."""
    if handler.command not in _METHODS:
        _plain(handler, 405, "only presigned downloads (GET) and upload forms (POST) pass here")
        return
    if "chunked" in handler.headers.get("Transfer-Encoding", "").lower():
        _plain(handler, 411, "send the upload with a Content-Length")
        return
    try:
        length = int(handler.headers.get("Content-Length") or 0)
    except ValueError:
        _plain(handler, 400, "Content-Length is not a number")
        return
    target = urlsplit(storage_url)
    assert target.hostname is not None, "the storage URL names a host"
    connection = http.client.HTTPConnection(target.hostname, target.port, timeout=timeout_s)
    try:
        connection.putrequest(handler.command, handler.path, skip_host=True, skip_accept_encoding=True)
        for name, value in handler.headers.items():
            if name.lower() not in _DROP_REQUEST:
                connection.putheader(name, value)
        connection.endheaders()
        remaining = length
        while remaining > 0:
            chunk = handler.rfile.read(min(_CHUNK, remaining))
            if not chunk:
                break  # the client went away mid-upload; storage sees a short body and refuses it
            connection.send(chunk)
            remaining -= len(chunk)
        answer = connection.getresponse()
        _relay(handler, answer)
    except OSError:
        handler.close_connection = True
        _plain(handler, 502, "drem's storage server is not answering")
    finally:
        connection.close()


def _relay(handler: BaseHTTPRequestHandler, answer: http.client.HTTPResponse) -> None:
    declared = answer.getheader("Content-Length")
    body = None if declared is not None else answer.read()  # moto always declares it; read if it ever does not
    handler.send_response(answer.status)
    for name, value in answer.getheaders():
        if name.lower() not in _DROP_RESPONSE and name.lower() != "content-length":
            handler.send_header(name, value)
    for name, value in _SAFE_RESPONSE_HEADERS:
        handler.send_header(name, value)
    handler.send_header("Content-Length", str(len(body)) if body is not None else str(declared))
    handler.end_headers()
    if handler.command == "HEAD":
        return
    if body is not None:
        handler.wfile.write(body)
        return
    while chunk := answer.read(_CHUNK):
        handler.wfile.write(chunk)


def _plain(handler: BaseHTTPRequestHandler, status: int, message: str) -> None:
    data = (message + "\n").encode()
    handler.send_response(status)
    handler.send_header("Content-Type", "text/plain; charset=utf-8")
    handler.send_header("X-Content-Type-Options", "nosniff")
    handler.send_header("Content-Length", str(len(data)))
    handler.end_headers()
    if handler.command != "HEAD":
        handler.wfile.write(data)
