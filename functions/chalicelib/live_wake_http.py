"""The writer's wake-up over HTTP (chalicelib.live_wake, on AWS): POST the event id to the public live origin's
/live/wake with the stage's wake secret; CloudFront passes it to one live task, which relays it to the others.

A lap write never waits long on it: the POST runs in a thread the writer waits for at most BOUND_S (a Lambda frozen
after its answer lets the thread finish on its next invocation), one POST at a time (a wake-up that finds one in
flight is dropped: the live server's poll catches up), and after a failure none is tried for BACKOFF_S, so a live
service that is down or slow costs one lap per BACKOFF_S its BOUND_S, not every lap. The connection is kept between
wake-ups (TLS once per Lambda environment, not per lap).
"""
from __future__ import annotations

import http.client
import logging
import threading
import time
from urllib.parse import urlsplit

from chalicelib.live_wake import WAKE_SECRET_HEADER

BOUND_S = 0.25  # the longest a lap write waits for its wake-up
SOCKET_TIMEOUT_S = 2.0  # the longest the thread behind it holds the one connection
BACKOFF_S = 5.0

log = logging.getLogger(__name__)


class HttpWaker:
    def __init__(self, url: str, secret: str, *, bound_s: float = BOUND_S, backoff_s: float = BACKOFF_S,
                 socket_timeout_s: float = SOCKET_TIMEOUT_S) -> None:
        parts = urlsplit(url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"the live server's wake URL must be http(s)://host/…, not {url!r}")
        self._scheme, self._host, self._port = parts.scheme, parts.hostname, parts.port
        self._path = parts.path or "/"
        self._secret = secret
        self._bound_s, self._backoff_s, self._socket_timeout_s = bound_s, backoff_s, socket_timeout_s
        self._busy = threading.Lock()
        self._quiet_until = 0.0
        self._connection: http.client.HTTPConnection | None = None
        self.sent = self.failed = self.skipped = 0

    def __call__(self, event_id: str) -> None:
        if time.monotonic() < self._quiet_until or not self._busy.acquire(blocking=False):
            self.skipped += 1
            return
        sender = threading.Thread(target=self._send, args=(event_id,), name="drem-live-wake", daemon=True)
        sender.start()
        sender.join(self._bound_s)

    def _send(self, event_id: str) -> None:
        try:
            kept = self._connection is not None
            try:
                status = self._post(event_id.encode())
            except (OSError, http.client.HTTPException):
                self._close()
                if not kept:
                    raise
                status = self._post(event_id.encode())  # the kept connection was closed by the other end: anew
            if status >= 300:
                raise OSError(f"the live server answered {status}")
            self.sent += 1
        except (OSError, http.client.HTTPException) as exc:
            self._quiet_until = time.monotonic() + self._backoff_s
            self.failed += 1
            log.warning("the live server was not woken (%s); its storage poll shows the change", exc)
        finally:
            self._busy.release()

    def _post(self, body: bytes) -> int:
        if self._connection is None:
            kind = http.client.HTTPSConnection if self._scheme == "https" else http.client.HTTPConnection
            self._connection = kind(self._host, self._port, timeout=self._socket_timeout_s)
        self._connection.request("POST", self._path, body=body, headers={
            WAKE_SECRET_HEADER: self._secret, "Content-Type": "text/plain"})
        response = self._connection.getresponse()
        response.read()
        return response.status

    def _close(self) -> None:
        if self._connection is not None:
            self._connection.close()
            self._connection = None
