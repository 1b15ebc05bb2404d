"""Events through the HTTP API: who may read and change them, the JSON they are answered with, and how refusals
reach the caller (400 naming the field, 404, 409). The rules themselves (track numbers, the combined board, live
races, version conflicts) are tested on the fast domain tier, tests/domain/test_event_rules.py."""
from __future__ import annotations

from typing import Any

import pytest

from tests.unit.device_api import Api

pytestmark = pytest.mark.unit


def event_body(**overrides: Any) -> dict[str, Any]:
    body: dict[str, Any] = {
        "name": "Stockholm Summit", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "se",
        "sponsor": "ACME", "race_config": {"race_time_min": 3, "resets_per_lap": 9999,
                                           "ranking_method": "BEST_AVERAGE_LAP_TIME_X_LAP", "average_window": 5},
        "tracks": [{"leaderboard_title": "Main track"}],
    }
    body.update(overrides)
    return body


def test_operator_creates_event_and_staff_read_it(api: Api) -> None:
    created = api.post("/api/events", event_body())
    assert created.status_code == 201, created.data
    event = created.data
    assert event["country_code"] == "SE"
    assert event["race_config"]["race_time_min"] == 3
    assert event["race_config"]["resets_per_lap"] is None  # DREM's 9999 = unlimited
    assert event["tracks"] == [{"track_id": "1", "fleet_id": None, "leaderboard_title": "Main track",
                                "leaderboard_footer": "Follow the race #AWSDeepRacer",
                                "direction": "counter_clockwise"}]
    assert event["combined_board"] is False
    assert event["stats_visibility"] == "public"  # the default: the event counts on the public /stats page
    assert event["landing_page_links"][0]["href"] == "/console/my-models"  # a page racers may open

    for reader in ("commentator", "registration", "admin"):
        listed = api.get("/api/events", as_=reader)
        assert listed.status_code == 200
        assert [e["event_id"] for e in listed.data["events"]] == [event["event_id"]]
    assert api.get(f"/api/events/{event['event_id']}", as_="commentator").data["name"] == "Stockholm Summit"


def test_racers_and_commentators_cannot_change_events(api: Api) -> None:
    assert api.post("/api/events", event_body(), as_="racer").status_code == 403
    assert api.post("/api/events", event_body(), as_="commentator").status_code == 403
    assert api.get("/api/events", as_="racer").status_code == 403
    assert api.get("/api/events", as_=None).status_code == 401


@pytest.mark.parametrize(("change", "field"), [
    ({"race_config": {"race_time_min": 11}}, "race_config.race_time_min"),
    ({"race_config": {"average_window": 8}}, "race_config.average_window"),
    ({"race_config": {"resets_per_lap": 11}}, "race_config.resets_per_lap"),
    ({"race_config": {"ranking_method": "FASTEST_EVER"}}, "race_config.ranking_method"),
    ({"race_config": {"track_type": "MOON_BASE"}}, "race_config.track_type"),
    ({"event_type": "PARTY"}, "event_type"),
    ({"country_code": "XX"}, "country_code"),
    ({"date": "14/05/2026"}, "date"),
    ({"name": ""}, "name"),
    ({"tracks": []}, "tracks"),
])
def test_invalid_event_is_refused_naming_the_field(api: Api, change: dict, field: str) -> None:
    reply = api.post("/api/events", event_body(**change))
    assert reply.status_code == 400
    assert field in reply.data["error"]["fields"], reply.data
    assert field in reply.data["error"]["message"]
    assert api.get("/api/events").data["events"] == []


def test_unknown_fleet_on_a_track_is_refused(api: Api) -> None:
    reply = api.post("/api/events", event_body(tracks=[{"fleet_id": "nope"}]))
    assert reply.status_code == 400
    assert reply.data["error"]["field"] == "tracks.0.fleet_id"


def test_delete_event(api: Api) -> None:
    event_id = api.post("/api/events", event_body()).data["event_id"]
    assert api.delete(f"/api/events/{event_id}").status_code == 204
    assert api.get(f"/api/events/{event_id}").status_code == 404
    assert api.delete(f"/api/events/{event_id}").status_code == 404


def _mark_live_race(aws_clients: Any, event_id: str, track_id: str) -> None:
    from chalicelib.settings import get_settings

    aws_clients.dynamodb.put_item(TableName=get_settings().table("races"), Item={
        "pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": f"LIVE#{track_id}"}, "raceId": {"S": "r1"}})


def test_a_refusal_for_a_live_race_is_a_409_that_says_why(api: Api, aws_clients: Any) -> None:
    event = api.post("/api/events", event_body()).data
    _mark_live_race(aws_clients, event["event_id"], "1")

    refused = api.delete(f"/api/events/{event['event_id']}")
    assert refused.status_code == 409
    assert "race in progress" in refused.data["error"]["message"]
    assert api.get(f"/api/events/{event['event_id']}").status_code == 200


def test_operator_replaces_an_event_and_a_racer_may_not(api: Api) -> None:
    event = api.post("/api/events", event_body()).data
    path = f"/api/events/{event['event_id']}"
    assert api.put(path, event_body(name="Renamed"), as_="racer").status_code == 403
    replaced = api.put(path, event_body(name="Renamed", tracks=event["tracks"]))
    assert replaced.status_code == 200, replaced.data
    assert (replaced.data["name"], replaced.data["version"]) == ("Renamed", 2)
    assert api.get(path, as_="commentator").data["name"] == "Renamed"
