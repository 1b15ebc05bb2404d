"""The statistics page: public events for everyone, staff-only events for signed-in staff, a world map drawn from the
country-shapes package, and filters (direction, country, dates) that are a plain GET form."""
from __future__ import annotations

import json
import re

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
