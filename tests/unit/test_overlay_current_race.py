"""The overlay and the commentator follow the track's current race: a lap edit in race admin of an older race must
not bring it back as "current" (issue 31: the commentator showed an old race after such an edit)."""
from __future__ import annotations

import json

import pytest

from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _overlay(desk: Desk, event_id: str) -> dict:
    return json.loads(desk.anonymous_get(f"/api/overlay/{event_id}").body)


def test_a_lap_edit_of_an_older_race_leaves_the_current_race_on_the_overlay(desk: Desk, scenario: Scenario) -> None:
    scenario.add_racers("vera", "omar").add_event()
    eid = scenario.event_id
    older = scenario.submitted_race("vera", [10_000, 11_000])
    newer = scenario.submitted_race("omar", [9_000])
    assert _overlay(desk, eid)["race_id"] == newer

    edited = desk.call("PUT", f"/api/events/{eid}/races/{older}/laps/0", {"time_ms": 8_500, "is_valid": True})
    assert edited.status_code == 200, edited.body
    overlay = _overlay(desk, eid)
    assert (overlay["race_id"], overlay["username"]) == (newer, "omar")
    # The edit itself counts: vera's 8.5 s now leads the board.
    assert desk.board(eid)["entries"][0]["username"] == "vera"

    # The live race always shows, and editing the race the overlay shows keeps it there with the new figures.
    live = scenario.add_race("vera", [12_000]).race_id
    assert _overlay(desk, eid)["race_id"] == live


def test_a_crash_replay_of_an_older_race_publishes_its_row_but_leaves_the_current_race_on_the_overlay(
        desk: Desk, scenario: Scenario, monkeypatch: pytest.MonkeyPatch) -> None:
    """The replay of a publish a crash cut off goes through the same step as the write: the board catches up, the
    overlay keeps showing the race after it (before, the replay put the older race back on the stream)."""
    from chalicelib import services
    from chalicelib.domain.races import RaceService

    scenario.add_racers("vera", "omar").add_event()
    eid = scenario.event_id
    with monkeypatch.context() as crash:
        crash.setattr(RaceService, "publish", lambda *args, **kwargs: None)  # dies before the board write
        scenario.submitted_race("vera", [10_000, 11_000])
    newer = scenario.submitted_race("omar", [9_000])  # its publish may already finish vera's (2 s old) intent

    services.race_service().complete_pending_publishes()  # what the sweeper runs

    assert sorted(e["username"] for e in desk.board(eid)["entries"]) == ["omar", "vera"]
    assert _overlay(desk, eid)["race_id"] == newer
