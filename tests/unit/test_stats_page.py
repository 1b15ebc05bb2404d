"""The statistics page: public events for everyone, staff-only events for signed-in staff, a world map drawn from the
country-shapes package, and filters (direction, country, dates) that are a plain GET form."""
from __future__ import annotations

import json
import re
from typing import Any

import pytest

from tests.unit.race_helpers import Desk
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit

HTML = {"Accept": "text/html"}


def _event(desk: Desk, name: str, country: str, day: str, *, visibility: str, direction: str,
           event_type: str = "AWS_SUMMIT", track_type: str = "REINVENT_2018") -> str:
    body = {"name": name, "event_type": event_type, "date": day, "country_code": country,
            "race_config": {"track_type": track_type, "min_lap_ms": 0}, "stats_visibility": visibility,
            "tracks": [{"track_id": "1", "direction": direction}]}
    return desk.ok(desk.call("POST", "/api/events", body), 201)["event_id"]


def _cards(page: str) -> dict[str, str]:
    return {label: value for value, label in re.findall(
        r'<span class="stat-value">([^<]*)</span><span class="stat-label">([^<]*)</span>', page)}


def _fastest(page: str) -> list[tuple[str, str, str]]:
    table = re.search(r'data-testid="stats-fastest">(.*?)</table>', page, re.S).group(1)
    return [(cells[1], cells[2], cells[3]) for cells in
            (re.findall(r"<td[^>]*>([^<]*)</td>", row) for row in re.findall(r"<tr>(.*?)</tr>", table, re.S))
            if len(cells) == 7]


def _map_values(page: str) -> dict[str, str]:
    return dict(re.findall(r'data-country="([A-Z]{2})" data-value="(\d+)"', page))


@pytest.fixture
def raced_events(desk: Desk, scenario: Scenario) -> Desk:
    """Three events, each with one submitted race: two public (one a test event), one staff-only."""
    scenario.add_racers("sven", "amy", "tess")
    stockholm = _event(desk, "Summit Stockholm", "SE", "2026-05-14", visibility="public", direction="clockwise")
    austin = _event(desk, "Austin private cup", "US", "2026-06-20", visibility="staff",
                    direction="counter_clockwise", event_type="PRIVATE_TRACK_RACE")
    trial = _event(desk, "Dry run", "GB", "2026-05-01", visibility="public", direction="clockwise",
                   event_type="TEST_EVENT")
    scenario.submitted_race("sven", [9_120, 8_838, 4_000], event_id=stockholm)  # the 4.0 s lap is a timing artefact
    scenario.submitted_race("amy", [7_500], event_id=austin)
    scenario.submitted_race("tess", [6_000], event_id=trial)
    return desk


def test_anyone_sees_the_public_events_only(raced_events: Desk) -> None:
    reply = raced_events.anonymous_get("/stats", headers=HTML)
    assert reply.status_code == 200
    page = reply.body.decode()
    cards = _cards(page)
    assert (cards["Events"], cards["Racers"], cards["Valid laps"], cards["Countries"]) == ("1", "1", "2", "1")
    assert _fastest(page) == [("sven", "0:08.838", "Summit Stockholm")]
    assert "Austin" not in page and "amy" not in page and "Dry run" not in page
    assert _map_values(page) == {"SE": "1"}
    assert re.search(r'<g fill="#[0-9a-f]{6}" data-country="SE" data-value="1"><title>Sweden: 1 events</title>',
                     page)
    assert page.count("data-country=") > 200  # every country of the package's map is drawn


def test_staff_also_see_staff_only_events_and_filter_without_javascript(raced_events: Desk) -> None:
    raced_events.token("com", "commentator")
    page = raced_events.call("GET", "/stats", as_user="com", headers=HTML).body.decode()
    assert _fastest(page) == [("amy", "0:07.500", "Austin private cup"), ("sven", "0:08.838", "Summit Stockholm")]
    assert _map_values(page) == {"SE": "1", "US": "1"}

    def filtered(query: str) -> str:
        return raced_events.call("GET", f"/stats?{query}", as_user="com", headers=HTML).body.decode()

    assert [r[0] for r in _fastest(filtered("direction=clockwise"))] == ["sven"]
    assert [r[0] for r in _fastest(filtered("country=US"))] == ["amy"]
    assert [r[0] for r in _fastest(filtered("from=2026-06-01&to=2026-12-31"))] == ["amy"]
    kept = filtered("country=US&direction=counter_clockwise")
    assert '<option value="US" selected>' in kept and '<option value="counter_clockwise" selected>' in kept
    assert _cards(filtered("country=SE&direction=counter_clockwise"))["Events"] == "0"


def test_a_bad_filter_is_a_clear_400(raced_events: Desk) -> None:
    reply = raced_events.anonymous_get("/stats?country=Sweden", headers={"Accept": "application/json"})
    assert reply.status_code == 400
    assert "country" in json.dumps(json.loads(reply.body))


# --- the stored digests: what /stats reads instead of every race ---------------------------------------------------


def _stored_digest(event_id: str) -> dict | None:
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients

    item = clients.dynamodb().get_item(TableName=get_settings().table("races"),
                                       Key={"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": "STATS"}}).get("Item")
    return json.loads(item["doc"]["S"]) if item else None


def _race_id(desk: Desk, event_id: str, racer: str) -> str:
    races = desk.ok(desk.call("GET", f"/api/events/{event_id}/races"))["races"]
    return next(r["race_id"] for r in races if r["username"] == racer)


def test_the_page_follows_submits_edits_and_deletes_through_the_digest(raced_events: Desk, scenario: Scenario,
                                                                       clock: Any) -> None:
    stockholm = next(e["event_id"] for e in raced_events.ok(raced_events.call("GET", "/api/events"))["events"]
                     if e["name"] == "Summit Stockholm")
    assert [r["username"] for r in _stored_digest(stockholm)["races"]] == ["sven"]  # built when the race was submitted

    scenario.add_racers("nora").submitted_race("nora", [8_500], event_id=stockholm)
    page = raced_events.anonymous_get("/stats", headers=HTML).body.decode()
    assert _cards(page)["Racers"] == "2" and _fastest(page)[0] == ("nora", "0:08.500", "Summit Stockholm")

    nora = _race_id(raced_events, stockholm, "nora")
    race = f"/api/events/{stockholm}/races/{nora}"
    lap_id = raced_events.ok(raced_events.call("GET", race))["laps"][0]["lap_id"]
    raced_events.ok(raced_events.call("PUT", f"{race}/laps/{lap_id}", {"is_valid": False}))
    page = raced_events.anonymous_get("/stats", headers=HTML).body.decode()
    assert _fastest(page)[0] == ("sven", "0:08.838", "Summit Stockholm")  # nora's only lap no longer counts

    assert raced_events.call("DELETE", f"/api/events/{stockholm}/races/{nora}").status_code == 204
    page = raced_events.anonymous_get("/stats", headers=HTML).body.decode()
    assert _cards(page)["Racers"] == "1" and [r["username"] for r in _stored_digest(stockholm)["races"]] == ["sven"]


def test_a_digest_lost_to_a_crash_is_rebuilt_by_the_publish_intent(raced_events: Desk, scenario: Scenario, clock: Any,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """Storage fails right after the race write (the digest write is lost): the race's publish intent stays, and
    the next race write finishes it, digest included, with no recompute by hand."""
    from chalicelib.core.errors import ServiceUnavailable
    from chalicelib.storage.race_stats import DynamoStatsDigestStore

    stockholm = next(e["event_id"] for e in raced_events.ok(raced_events.call("GET", "/api/events"))["events"]
                     if e["name"] == "Summit Stockholm")
    scenario.add_racers("nora")
    real_put = DynamoStatsDigestStore.put

    def storage_down(self, digest, listed_at_ms):  # type: ignore[no-untyped-def]
        raise ServiceUnavailable("The races table cannot be reached.")

    monkeypatch.setattr(DynamoStatsDigestStore, "put", storage_down)
    scenario.submitted_race("nora", [8_500], event_id=stockholm)  # acknowledged: the race is stored with its intent
    assert [r["username"] for r in _stored_digest(stockholm)["races"]] == ["sven"]  # the digest is behind

    monkeypatch.setattr(DynamoStatsDigestStore, "put", real_put)
    clock.advance(60_000)  # the intent is old enough for any writer to finish it
    scenario.add_racers("olle").submitted_race("olle", [9_900], event_id=stockholm)
    assert sorted(r["username"] for r in _stored_digest(stockholm)["races"]) == ["nora", "olle", "sven"]


def test_an_older_rebuild_never_overwrites_a_newer_digest(raced_events: Desk) -> None:
    from chalicelib import services
    from chalicelib.domain.stats import EventDigest
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.race_stats import DynamoStatsDigestStore

    store = DynamoStatsDigestStore(clients.dynamodb(), get_settings().table("races"))
    newer = services.stats_digests().refresh("later-event")  # an event with no races: an empty digest
    store.put(EventDigest(event_id="later-event", races=newer.races), listed_at_ms=2 * 10**13)
    store.put(EventDigest(event_id="later-event", races=()), listed_at_ms=10**13)  # built from an older listing
    assert _stored_digest("later-event") is not None
    assert store.digests(["later-event"])["later-event"] == newer


def test_an_event_without_a_digest_gets_one_on_the_first_read(raced_events: Desk) -> None:
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients

    stockholm = next(e["event_id"] for e in raced_events.ok(raced_events.call("GET", "/api/events"))["events"]
                     if e["name"] == "Summit Stockholm")
    clients.dynamodb().delete_item(TableName=get_settings().table("races"),
                                   Key={"pk": {"S": f"EVENT#{stockholm}"}, "sk": {"S": "STATS"}})  # e.g. imported
    page = raced_events.anonymous_get("/stats", headers=HTML).body.decode()
    assert _fastest(page) == [("sven", "0:08.838", "Summit Stockholm")]
    assert _stored_digest(stockholm) is not None
