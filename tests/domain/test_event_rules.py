"""The rules of events, on the fast domain tier: EventService over the in-memory stores (tests/in_memory), no moto
and no HTTP. What crosses a boundary (roles, the 400/404/409 answers, the JSON) stays in tests/unit/test_events_api.py.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pytest

from chalicelib.core.errors import Conflict, InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.events import Event, EventInput, EventService
from chalicelib.domain.fleets import FleetRecord
from tests.in_memory.events import InMemoryEventStore, InMemoryFleetStore, InMemoryLiveRaceProbe

pytestmark = pytest.mark.domain

OPERATOR = User(sub="op-sub", username="op", groups=frozenset({"operator"}))


@dataclass
class Desk:
    """The event service as an operator uses it, with the stores behind it kept at hand."""
    service: EventService
    events: InMemoryEventStore
    fleets: InMemoryFleetStore
    live: InMemoryLiveRaceProbe
    saved: list[Event]

    def create(self, **fields: Any) -> Event:
        return self.service.create_event(OPERATOR, an_input(**fields))

    def update(self, event: Event, **fields: Any) -> Event:
        return self.service.update_event(OPERATOR, event.event_id, an_input(**fields))

    def fleet(self, fleet_id: str) -> str:
        self.fleets.put_fleet(FleetRecord(fleet_id=fleet_id, name=fleet_id, created_at_ms=1, created_by="op"))
        return fleet_id


def an_input(**fields: Any) -> EventInput:
    body: dict[str, Any] = {"name": "Stockholm Summit", "event_type": "AWS_SUMMIT", "date": "2026-05-14",
                            "country_code": "se", "tracks": [{"leaderboard_title": "Main track"}]}
    return EventInput.model_validate({**body, **fields})


@pytest.fixture
def desk() -> Desk:
    events, fleets, live, saved = InMemoryEventStore(), InMemoryFleetStore(), InMemoryLiveRaceProbe(), []
    ticks = iter(range(1_000, 10**9, 1_000))
    clock: Callable[[], int] = lambda: next(ticks)  # noqa: E731 - every reading a second later
    return Desk(EventService(events, live, fleets, clock, on_saved=saved.append), events, fleets, live, saved)


def test_lap_count_ranking_keeps_its_target(desk: Desk) -> None:
    event = desk.create(race_config={"ranking_method": "LAP_COUNT", "lap_count_target": 10})
    assert desk.service.get_event(event.event_id).race_config.lap_count_target == 10


def test_a_second_track_brings_the_combined_board_and_removing_it_drops_it(desk: Desk) -> None:
    north = desk.fleet("fleet-a")
    event = desk.create(tracks=[{"fleet_id": north, "leaderboard_title": "North"}, {"leaderboard_title": "South"}])
    assert [t.track_id for t in event.tracks] == ["1", "2"]
    assert event.tracks[0].fleet_id == north
    assert event.combined_board is True
    assert event.boards == ["1", "2", "combined"]

    one = desk.update(event, tracks=[event.tracks[0].model_dump()])
    assert one.combined_board is False
    assert one.version == 2
    assert desk.service.get_event(event.event_id) == one
    assert desk.saved == [event, one]  # the big screen hears of each save


def test_a_track_added_in_the_edit_that_removes_another_does_not_take_its_number(desk: Desk) -> None:
    event = desk.create(tracks=[{"leaderboard_title": "North"}, {"leaderboard_title": "South"}])
    swapped = desk.update(event, tracks=[event.tracks[1].model_dump(), {"leaderboard_title": "East"}])
    # A race or board row still naming track 1 must not silently become East's.
    assert [(t.track_id, t.leaderboard_title) for t in swapped.tracks] == [("2", "South"), ("3", "East")]


def test_an_unknown_fleet_on_a_track_is_refused_naming_the_track(desk: Desk) -> None:
    with pytest.raises(InvalidInput) as refused:
        desk.create(tracks=[{"fleet_id": "nope"}])
    assert refused.value.field == "tracks.0.fleet_id"
    assert desk.service.list_events() == []


def test_an_event_stays_editable_after_its_fleet_is_deleted(desk: Desk) -> None:
    event = desk.create(tracks=[{"fleet_id": desk.fleet("gone-soon")}])
    desk.fleets.delete_fleet("gone-soon")
    renamed = desk.update(event, name="Renamed", tracks=[t.model_dump() for t in event.tracks])
    assert renamed.name == "Renamed"
    assert renamed.tracks[0].fleet_id == "gone-soon"


def test_a_deleted_event_is_gone_and_deleting_it_again_is_not_found(desk: Desk) -> None:
    event = desk.create()
    desk.service.delete_event(OPERATOR, event.event_id)
    with pytest.raises(NotFound):
        desk.service.get_event(event.event_id)
    with pytest.raises(NotFound):
        desk.service.delete_event(OPERATOR, event.event_id)


def test_a_track_with_a_live_race_can_be_neither_removed_nor_deleted_with_its_event(desk: Desk) -> None:
    event = desk.create(tracks=[{"leaderboard_title": "North"}, {"leaderboard_title": "South"}])
    desk.live.start(event.event_id, "2")

    with pytest.raises(Conflict, match="race in progress"):
        desk.service.delete_event(OPERATOR, event.event_id)
    with pytest.raises(Conflict, match="Track 2 has a race in progress") as dropping_2:
        desk.update(event, tracks=[event.tracks[0].model_dump()])
    assert dropping_2.value.field == "tracks"
    assert desk.service.get_event(event.event_id) == event  # nothing was changed by the refusals

    keep_2 = desk.update(event, tracks=[event.tracks[1].model_dump()])  # track 1 has no live race: it may go
    assert [t.track_id for t in keep_2.tracks] == ["2"]

    desk.live.end(event.event_id, "2")  # the race finished: now the event may go
    desk.service.delete_event(OPERATOR, event.event_id)
    assert desk.service.list_events() == []


def test_two_operators_editing_at_once_cannot_overwrite_each_other(desk: Desk) -> None:
    event = desk.create(name="Summit")
    stale_copy = desk.service.get_event(event.event_id)
    desk.update(event, name="First edit")

    # The second operator's edit was based on the version before the first edit: the store refuses it.
    second = stale_copy.model_copy(update={"name": "Second edit", "version": stale_copy.version + 1})
    with pytest.raises(Conflict, match="changed this event meanwhile"):
        desk.events.replace(second, expected_version=stale_copy.version)
    assert desk.service.get_event(event.event_id).name == "First edit"


def test_events_are_listed_newest_date_first(desk: Desk) -> None:
    older = desk.create(name="Spring", date="2026-03-01")
    newer = desk.create(name="Autumn", date="2026-10-01")
    same_day_later = desk.create(name="Autumn again", date="2026-10-01")
    assert [e.event_id for e in desk.service.list_events()] == [same_day_later.event_id, newer.event_id,
                                                                   older.event_id]
