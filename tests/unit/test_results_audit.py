"""The audit trail of results: every lap edit, validity toggle, race delete and recompute records who, when, before
and after; race admin shows it (per race on the race page, per event on the races page)."""
from __future__ import annotations

import re

import pytest

from tests.unit.operator_console_helpers import text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _trail(html: str) -> list[dict[str, str]]:
    """The rows of the audit table as a person reads them."""
    table = re.search(r'<table[^>]*data-testid="audit-trail".*?</table>', html, re.S)
    assert table, "the page shows no audit trail"
    rows = []
    for row in re.findall(r'<tr data-action="(\w+)">(.*?)</tr>', table.group(0), re.S):
        cells = [text_of(c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", row[1], re.S)]
        rows.append(dict(zip(["when", "who", "what", "racer", "lap", "before", "after"], cells, strict=True),
                         action=row[0]))
    return rows


def _race(console, clock, event_id: str, racer: str, laps: list[int], *, submit: bool = True) -> str:
    return Scenario(console.desk, clock).add_race(racer, laps, submit=submit, event_id=event_id).race_id


@pytest.fixture
def event_id(console, clock) -> str:
    return Scenario(console.desk, clock).add_racers("ann", "bob").add_event().event_id


def test_a_lap_edit_records_who_and_the_lap_before_and_after(console, clock, event_id):
    race_id = _race(console, clock, event_id, "ann", [12_345, 11_000])
    web = console.sign_in("op-web", "operator")
    page = f"/console/races/{event_id}/{race_id}"
    assert _trail(web.get(page).body.decode()) == []  # racing itself is not a correction

    assert console.post(f"{page}/laps/0", {"time_s": "11.5", "resets": "2"}).status_code == 303
    [entry] = _trail(web.get(page).body.decode())
    assert entry["who"] == "op-web" and entry["what"] == "Lap edited" and entry["racer"] == "ann"
    assert entry["lap"] == "1"
    assert entry["before"] == "0:12.345; 0 resets; valid" and entry["after"] == "0:11.500; 2 resets; invalid"
    assert re.fullmatch(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC", entry["when"])

    # A failed edit changes nothing and records nothing.
    assert console.post(f"{page}/laps/0", {"time_s": "fast", "resets": "1"}).status_code == 400
    assert len(_trail(web.get(page).body.decode())) == 1


def test_validity_toggles_by_the_timekeeper_and_the_api_are_recorded(console, clock, event_id):
    desk = console.desk
    race_id = _race(console, clock, event_id, "bob", [9_000, 9_500], submit=False)
    desk.ok(desk.command(event_id, race_id, "set_lap_validity", lap_id=1, is_valid=False))
    desk.ok(desk.command(event_id, race_id, "set_lap_validity", lap_id=1, is_valid=False))  # no change: no entry
    clock.advance(1_000)
    desk.ok(desk.call("PUT", f"/api/events/{event_id}/races/{race_id}/laps/1", {"is_valid": True}))

    web = console.sign_in("admin-web", "admin")
    trail = _trail(web.get(f"/console/races/{event_id}/{race_id}").body.decode())
    assert [(e["what"], e["who"], e["before"], e["after"]) for e in trail] == [
        ("Lap edited", "op", "0:09.500; 0 resets; invalid", "0:09.500; 0 resets; valid"),
        ("Lap validity changed", "op", "0:09.500; 0 resets; valid", "0:09.500; 0 resets; invalid")]


def test_a_deleted_race_and_a_recompute_show_on_the_event_trail(console, clock, event_id):
    desk = console.desk
    ann = _race(console, clock, event_id, "ann", [10_000])
    _race(console, clock, event_id, "bob", [10_500])
    web = console.sign_in("op-web", "operator")
    assert console.post(f"/console/races/{event_id}/{ann}/delete", {}).status_code == 303
    clock.advance(1_000)
    desk.ok(desk.call("POST", f"/api/events/{event_id}/recompute"))

    trail = _trail(web.get(f"/console/races?event_id={event_id}").body.decode())
    assert [e["action"] for e in trail] == ["recompute", "race_delete"]
    recompute, deleted = trail
    assert deleted["who"] == "op-web" and deleted["racer"] == "ann"
    assert deleted["before"] == "SUBMITTED, 1 laps, fastest 0:10.000" and deleted["after"] == "—"
    # The board was already right (deleting refreshed it); the recompute shows it unchanged, per board.
    assert recompute["who"] == "op" and recompute["before"] == "1: 1 bob 0:10.500; combined: 1 bob 0:10.500"
    assert recompute["after"] == recompute["before"]
