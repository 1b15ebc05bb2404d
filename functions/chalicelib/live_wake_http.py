"""The writer's wake-up over HTTP (chalicelib.live_wake, on AWS): POST the event id to the public live origin's
/live/wake with the stage's wake secret; CloudFront passes it to one live task, which relays it to the others.

A lap write never waits long on it: the POST runs in a thread the writer waits for at most BOUND_S (a Lambda frozen
after its answer lets the thread finish on its next invocation), one POST at a time: a wake-up that finds one in
flight is not waited for but remembered, and the same thread sends it right after (once per event however many
writes came meanwhile: a lap's second write is never left to the poll), and after a failure none is tried for
BACKOFF_S (the remembered ones are dropped: the live server's poll shows them), so a live service that is down or
slow costs one lap per BACKOFF_S its BOUND_S, not every lap. The connection is kept between
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
MAX_REMEMBERED = 64  # distinct events waiting behind the POST in flight (a Lambda writes for one event at a time)

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
        self._lock = threading.Lock()
        self._in_flight = False
        self._remembered: dict[str, None] = {}  # the events to wake once the POST in flight is answered, in order
        self._quiet_until = 0.0
        self._connection: http.client.HTTPConnection | None = None
        self.sent = self.failed = self.skipped = 0

    def __call__(self, event_id: str) -> None:
        with self._lock:
            if time.monotonic() < self._quiet_until:
                self.skipped += 1
                return
            if self._in_flight:
                if event_id in self._remembered or len(self._remembered) < MAX_REMEMBERED:
                    self._remembered[event_id] = None
                else:
                    self.skipped += 1
                return
            self._in_flight = True
        sender = threading.Thread(target=self._send_all, args=(event_id,), name="drem-live-wake", daemon=True)
        sender.start()
        sender.join(self._bound_s)

    @property
    def remembered(self) -> int:
        return len(self._remembered)

    def _send_all(self, event_id: str) -> None:
        """Send `event_id`, then whatever was remembered meanwhile, until nothing is left or a POST fails."""
        while True:
            ok = self._send(event_id)
            with self._lock:
                if not ok or not self._remembered:
                    self.skipped += len(self._remembered)
                    self._remembered.clear()
                    self._in_flight = False
                    return
                event_id = next(iter(self._remembered))
                del self._remembered[event_id]

    def _send(self, event_id: str) -> bool:
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
            return True
        except (OSError, http.client.HTTPException) as exc:
            self._quiet_until = time.monotonic() + self._backoff_s
            self.failed += 1
            log.warning("the live server was not woken (%s); its storage poll shows the change", exc)
            return False

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
