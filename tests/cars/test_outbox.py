from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from drem_cars.client import Rejected, Unreachable
from drem_cars.outbox import STRIP_EVENT, Outbox, OutboxItem

pytestmark = pytest.mark.unit


class FlakyServer:
    """Remembers what it accepted by idempotency key (as the API does) and can be switched off."""

    def __init__(self) -> None:
        self.up = True
        self.accepted: list[str] = []
        self.calls = 0
        self.lose_answer_once = False

    def send(self, item: OutboxItem) -> dict:
        self.calls += 1
        if not self.up:
            raise Unreachable("connection refused")
        if item.idempotency_key not in self.accepted:
            self.accepted.append(item.idempotency_key)
        if self.lose_answer_once:  # the request got through, the answer did not
            self.lose_answer_once = False
            raise Unreachable("read timed out")
        if item.body.get("bad"):
            raise Rejected("HTTP 400: sensor must be ≤ 1000")
        return {"ok": True}


def test_items_are_delivered_in_order_and_stop_at_the_first_that_cannot_go(tmp_path: Path) -> None:
    outbox = Outbox(tmp_path / "o.sqlite3")
    server = FlakyServer()
    for n in range(3):
        outbox.enqueue(STRIP_EVENT, {"n": n}, f"k{n}")
    server.up = False
    assert outbox.deliver(server.send) == 0
    assert server.calls == 1, "delivery stops at the first failure, so order is kept"
    server.up = True
    assert outbox.deliver(server.send) == 3
    assert server.accepted == ["k0", "k1", "k2"]
    assert outbox.count() == 0 and outbox.count("delivered") == 3


def test_a_lost_answer_redelivers_with_the_same_key_and_the_server_sees_it_once(tmp_path: Path) -> None:
    outbox = Outbox(tmp_path / "o.sqlite3")
    server = FlakyServer()
    outbox.enqueue(STRIP_EVENT, {"n": 1}, "k1")
    server.lose_answer_once = True
    outbox.deliver(server.send)
    outbox.deliver(server.send)
    assert server.calls == 2 and server.accepted == ["k1"]
    assert outbox.count() == 0


def test_a_rejected_item_is_set_aside_with_its_reason_and_does_not_block_the_rest(tmp_path: Path) -> None:
    outbox = Outbox(tmp_path / "o.sqlite3")
    server = FlakyServer()
    outbox.enqueue(STRIP_EVENT, {"bad": True}, "bad")
    outbox.enqueue(STRIP_EVENT, {"n": 2}, "good")
    assert outbox.deliver(server.send) == 2
    [(item, reason)] = outbox.rejected()
    assert item.idempotency_key == "bad" and "sensor must be" in reason


def test_enqueueing_the_same_key_twice_keeps_one_item(tmp_path: Path) -> None:
    outbox = Outbox(tmp_path / "o.sqlite3")
    outbox.enqueue(STRIP_EVENT, {"n": 1}, "same")
    outbox.enqueue(STRIP_EVENT, {"n": 1}, "same")
    assert outbox.count() == 1


WRITER = """
import sys, os
from drem_cars.outbox import Outbox, STRIP_EVENT
box = Outbox(sys.argv[1])
for n in range(5):
    box.enqueue(STRIP_EVENT, {"n": n}, f"k{n}")
os._exit(9)  # no close, no flush: like kill -9 right after the enqueues returned
"""


def test_queued_items_survive_a_killed_agent_and_go_out_once_in_order(tmp_path: Path) -> None:
    path = tmp_path / "o.sqlite3"
    first = Outbox(path)
    first.enqueue(STRIP_EVENT, {"n": -1}, "before")
    first.deliver(FlakyServer().send)  # delivered before the crash: must not go again
    first.close()
    done = subprocess.run([sys.executable, "-c", WRITER, str(path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 9, done.stderr
    server = FlakyServer()
    reopened = Outbox(path)
    assert reopened.deliver(server.send) == 5
    assert server.accepted == [f"k{n}" for n in range(5)]
    assert [json.dumps(i.body) for i in reopened.pending()] == []
