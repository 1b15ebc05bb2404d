"""The rules of races, on the fast domain tier: RaceService over the in-memory race, board, event and account stores
(tests/in_memory), no moto and no HTTP. What crosses a boundary stays in tests/unit/test_races_api.py: a full race
with the board item after every lap, the 400/404/409 answers and their JSON, edits, recompute and the CSV exports;
who may call each route is the authorization matrix's (tests/unit/test_authz_matrix.py)."""
from __future__ import annotations

import pytest

from chalicelib.core.errors import Conflict, Forbidden, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.races import CreateRaceInput
from tests.domain.race_desk import COMMENTATOR, OPERATOR, Desk, new_desk

pytestmark = pytest.mark.domain


@pytest.fixture
def desk() -> Desk:
    return new_desk()


def test_a_command_the_race_cannot_take_is_a_conflict_saying_why(desk: Desk) -> None:
    desk.users.add("bob", "racer")
    race_id = desk.race(desk.event(), "bob")
    with pytest.raises(Conflict, match="^cannot capture a lap: the race has not started$"):
        desk.command("e1", race_id, "capture_lap")


def test_a_discarded_race_leaves_the_board(desk: Desk) -> None:
    desk.users.add("carol", "racer")
    race_id = desk.race(desk.event(), "carol")
    desk.command("e1", race_id, "start")
    desk.command("e1", race_id, "capture_lap")
    assert desk.board_names("e1") == ["carol"]
    desk.command("e1", race_id, "end")
    desk.command("e1", race_id, "discard")
    assert desk.board_names("e1") == []


def test_max_runs_are_enforced_and_an_operators_override_is_recorded(desk: Desk) -> None:
    desk.users.add("dave", "racer")
    event_id = desk.event(max_runs_per_racer=2)
    for _ in range(2):
        race_id = desk.race(event_id, "dave")
        desk.command(event_id, race_id, "end")
        desk.command(event_id, race_id, "submit")
    with pytest.raises(Conflict, match=r"^dave has used 2 of 2 runs at this event\.$") as refused:
        desk.race(event_id, "dave")
    assert refused.value.field == "override_max_runs"

    allowed = desk.service.create_race(OPERATOR, event_id, CreateRaceInput(track_id="1", racer_username="dave",
                                                                           override_max_runs=True))
    assert allowed["max_runs_override"] == {"by": "op", "runs_used": 2, "max_runs": 2}
    listed = desk.service.list_races(event_id, None)
    assert [r["max_runs_override"] is not None for r in listed] == [False, False, True]


def test_only_an_operator_or_admin_may_override_max_runs(desk: Desk) -> None:
    desk.users.add("dave", "racer")
    event_id = desk.event(max_runs_per_racer=1)
    race_id = desk.race(event_id, "dave")
    desk.command(event_id, race_id, "end")
    desk.command(event_id, race_id, "submit")
    with pytest.raises(Forbidden, match="Only an operator or admin may override"):
        desk.race(event_id, "dave", by=COMMENTATOR, override_max_runs=True)


def test_discarded_runs_do_not_count_towards_max_runs(desk: Desk) -> None:
    desk.users.add("erin", "racer")
    event_id = desk.event(max_runs_per_racer=1)
    race_id = desk.race(event_id, "erin")
    desk.command(event_id, race_id, "end")
    desk.command(event_id, race_id, "discard")
    assert desk.race(event_id, "erin")  # the one counted run is still free


def test_one_live_race_per_track(desk: Desk) -> None:
    desk.users.add("fay", "racer")
    desk.users.add("gus", "racer")
    event_id = desk.event(tracks=("1", "2"))
    desk.race(event_id, "fay", "1")
    with pytest.raises(Conflict, match=r"^Track 1 already has a live race \(fay\); submit or discard it first\.$"):
        desk.race(event_id, "gus", "1")
    assert desk.race(event_id, "gus", "2")  # the other track is free


def test_an_unknown_racer_track_or_event_is_not_found_naming_the_field(desk: Desk) -> None:
    event_id = desk.event()
    with pytest.raises(NotFound) as no_racer:
        desk.race(event_id, "nobody")
    desk.users.add("hal", "racer")
    with pytest.raises(NotFound) as no_track:
        desk.race(event_id, "hal", "9")
    with pytest.raises(NotFound) as no_event:
        desk.race("no-such-event", "hal")
    assert (no_racer.value.field, no_track.value.field, no_event.value.field) == ("username", "track_id", "event_id")
    assert desk.races.list_event(event_id) == []


def test_racers_read_only_their_own_races(desk: Desk) -> None:
    ivy, jon = desk.users.add("ivy", "racer"), desk.users.add("jon", "racer")
    as_ivy = User(sub=ivy.sub, username="ivy", groups=frozenset({"racer"}))
    as_jon = User(sub=jon.sub, username="jon", groups=frozenset({"racer"}))
    race_id = desk.race(desk.event(), "ivy")

    assert desk.service.get_race(as_ivy, "e1", race_id)["racer"]["username"] == "ivy"
    with pytest.raises(Forbidden):
        desk.service.get_race(as_jon, "e1", race_id)
    assert desk.service.get_race(COMMENTATOR, "e1", race_id)["race_id"] == race_id
    assert [r["race_id"] for r in desk.service.my_races(as_ivy)] == [race_id]
    assert desk.service.my_races(as_jon) == []


def test_no_race_for_a_racer_whose_registration_was_cut_off(desk: Desk) -> None:
    desk.users.add("halfway")  # the account exists, but the registration never reached its racer group
    with pytest.raises(Conflict, match="Register halfway again at the desk") as refused:
        desk.race(desk.event(), "halfway")
    assert refused.value.field == "racer_username"
