"""The app's repair sweep tells a storage restart (a crash: the journal was replayed) from the start time in the
storage server's health answer, so it finishes cut-off sign-ups at once instead of after the in-flight grace."""
from __future__ import annotations

import json

import pytest

from drem_local import stack
from drem_local.appserver import StorageRestarts

pytestmark = pytest.mark.unit


def test_a_new_start_time_is_a_restart_seen_once_and_an_unanswered_health_is_none(monkeypatch):
    def health(started_at: float) -> tuple[int, bytes]:
        return 200, json.dumps({"started_at": started_at}).encode()

    answers = iter([health(100.0), health(100.0), None, (503, b""), health(250.5), health(250.5)])
    monkeypatch.setattr(stack, "http_get", lambda url, timeout=2.0: next(answers))
    restarts = StorageRestarts("http://127.0.0.1:1")
    seen = [restarts.restarted_at() for _ in range(6)]
    assert seen == [None, None, None, None, 250.5, None]  # the first look is the app's own start: not a restart


def test_without_a_storage_url_there_is_nothing_to_watch():
    assert StorageRestarts(None).restarted_at() is None
