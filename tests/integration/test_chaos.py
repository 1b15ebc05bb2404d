"""Crash consistency over HTTP: an event's traffic (laps with retried idempotency keys, registrations, event creation)
while storage and app are killed -9 at random moments and restarted. After the retries nothing acknowledged is lost,
nothing counts twice, boards equal their races without a manual recompute, and no account is left half-registered.
The 20-round version with restart timings is `bench/chaos.py`."""
from __future__ import annotations

import pytest

from tests.chaos_harness import Chaos

pytestmark = [pytest.mark.integration, pytest.mark.durability]


def test_kill_9_at_random_moments_loses_nothing_and_leaves_nothing_half_done(tmp_path):
    chaos = Chaos(tmp_path / "state", seed=19)
    try:
        chaos.start()
        report = chaos.run(rounds=3)
    finally:
        chaos.close()

    assert report.errors == []
    assert (report.kills["storage"], report.kills["app"]) == (2, 1)
    assert report.laps_acknowledged > 0 and report.racers_acknowledged > 2 and report.events_acknowledged > 0
    assert (report.laps_lost, report.racers_lost, report.events_lost) == (0, 0, 0)
    assert (report.laps_duplicated, report.events_duplicated) == (0, 0)
    assert report.stale_boards == 0
    assert report.half_created_accounts == 0
    assert report.misleading_answers == []
