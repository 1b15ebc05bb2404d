"""The events screens: create with two tracks and fleets, errors next to the field, edit, delete with confirmation."""
from __future__ import annotations

import json
import re

import pytest

from tests.unit.operator_console_helpers import field_error

pytestmark = pytest.mark.unit

FORM = {"name": "Summit Stockholm", "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "se",
        "sponsor": "", "race_time_min": "3", "resets_per_lap": "", "track_type": "REINVENT_2018",
        "ranking_method": "BEST_LAP_TIME", "lap_count_target": "", "max_runs_per_racer": "3", "average_window": "3",
        "landing_page_links": "Upload | /upload | Upload a model",
        "track-1-use": "on", "track-1-track_id": "", "track-1-title": "Main track", "track-1-footer": "",
        "track-2-use": "on", "track-2-track_id": "", "track-2-title": "Second track", "track-2-footer": ""}


def _events(console) -> list[dict]:
    return json.loads(console.desk.call("GET", "/api/events").body)["events"]


def test_an_operator_creates_an_event_with_two_tracks_and_sees_it_listed(console):
    fleet = console.desk.fleet("Track 2 cars")
    console.sign_in("eve", "operator")

    reply = console.post("/console/events", {**FORM, "track-1-fleet_id": "", "track-2-fleet_id": fleet})

    assert reply.status_code == 303 and reply.headers["Location"] == "/console/events?done=event-created"
    [event] = _events(console)
    assert event["country_code"] == "SE" and event["race_config"]["race_time_min"] == 3
    assert event["race_config"]["resets_per_lap"] is None
    assert [(t["track_id"], t["fleet_id"], t["leaderboard_title"]) for t in event["tracks"]] == [
        ("1", None, "Main track"), ("2", fleet, "Second track")]
    listing = console.web.get("/console/events").body.decode()
    assert "Summit Stockholm" in listing and "Second track" in listing
    assert f'href="/leaderboard/{event["event_id"]}"' in listing
    assert f'href="/commentator/{event["event_id"]}"' in listing
    for track in ("1", "2"):  # every track its overlay link builder and timekeeper, not only track 1
        assert f'href="/console/events/{event["event_id"]}/overlay?track={track}"' in listing
        assert f'href="/console/timekeeper/{event["event_id"]}/{track}"' in listing


def test_bad_input_is_shown_next_to_each_field_and_nothing_typed_is_lost(console):
    console.sign_in("eve", "operator")

    reply = console.post("/console/events", {**FORM, "country_code": "XX", "race_time_min": "99",
                                             "track-2-fleet_id": "no-such-fleet", "track-1-fleet_id": ""})

    assert reply.status_code == 400
    html = reply.body.decode()
    assert field_error(html, "country_code").startswith("No country is called &#39;XX&#39;")
    assert field_error(html, "race_time_min")
    assert 'value="Summit Stockholm"' in html and 'value="Second track"' in html
    assert _events(console) == []


def test_an_unknown_fleet_is_named_next_to_its_track(console):
    console.sign_in("eve", "operator")
    reply = console.post("/console/events", {**FORM, "track-1-fleet_id": "", "track-2-fleet_id": "gone"})
    assert reply.status_code == 400
    assert field_error(reply.body.decode(), "track-2-fleet_id") == "There is no fleet gone."


def test_edit_keeps_track_ids_and_delete_asks_first(console):
    console.sign_in("eve", "operator")
    console.post("/console/events", {**FORM, "track-1-fleet_id": "", "track-2-fleet_id": ""})
    [event] = _events(console)
    event_id = event["event_id"]

    form_page = console.web.get(f"/console/events/{event_id}/edit").body.decode()
    assert 'value="Main track"' in form_page and "Save event" in form_page
    edited = {**FORM, "name": "Summit Stockholm 2026", "track-1-track_id": "1", "track-1-existing": "1",
              "track-2-track_id": "2", "track-2-existing": "1", "track-1-fleet_id": "", "track-2-fleet_id": "",
              "track-2-use": ""}
    assert console.post(f"/console/events/{event_id}", edited).status_code == 303
    [after] = _events(console)
    assert after["name"] == "Summit Stockholm 2026" and [t["track_id"] for t in after["tracks"]] == ["1"]

    confirm = console.web.get(f"/console/events/{event_id}/delete").body.decode()
    assert "Delete “Summit Stockholm 2026”?" in confirm
    assert console.post(f"/console/events/{event_id}/delete", {}).status_code == 303
    assert _events(console) == []


def test_only_operators_and_admins_see_the_events_screens(console):
    web = console.sign_in("reg", "registration")
    assert web.get("/console/events").status_code == 403
    anonymous = console.web
    anonymous.cookies.clear()
    reply = anonymous.get("/console/events")
    assert reply.status_code == 303 and reply.headers["Location"].startswith("/login")


def test_every_track_type_is_offered_by_its_name_up_to_re_invent_2024(console):
    """Issue 13, item 18: the track picker showed DREM's values and seemed to stop at 2023. Every track type has a
    label (none falls back to its de-shouted enum value), Forever Raceway says it is the re:Invent 2024 track, and an
    event saved with it shows that name in the list."""
    from drem_leaderboard.models import TrackType
    from drem_web.labels import LABELS

    assert all(track.value in LABELS for track in TrackType)
    console.sign_in("eve", "operator")
    form = console.web.get("/console/events/new").body.decode()
    picker = form.split('<select id="track_type"')[1].split("</select>")[0]
    offered = re.findall(r'<option value="([^"]*)"[^>]*>([^<]*)</option>', picker)
    assert [value for value, _ in offered] == [track.value for track in TrackType]
    names = [name for _, name in offered]
    assert names[:5] == ["re:Invent 2018", "re:Invent 2019", "re:Invent 2022", "re:Invent 2023",
                         "re:Invent 2024 · Forever Raceway"]
    reply = console.post("/console/events", {**FORM, "track_type": "FOREVER_RACEWAY", "track-1-fleet_id": "",
                                             "track-2-fleet_id": ""})
    assert reply.status_code == 303
    [event] = _events(console)
    assert event["race_config"]["track_type"] == "FOREVER_RACEWAY"
    listing = console.web.get("/console/events").body.decode()
    assert 'data-testid="event-track-type">re:Invent 2024 · Forever Raceway<' in listing
