"""The race desk of the fast domain tier: RaceService over the in-memory race, board, event and account stores
(tests/in_memory), with a hand-moved clock, driven as an operator drives it (tests/domain/test_race_rules.py,
tests/domain/test_timing_rules.py)."""
from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import date
from typing import Any

from chalicelib.core.principals import User
from chalicelib.domain.events import Event, Track
from chalicelib.domain.leaderboards import LeaderboardPublisher
from chalicelib.domain.races import CreateRaceInput, RaceService
from drem_leaderboard.commands import parse_command
from drem_leaderboard.models import RaceConfig
from drem_leaderboard.ranking import RacerProfile
from tests.in_memory.boards import InMemoryBoardStore
from tests.in_memory.events import InMemoryEventStore
from tests.in_memory.races import InMemoryRaceStore
from tests.in_memory.users import InMemoryUserDirectory

OPERATOR = User(sub="op-sub", username="op", groups=frozenset({"operator"}))
COMMENTATOR = User(sub="kim-sub", username="kim", groups=frozenset({"commentator"}))


class SignInNames:
    """Boards show the sign-in name (no profiles here; ProfilesForBoards' rules are tests/unit/test_profiles.py's)."""

    def racer_profile(self, sub: str, fallback_username: str) -> RacerProfile:
        return RacerProfile(username=fallback_username)


class Clock:
    """The server clock, moved by hand (a minute between races, so their order is certain)."""

    def __init__(self) -> None:
        self.now = 1_800_000_000_000

    def __call__(self) -> int:
        return self.now

    def advance(self, ms: int) -> None:
        self.now += ms


@dataclass
class Desk:
    service: RaceService
    races: InMemoryRaceStore
    events: InMemoryEventStore
    users: InMemoryUserDirectory
    boards: LeaderboardPublisher
    clock: Clock

    def event(self, event_id: str = "e1", tracks: tuple[str, ...] = ("1",), fleet_id: str | None = None,
              **config: Any) -> str:
        """An event whose tracks race with `fleet_id`'s devices (none: no device may time them)."""
        self.events.create(Event(event_id=event_id, name="Summit", event_type="AWS_SUMMIT", date=date(2026, 5, 14),
                                 country_code="SE", sponsor="", race_config=RaceConfig(**config),
                                 tracks=tuple(Track(track_id=t, fleet_id=fleet_id) for t in tracks),
                                 landing_page_links=(),
                                 created_at_ms=1, created_by="op", updated_at_ms=1, version=1))
        return event_id

    def race(self, event_id: str, racer: str, track_id: str = "1", by: User = OPERATOR, **fields: Any) -> str:
        self.clock.advance(60_000)
        data = CreateRaceInput(track_id=track_id, racer_username=racer, **fields)
        return str(self.service.create_race(by, event_id, data)["race_id"])

    def command(self, event_id: str, race_id: str, kind: str, **fields: Any) -> dict[str, Any]:
        self.clock.advance(1_000)
        return self.service.apply_command(event_id, race_id, parse_command({"kind": kind, **fields}), by="op")

    def board_entries(self, event_id: str, track_id: str = "1") -> list[dict[str, Any]]:
        """What the big screen shows for the track (its board's first page)."""
        return list(json.loads(self.boards.board(event_id, track_id).body)["entries"])

    def board_names(self, event_id: str, track_id: str = "1") -> list[str]:
        return [e["username"] for e in self.board_entries(event_id, track_id)]


def new_desk() -> Desk:
    races, events, users, clock = InMemoryRaceStore(), InMemoryEventStore(), InMemoryUserDirectory(), Clock()
    boards = LeaderboardPublisher(InMemoryBoardStore(), clock, cache=None)
    service = RaceService(races, events, users, SignInNames(), boards, clock)
    return Desk(service, races, events, users, boards, clock)
