"""The public leaderboard and overlay polls: anyone may read them, and conditional requests answer 304."""
from __future__ import annotations

import json

import pytest

from tests.unit.race_helpers import Desk, FakeClock
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _live_race_with_a_lap(scenario: Scenario, racer: str = "vera") -> tuple[str, str]:
    scenario.add_racers(racer).add_event().add_race(racer, laps=[10_000])
    return scenario.event_id, scenario.race_id


def test_conditional_get_answers_304_until_the_board_changes(desk: Desk, clock: FakeClock,
                                                             scenario: Scenario) -> None:
    eid, rid = _live_race_with_a_lap(scenario)
    first = desk.anonymous_get(f"/api/leaderboard/{eid}?track=1")
    assert first.status_code == 200
    etag, body = first.headers["ETag"], json.loads(first.body)
    assert etag == f'"v{body["version"]}"'
    unchanged = desk.anonymous_get(f"/api/leaderboard/{eid}?track=1", headers={"If-None-Match": etag})
    assert unchanged.status_code == 304 and unchanged.body == b""
    # A cache that holds several versions sends them all, weak ones marked W/ (RFC 9110 13.1.2).
    among_others = desk.anonymous_get(f"/api/leaderboard/{eid}?track=1", headers={"If-None-Match": f'"v0", W/{etag}'})
    assert among_others.status_code == 304
    since = desk.anonymous_get(f"/api/leaderboard/{eid}?track=1&since={body['version']}")
    assert since.status_code == 304 and since.body == b""

    desk.ok(desk.command(eid, rid, "reset_add"))  # nothing a viewer sees on the board changes
    assert desk.anonymous_get(f"/api/leaderboard/{eid}?track=1", headers={"If-None-Match": etag}).status_code == 304

    clock.advance(9_000)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    changed = desk.anonymous_get(f"/api/leaderboard/{eid}?track=1", headers={"If-None-Match": etag})
    assert changed.status_code == 200 and changed.headers["ETag"] != etag
    assert json.loads(changed.body)["version"] > body["version"]
    assert desk.anonymous_get(f"/api/leaderboard/{eid}?track=1&since={body['version']}").status_code == 200


def test_board_without_track_is_the_combined_board(desk: Desk, scenario: Scenario) -> None:
    eid, _ = _live_race_with_a_lap(scenario, "walt")
    board = desk.ok(desk.anonymous_get(f"/api/leaderboard/{eid}"))
    assert board["track_id"] == "combined" and [e["username"] for e in board["entries"]] == ["walt"]


def test_unknown_board_is_empty_not_an_error(desk: Desk, clock: FakeClock) -> None:
    reply = desk.anonymous_get("/api/leaderboard/nope?track=1")
    assert reply.status_code == 200 and json.loads(reply.body)["entries"] == []
    assert reply.headers["ETag"] == '"v0"'


def test_overlay_follows_the_live_race(desk: Desk, scenario: Scenario) -> None:
    eid, rid = _live_race_with_a_lap(scenario, "xena")
    overlay = desk.anonymous_get(f"/api/overlay/{eid}?track=1")
    state = json.loads(overlay.body)
    assert (state["status"], state["username"], state["laps"], state["last_lap_ms"], state["position"]) == (
        "RUNNING", "xena", 1, 10_000, 1)
    assert state["running"] is True and state["time_left_ms"] == 2 * 60_000 - 10_000
    assert desk.anonymous_get(f"/api/overlay/{eid}?track=1",
                              headers={"If-None-Match": overlay.headers["ETag"]}).status_code == 304
    desk.ok(desk.command(eid, rid, "pause"))
    paused = desk.anonymous_get(f"/api/overlay/{eid}?track=1", headers={"If-None-Match": overlay.headers["ETag"]})
    assert paused.status_code == 200 and json.loads(paused.body)["status"] == "PAUSED"
    assert json.loads(desk.anonymous_get("/api/overlay/none?track=1").body)["status"] == "NO_RACE"


def test_board_names_come_from_profiles_and_deleted_racers_are_anonymised(desk: Desk, scenario: Scenario) -> None:
    from chalicelib.domain.profiles import Profile, anonymised_name
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.profiles import DynamoProfileStore

    store = DynamoProfileStore(clients.dynamodb(), get_settings().table("profiles"))
    desk.users.create("yuri", ("racer",))
    sub = next(a["Value"] for a in desk.users.clients.cognito.admin_get_user(
        UserPoolId=desk.users.outputs.user_pool_id, Username="yuri")["UserAttributes"] if a["Name"] == "sub")
    store.put(Profile(sub=sub, username="yuri", country_code="SE", highlight_colour="#FF0000"))
    eid = scenario.add_event().add_race("yuri", laps=[10_000]).event_id
    entry = desk.board(eid)["entries"][0]
    assert (entry["username"], entry["country_code"], entry["highlight_colour"]) == ("yuri", "SE", "#FF0000")

    store.put(Profile(sub=sub, deleted=True, avatar="none"))
    desk.ok(desk.call("POST", f"/api/events/{eid}/recompute"))
    entry = desk.board(eid)["entries"][0]
    assert (entry["username"], entry["country_code"]) == (anonymised_name(sub), None)
