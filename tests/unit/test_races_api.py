"""Races through the JSON API: a full race with the board item updated on every lap, the 400/404/409 answers of a bad
command or an unknown racer, track or event, race admin edits/deletes/recompute, and the CSV exports. The rules
(max runs and their override, one live race per track, who reads which race, discarded races) are
tests/domain/test_race_rules.py's, on the in-memory stores; who may call each route is the authorization matrix's."""
from __future__ import annotations

import csv
import io
import json

import pytest

from tests.unit.race_helpers import Desk, FakeClock
from tests.unit.scenario import Scenario

pytestmark = pytest.mark.unit


def _board_item(aws_clients, event_id: str, track: str = "1") -> dict:
    from drem_infra.resources import table_name

    item = aws_clients.dynamodb.get_item(TableName=table_name("test", "leaderboards"),
                                         Key={"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": f"BOARD#{track}"}})["Item"]
    return {"version": int(item["version"]["N"]), "body": json.loads(item["body"]["S"])}


def test_full_race_updates_the_board_item_after_every_lap(desk: Desk, clock: FakeClock, aws_clients) -> None:
    desk.users.create("alice", ("racer",))
    event = desk.event(race_time_min=4, resets_per_lap=2)
    eid = event["event_id"]
    race = desk.ok(desk.create_race(eid, "alice"), 201)
    rid = race["race_id"]
    assert race["status"] == "READY" and race["config"]["race_time_min"] == 4

    desk.ok(desk.command(eid, rid, "start"))
    versions = []
    clock.advance(10_000)
    lap0 = desk.ok(desk.command(eid, rid, "capture_lap"))
    assert lap0["outcome"]["lap"]["time_ms"] == 10_000
    versions.append(_board_item(aws_clients, eid)["version"])
    assert desk.board(eid)["entries"][0]["fastest_lap_ms"] == 10_000  # live laps are on the board

    desk.ok(desk.command(eid, rid, "reset_add"))
    desk.ok(desk.command(eid, rid, "reset_add"))
    desk.ok(desk.command(eid, rid, "reset_add"))
    clock.advance(8_000)
    lap1 = desk.ok(desk.command(eid, rid, "capture_lap"))["outcome"]["lap"]
    assert lap1 == {**lap1, "time_ms": 8_000, "resets": 3, "is_valid": False}  # 3 resets > 2 allowed
    versions.append(_board_item(aws_clients, eid)["version"])

    clock.advance(9_000)
    desk.ok(desk.command(eid, rid, "capture_lap"))
    versions.append(_board_item(aws_clients, eid)["version"])
    assert desk.board(eid)["entries"][0]["fastest_lap_ms"] == 9_000

    clock.advance(500)  # a false finish half a second later: undo gives the time back to the running lap
    desk.ok(desk.command(eid, rid, "capture_lap"))
    undone = desk.ok(desk.command(eid, rid, "undo_false_finish"))
    assert len(undone["laps"]) == 3 and undone["current_lap_ms"] == 500
    assert desk.board(eid)["entries"][0]["fastest_lap_ms"] == 9_000

    clock.advance(3_000)
    dnf = desk.ok(desk.command(eid, rid, "dnf"))
    assert dnf["status"] == "PAUSED" and dnf["laps"][-1]["is_valid"] is False
    versions.append(_board_item(aws_clients, eid)["version"])
    assert versions == sorted(versions) and len(set(versions)) == len(versions)

    desk.ok(desk.command(eid, rid, "end"))
    submitted = desk.ok(desk.command(eid, rid, "submit"))
    assert submitted["status"] == "SUBMITTED"
    entry = desk.board(eid)["entries"][0]
    assert (entry["username"], entry["fastest_lap_ms"], entry["laps"], entry["is_dnf"]) == ("alice", 9_000, 2, False)
    # The track is free again: the next race can start.
    desk.ok(desk.create_race(eid, "alice"), 201)


def test_illegal_command_is_a_clear_conflict(desk: Desk, scenario: Scenario) -> None:
    scenario.add_racers("bob").add_event().add_race("bob", start=False)
    eid, rid = scenario.event_id, scenario.race_id
    reply = desk.command(eid, rid, "capture_lap")
    assert reply.status_code == 409
    assert json.loads(reply.body)["error"]["message"] == "cannot capture a lap: the race has not started"
    assert desk.command(eid, rid, "warp_speed").status_code == 400


def test_unknown_racer_track_and_event_are_clear_errors(desk: Desk, clock: FakeClock) -> None:
    eid = desk.event()["event_id"]
    assert desk.create_race(eid, "nobody").status_code == 404
    desk.users.create("hal", ("racer",))
    wrong_track = desk.create_race(eid, "hal", "9")
    assert wrong_track.status_code == 404 and json.loads(wrong_track.body)["error"]["field"] == "track_id"
    assert desk.create_race("no-such-event", "hal").status_code == 404
    missing = desk.call("POST", f"/api/events/{eid}/races", {"racer_username": "hal"})
    assert missing.status_code == 400 and json.loads(missing.body)["error"]["field"] == "track_id"


def test_edit_lap_and_delete_race_recompute_the_board(desk: Desk, scenario: Scenario) -> None:
    eid = scenario.add_racers("lea", "max").add_event().event_id
    lea = scenario.submitted_race("lea", [11_000, 10_000])
    scenario.submitted_race("max", [10_500])
    assert [e["username"] for e in desk.board(eid)["entries"]] == ["lea", "max"]

    edited = desk.ok(desk.call("PUT", f"/api/events/{eid}/races/{lea}/laps/1", {"is_valid": False}))
    assert edited["laps"][1]["is_valid"] is False
    assert [(e["username"], e["time_ms"]) for e in desk.board(eid)["entries"]] == [("max", 10_500), ("lea", 11_000)]
    desk.ok(desk.call("PUT", f"/api/events/{eid}/races/{lea}/laps/0", {"time_ms": 9_000}))
    assert desk.board(eid)["entries"][0]["username"] == "lea"
    assert desk.call("PUT", f"/api/events/{eid}/races/{lea}/laps/7", {"resets": 1}).status_code == 404
    assert desk.call("PUT", f"/api/events/{eid}/races/{lea}/laps/0", {}).status_code == 400

    assert desk.call("DELETE", f"/api/events/{eid}/races/{lea}").status_code == 204
    assert [e["username"] for e in desk.board(eid)["entries"]] == ["max"]
    assert desk.call("GET", f"/api/events/{eid}/races/{lea}").status_code == 404


def test_live_race_cannot_be_deleted(desk: Desk, scenario: Scenario) -> None:
    scenario.add_racers("ned").add_event().add_race("ned", start=False)
    eid, rid = scenario.event_id, scenario.race_id
    assert desk.call("DELETE", f"/api/events/{eid}/races/{rid}").status_code == 409


def test_recompute_rebuilds_every_board_including_combined(desk: Desk, scenario: Scenario, aws_clients) -> None:
    from drem_infra.resources import table_name

    eid = scenario.add_racers("ola", "pia").add_event(tracks=[{"track_id": "1"}, {"track_id": "2"}]).event_id
    scenario.submitted_race("ola", [12_000], track="1")
    scenario.submitted_race("pia", [11_000], track="2")
    scenario.submitted_race("ola", [10_000], track="2")
    combined = desk.board(eid, "combined")
    assert [(e["username"], e["track_id"], e["time_ms"]) for e in combined["entries"]] == [
        ("ola", "2", 10_000), ("pia", "2", 11_000)]
    aws_clients.dynamodb.delete_item(TableName=table_name("test", "leaderboards"),
                                     Key={"pk": {"S": f"EVENT#{eid}"}, "sk": {"S": "BOARD#2"}})
    assert desk.board(eid, "2")["entries"] == []
    result = desk.ok(desk.call("POST", f"/api/events/{eid}/recompute"))
    assert set(result["boards"]) == {"1", "2", "combined"}
    assert [e["username"] for e in desk.board(eid, "2")["entries"]] == ["ola", "pia"]


def test_racer_with_zero_valid_laps_shows_as_dnf(desk: Desk, clock: FakeClock, scenario: Scenario) -> None:
    scenario.add_racers("quinn", "rose").add_event().add_race("quinn")
    eid, rid = scenario.event_id, scenario.race_id
    clock.advance(7_000)
    desk.ok(desk.command(eid, rid, "dnf"))
    desk.ok(desk.command(eid, rid, "end"))
    desk.ok(desk.command(eid, rid, "submit"))
    scenario.submitted_race("rose", [15_000])
    entries = desk.board(eid)["entries"]
    assert [(e["username"], e["is_dnf"], e["time_ms"]) for e in entries] == [("rose", False, 15_000),
                                                                             ("quinn", True, None)]
    summary = desk.call("GET", f"/api/events/{eid}/export/summary.csv")
    rows = list(csv.reader(io.StringIO(summary.body.decode())))
    quinn = next(r for r in rows if r[0] == "quinn")
    assert quinn[7:9] == ["", ""]  # Fastest and Avg blank, no crash


def test_csv_exports_have_drem_columns_and_file_names(desk: Desk, clock: FakeClock, scenario: Scenario) -> None:
    eid = scenario.add_racers("=sam").add_event(name="Summit Stockholm 2026").event_id
    rid = scenario.submitted_race("=sam", [10_000, 11_500])
    laps = desk.call("GET", f"/api/events/{eid}/export/laps.csv")
    assert laps.status_code == 200 and laps.headers["Content-Type"].startswith("text/csv")
    day = __import__("datetime").datetime.fromtimestamp(clock.now / 1000, tz=__import__("datetime").UTC).date()
    assert laps.headers["Content-Disposition"] == f'attachment; filename="summit-stockholm-2026-laps-{day}.csv"'
    rows = list(csv.reader(io.StringIO(laps.body.decode())))
    assert rows[0] == ["Race ID", "Username", "User ID", "Track", "Raced By Proxy", "Race Date", "Lap #",
                       "Lap Time (ms)", "Lap Time (s)", "Resets", "Valid"]
    assert [(r[0], r[1], r[6], r[7], r[8], r[10]) for r in rows[1:]] == [
        (rid, "'=sam", "1", "10000", "10.000", "true"), (rid, "'=sam", "2", "11500", "11.500", "true")]
    summary = desk.call("GET", f"/api/events/{eid}/export/summary.csv")
    rows = list(csv.reader(io.StringIO(summary.body.decode())))
    assert rows[0] == ["Username", "User ID", "Track", "Races", "Total laps", "Valid laps", "Invalid laps",
                       "Fastest", "Avg", "Total resets", "Completion %"]
    assert rows[1][3:] == ["1", "2", "2", "0", "10.000", "10.750", "0", "100.0"]
    assert 'summary' in summary.headers["Content-Disposition"]
    assert desk.call("GET", f"/api/events/{eid}/export/everything.csv").status_code == 400
