"""Race admin: the races of an event by track, lap edits (time, resets, validity) with errors next to the field,
delete with confirmation, and the CSV link."""
from __future__ import annotations

import json

import pytest

from tests.unit.operator_console_helpers import field_error, text_of
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _submitted_race(console, clock, event_id: str, racer: str, track: str = "1") -> str:
    return Scenario(console.desk, clock).submitted_race(racer, [12_345], track=track, event_id=event_id)


@pytest.fixture
def event(console, clock) -> dict:
    return Scenario(console.desk, clock).add_racers("ann", "bob").add_event(
        tracks=[{"track_id": "1"}, {"track_id": "2"}]).event


def test_races_are_listed_and_filtered_by_track(console, clock, event):
    _submitted_race(console, clock, event["event_id"], "ann", "1")
    _submitted_race(console, clock, event["event_id"], "bob", "2")
    console.sign_in("admin-web", "admin")

    everything = text_of(console.web.get(f"/console/races?event_id={event['event_id']}").body.decode())
    assert "ann" in everything and "bob" in everything and "0:12.345" in everything
    track_2 = console.web.get(f"/console/races?event_id={event['event_id']}&track=2").body.decode()
    assert "bob" in text_of(track_2) and "ann" not in text_of(track_2)
    assert f'href="/api/events/{event["event_id"]}/export/laps.csv"' in track_2


def test_a_lap_edit_is_saved_and_a_bad_time_is_shown_next_to_it(console, clock, event):
    race_id = _submitted_race(console, clock, event["event_id"], "ann")
    console.sign_in("op-web", "operator")
    base = f"/console/races/{event['event_id']}/{race_id}"

    saved = console.post(f"{base}/laps/0", {"time_s": "11.5", "resets": "2"})  # validity box left unticked
    assert saved.status_code == 303
    lap = json.loads(console.desk.call("GET", f"/api/events/{event['event_id']}/races/{race_id}").body)["laps"][0]
    assert (lap["time_ms"], lap["resets"], lap["is_valid"]) == (11_500, 2, False)

    bad = console.post(f"{base}/laps/0", {"time_s": "fast", "resets": "1", "is_valid": "on"})
    assert bad.status_code == 400
    assert field_error(bad.body.decode(), "lap-0-time_s") == "Write the lap time in seconds, e.g. 12.345."


def test_deleting_a_race_asks_first_and_takes_it_off_the_board(console, clock, event):
    race_id = _submitted_race(console, clock, event["event_id"], "ann")
    console.sign_in("op-web", "operator")
    base = f"/console/races/{event['event_id']}/{race_id}"
    assert "Delete this race of ann?" in text_of(console.web.get(f"{base}/delete").body.decode())

    assert console.post(f"{base}/delete", {}).status_code == 303

    assert console.desk.call("GET", f"/api/events/{event['event_id']}/races/{race_id}").status_code == 404
    assert console.desk.board(event["event_id"])["entries"] == []


def test_a_live_race_cannot_be_deleted_and_says_why(console, clock, event):
    race = console.desk.ok(console.desk.create_race(event["event_id"], "ann"), 201)
    console.sign_in("op-web", "operator")
    reply = console.post(f"/console/races/{event['event_id']}/{race['race_id']}/delete", {})
    assert reply.status_code == 409 and "end and discard it instead" in text_of(reply.body.decode())


def test_printed_results_are_linked_from_race_admin_and_download_as_pdf(console, clock, event, tmp_path):
    import re

    from tests.unit.pdf_helpers import pdf_text

    _submitted_race(console, clock, event["event_id"], "ann", "1")
    console.sign_in("admin-web", "admin")
    page = console.web.get(f"/console/races?event_id={event['event_id']}&track=1").body.decode()
    links = dict(re.findall(r'href="([^"]+)" data-testid="(pdf-\w+)"', page))
    summary = next(href for href, testid in links.items() if testid == "pdf-summary")
    assert summary == f"/api/events/{event['event_id']}/results/summary.pdf?track=1"
    # What a browser sends when following a link: */* among the accepted types.
    browser_accept = "text/html,application/xhtml+xml,application/xml;q=0.9,*/*;q=0.8"
    reply = console.web.get(summary.replace("&amp;", "&"), headers={"Accept": browser_accept})
    assert reply.status_code == 200 and reply.headers["Content-Type"] == "application/pdf"
    text = pdf_text(reply.body, tmp_path)
    assert "ann" in text and "0:12.345" in text and "Track 1" in text
