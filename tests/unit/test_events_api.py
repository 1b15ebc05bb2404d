"""Events through the HTTP API: create, read, replace, delete, validation that names the field, the combined board,
and the refusal to delete while a race is live."""
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


def test_lap_count_ranking_with_target(api: Api) -> None:
    reply = api.post("/api/events", event_body(race_config={"ranking_method": "LAP_COUNT", "lap_count_target": 10}))
    assert reply.status_code == 201
    assert reply.data["race_config"]["lap_count_target"] == 10


def test_second_track_brings_combined_board_and_removing_it_drops_it(api: Api) -> None:
    fleet_id = api.fleet("Fleet A")
    two = event_body(tracks=[{"fleet_id": fleet_id, "leaderboard_title": "North"}, {"leaderboard_title": "South"}])
    event = api.post("/api/events", two).data
    assert [t["track_id"] for t in event["tracks"]] == ["1", "2"]
    assert event["tracks"][0]["fleet_id"] == fleet_id
    assert event["combined_board"] is True
    assert event["boards"] == ["1", "2", "combined"]

    one = event_body(tracks=[event["tracks"][0]])
    replaced = api.put(f"/api/events/{event['event_id']}", one)
    assert replaced.status_code == 200, replaced.data
    assert replaced.data["combined_board"] is False
    assert replaced.data["version"] == 2


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


def test_event_or_track_with_live_race_cannot_be_deleted(api: Api, aws_clients: Any) -> None:
    two = event_body(tracks=[{"leaderboard_title": "North"}, {"leaderboard_title": "South"}])
    event = api.post("/api/events", two).data
    _mark_live_race(aws_clients, event["event_id"], "2")

    refused = api.delete(f"/api/events/{event['event_id']}")
    assert refused.status_code == 409
    assert "race in progress" in refused.data["error"]["message"]
    dropping_track_2 = api.put(f"/api/events/{event['event_id']}", event_body(tracks=[event["tracks"][0]]))
    assert dropping_track_2.status_code == 409
    # Track 1 has no live race: it may go, and the event keeps its data.
    keep_2 = api.put(f"/api/events/{event['event_id']}", event_body(tracks=[event["tracks"][1]]))
    assert keep_2.status_code == 200
    assert [t["track_id"] for t in keep_2.data["tracks"]] == ["2"]
    assert api.get(f"/api/events/{event['event_id']}").status_code == 200


def test_event_stays_editable_after_its_fleet_is_deleted(api: Api) -> None:
    fleet_id = api.fleet("Gone soon")
    event = api.post("/api/events", event_body(tracks=[{"fleet_id": fleet_id}])).data
    assert api.delete(f"/api/fleets/{fleet_id}").status_code == 204
    renamed = api.put(f"/api/events/{event['event_id']}", event_body(name="Renamed", tracks=event["tracks"]))
    assert renamed.status_code == 200, renamed.data
    assert renamed.data["name"] == "Renamed"
