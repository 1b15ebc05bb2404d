"""A durable, ordered outbox for what a device must tell the server (strip events, model status reports).

sqlite3 in WAL mode with `synchronous=FULL`: an `enqueue` has reached the disk when it returns, so a network cut, an
API restart or an agent restart (even kill -9) loses nothing. Items are delivered strictly in the order they were
queued; delivery stops at the first item the server cannot take right now and resumes from it later. Each item carries
an idempotency key chosen at enqueue time, so a redelivery after an unclear failure (the request got through, the
answer did not) is harmless: the server answers the repeat with its stored outcome.

An item the server rejects for good (a 4xx) is set aside as `rejected` with the reason, so one bad item cannot block
the line forever.
"""
from __future__ import annotations

import json
import sqlite3
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from drem_cars.client import Rejected, Unreachable

STRIP_EVENT = "strip_event"
MODEL_STATUS = "model_status"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS outbox (
    seq INTEGER PRIMARY KEY AUTOINCREMENT,
    kind TEXT NOT NULL,
    idempotency_key TEXT NOT NULL UNIQUE,
    body TEXT NOT NULL,
    queued_at REAL NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 0,
    state TEXT NOT NULL DEFAULT 'pending',   -- pending | delivered | rejected
    answer TEXT
)
"""


@dataclass(frozen=True)
class OutboxItem:
    seq: int
    kind: str
    idempotency_key: str
    body: dict[str, Any]
    attempts: int


Sender = Callable[[OutboxItem], Any]


class Outbox:
    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute("PRAGMA synchronous=FULL")
        self._db.execute(_SCHEMA)

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def enqueue(self, kind: str, body: dict[str, Any], idempotency_key: str | None = None) -> str:
        key = idempotency_key or body.get("idempotency_key") or uuid.uuid4().hex
        with self._lock:
            self._db.execute("INSERT OR IGNORE INTO outbox (kind, idempotency_key, body, queued_at) VALUES (?,?,?,?)",
                             (kind, key, json.dumps(body), time.time()))
        return key

    def pending(self, limit: int = 100) -> list[OutboxItem]:
        with self._lock:
            rows = self._db.execute("SELECT seq, kind, idempotency_key, body, attempts FROM outbox "
                                    "WHERE state = 'pending' ORDER BY seq LIMIT ?", (limit,)).fetchall()
        return [OutboxItem(seq, kind, key, json.loads(body), attempts) for seq, kind, key, body, attempts in rows]

    def count(self, state: str = "pending") -> int:
        with self._lock:
            return self._db.execute("SELECT COUNT(*) FROM outbox WHERE state = ?", (state,)).fetchone()[0]

    def rejected(self) -> list[tuple[OutboxItem, str]]:
        with self._lock:
            rows = self._db.execute("SELECT seq, kind, idempotency_key, body, attempts, answer FROM outbox "
                                    "WHERE state = 'rejected' ORDER BY seq").fetchall()
        return [(OutboxItem(s, k, key, json.loads(b), a), answer or "") for s, k, key, b, a, answer in rows]

    def _finish(self, item: OutboxItem, state: str, answer: str) -> None:
        with self._lock:
            self._db.execute("UPDATE outbox SET state = ?, answer = ?, attempts = attempts + 1 WHERE seq = ?",
                             (state, answer[:2000], item.seq))

    def _attempted(self, item: OutboxItem) -> None:
        with self._lock:
            self._db.execute("UPDATE outbox SET attempts = attempts + 1 WHERE seq = ?", (item.seq,))

    def deliver(self, send: Sender, limit: int = 100) -> int:
        """Send pending items in order until one cannot go now; returns how many were settled.

        `send` raises `Unreachable` (stop here, retry later) or `Rejected` (set aside); anything else it raises
        (a revoked credential) propagates with the item still pending."""
        settled = 0
        for item in self.pending(limit):
            try:
                answer = send(item)
            except Unreachable:
                self._attempted(item)
                return settled
            except Rejected as exc:
                self._finish(item, "rejected", str(exc))
                # Said where the operator watches the agent, not only in `drem car status`: a refused crossing
                # is a lap the board will not show.
                print(f"drem car: the server refused {item.kind} #{item.seq}: {exc}", file=sys.stderr, flush=True)
            else:
                self._finish(item, "delivered", json.dumps(answer)[:2000])
            settled += 1
        return settled
