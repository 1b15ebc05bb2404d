"""The rules of the virtual league, on the fast domain tier: LeagueService over the in-memory store
(tests/in_memory/league.py), no moto and no HTTP. Reading exports (the formats), the roles a route lets in and the
status codes stay in tests/unit/test_league_api.py and test_league_cheats.py."""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

import pytest

from chalicelib.core.errors import Forbidden, InvalidInput, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.league import (
    Board,
    BoardQuery,
    EvaluationTrial,
    EvidenceTaken,
    LeaguePolicy,
    LeagueService,
    SelfReported,
    SortKey,
    SubmissionInput,
    VerifiedDrive,
)
from chalicelib.domain.league_board_cache import LeagueBoardCache
from chalicelib.domain.league_tracks import RegisteredTrack
from tests.in_memory.league import InMemoryLeagueStore

pytestmark = pytest.mark.domain

REINVENT = "reinvent_base"  # 17.709 m: at 2 m/s no lap takes less than 8.854 s
ADMIN = User(sub="root-sub", username="root", groups=frozenset({"admin"}))


def racer(name: str) -> User:
    return User(sub=f"{name}-sub", username=name, groups=frozenset({"racer"}))


@dataclass
class League:
    """The league service (its clock moves a second per push, so each push is a newer submission)."""
    service: LeagueService
    store: InMemoryLeagueStore

    def push(self, name: str, laps: list[float], *, track: str = REINVENT, digest: str | None = None,
             by: User | None = None, completion: float = 100, **fields: Any) -> Any:
        body = SubmissionInput(
            racer=name, track=track, model_name=fields.pop("model_name", f"{name}-model"), layout="drfc",
            sensor=fields.pop("sensor", ["FRONT_FACING_CAMERA"]), algorithm=fields.pop("algorithm", "clipped_ppo"),
            action_space_type="discrete", action_space="10 actions", hyperparameters={"lr": 0.0003},
            training_episodes=10, top_speed_m_s=2.0, evidence_digest=digest or _digest(name, laps),
            trials=[EvaluationTrial(trial=i + 1, time_s=t, completion_pct=completion) for i, t in enumerate(laps)],
            **fields)
        return self.service.push(by or racer(name), track, body)

    def order(self, track: str = REINVENT, **query: Any) -> list[str]:
        return [ranked.entry.racer for ranked in self.service.board(track, BoardQuery(**query)).entries]


def _digest(name: str, laps: list[float]) -> str:
    """Each racer's own logs: a digest no other push shares unless a test passes the same one."""
    return hashlib.sha256(repr((name, laps)).encode()).hexdigest()


@pytest.fixture(params=["read every time", "boards kept"])
def league(request: pytest.FixtureRequest) -> League:
    """Each rule holds with the app's board cache too: its clock never moves, so a board read after a write shows the
    write only because the write dropped it (domain/league_board_cache.py)."""
    store = InMemoryLeagueStore()
    ticks = iter(range(10, 60))
    boards: LeagueBoardCache[Board] | None = (
        LeagueBoardCache(monotonic=lambda: 0.0) if request.param == "boards kept" else None)
    service = LeagueService(store, clock=lambda: f"2026-05-14T10:00:{next(ticks):02d}.000000Z", boards=boards)
    return League(service, store)


def test_boards_rank_completed_laps_first_by_best_or_by_average(league: League) -> None:
    league.push("alice", [15.0, 18.0])
    league.push("bob", [15.5, 15.6])
    league.push("carol", [20.0], completion=80)  # no completed lap
    assert league.order() == ["alice", "bob", "carol"]
    assert league.order(sort=SortKey.AVG) == ["bob", "alice", "carol"]
    best = league.service.board(REINVENT, BoardQuery()).entries[0].entry
    assert (best.best_lap_s, best.average_lap_s, best.laps_completed) == (15.0, 16.5, 2)


def test_filters_keep_the_algorithm_sensor_and_days_asked_for(league: League) -> None:
    league.push("alice", [15.0])
    league.push("bob", [15.5], algorithm="sac", sensor=["FRONT_FACING_CAMERA", "SECTOR_LIDAR"])
    assert league.order(algorithm="sac") == ["bob"]
    assert league.order(sensor="SECTOR_LIDAR") == ["bob"]
    assert league.order(since="2026-05-14", until="2026-05-14") == ["alice", "bob"]
    assert league.order(until="2026-05-13") == []


def test_a_new_push_replaces_the_racers_entry_and_the_latest_is_the_one_shown_in_full(league: League) -> None:
    league.push("alice", [15.0])
    league.push("alice", [14.0], model_name="a3")
    entries = league.service.board(REINVENT, BoardQuery()).entries
    assert [ranked.entry.racer for ranked in entries] == ["alice"]
    assert (entries[0].entry.best_lap_s, entries[0].entry.model_name) == (14.0, "a3")
    assert league.service.latest(REINVENT, "alice").model_name == "a3"


def test_racers_push_only_as_themselves_and_admins_for_anyone(league: League) -> None:
    with pytest.raises(Forbidden, match="only as yourself"):
        league.push("bob", [12.0], by=racer("alice"))
    assert league.order() == []
    league.push("bob", [12.0], by=ADMIN)
    assert league.order() == ["bob"]


def test_someone_elses_logs_are_refused_naming_who_pushed_them_first(league: League) -> None:
    league.push("alice", [15.0], digest="a" * 64)
    with pytest.raises(EvidenceTaken, match="already pushed by alice"):
        league.push("bob", [15.0], digest="a" * 64)
    assert league.order() == ["alice"]
    league.push("alice", [15.0], digest="a" * 64)  # her own logs again: fine


def test_a_copier_removed_by_staff_frees_the_logs_for_their_owner(league: League) -> None:
    league.push("bob", [15.0], digest="a" * 64)  # bob got there first
    with pytest.raises(EvidenceTaken, match="already pushed by bob"):
        league.push("alice", [15.0], digest="a" * 64)
    assert league.service.delete(ADMIN, REINVENT, "bob") == 1
    league.push("alice", [15.0], digest="a" * 64)
    assert league.order() == ["alice"]


def test_only_admins_delete_and_deleting_nothing_is_not_found(league: League) -> None:
    league.push("bob", [15.5])
    with pytest.raises(Forbidden):
        league.service.delete(racer("bob"), REINVENT, "bob")
    assert league.service.delete(ADMIN, REINVENT, "bob") == 1
    assert league.order() == []
    with pytest.raises(NotFound):
        league.service.latest(REINVENT, "bob")
    with pytest.raises(NotFound):
        league.service.delete(ADMIN, REINVENT, "bob")


def test_no_lap_is_faster_than_the_track_driven_at_top_speed(league: League) -> None:
    with pytest.raises(InvalidInput, match="no lap can take less than 8.854 s") as refused:
        league.push("alice", [9.0, 3.0])
    assert refused.value.field == "trials[1].time_s"
    with pytest.raises(InvalidInput, match="3.000 s lap"):
        league.push("alice", [3.0, 3.0], track="drem_oval")
    league.push("alice", [3.0], completion=60)  # not a completed lap: no claim to check
    assert league.order() == ["alice"] and league.order("drem_oval") == []


def test_an_invented_track_never_creates_a_board(league: League) -> None:
    with pytest.raises(NotFound, match="'Nowhere_track' is not a track drem knows"):
        league.push("alice", [12.0], track="Nowhere_track")
    assert league.order("Nowhere_track") == []


def test_admins_register_a_track_drems_set_lacks_and_its_length_bounds_the_laps(league: League) -> None:
    with pytest.raises(NotFound):
        league.push("alice", [12.0], track="venue_figure8")
    with pytest.raises(Forbidden):
        league.service.register_track(racer("alice"), "venue_figure8", RegisteredTrack(length_m=21.5))
    with pytest.raises(InvalidInput, match="drem's own tracks"):
        league.service.register_track(ADMIN, REINVENT, RegisteredTrack(length_m=5.0))
    league.service.register_track(ADMIN, "venue_figure8", RegisteredTrack(length_m=21.5))
    league.push("alice", [12.0], track="venue_figure8")
    assert league.order("venue_figure8") == ["alice"]
    with pytest.raises(InvalidInput, match="venue_figure8 is 21.50 m long"):
        league.push("alice", [10.0], track="venue_figure8")


def test_a_league_that_refuses_self_reported_entries_takes_and_shows_only_models_drem_drives(league: League) -> None:
    league.push("bob", [15.5])  # self-reported, before the policy
    with pytest.raises(Forbidden):
        league.service.set_policy(racer("bob"), REINVENT, LeaguePolicy(self_reported=SelfReported.REFUSED))
    league.service.set_policy(ADMIN, REINVENT, LeaguePolicy(self_reported=SelfReported.REFUSED))
    assert league.order() == []  # bob's self-reported entry is no longer shown
    with pytest.raises(Forbidden, match="only entries drem verifies"):
        league.push("alice", [15.0])
    league.push("alice", [15.0], model_id="m-alice")
    assert league.order() == []  # pending until drem re-drives it
    league.service.record_drive(REINVENT, "alice", "m-alice",
                                VerifiedDrive(laps=3, laps_completed=3, best_lap_s=15.2, mean_lap_s=15.4))
    assert league.order() == ["alice"]


def test_a_re_drive_much_slower_than_the_logs_disputes_the_entry_and_hides_it(league: League) -> None:
    league.push("alice", [10.0], model_id="m-alice")
    league.push("bob", [15.5], model_id="m-bob")
    disputed = league.service.record_drive(REINVENT, "alice", "m-alice",
                                           VerifiedDrive(laps=3, laps_completed=3, best_lap_s=14.0, mean_lap_s=14.5))
    assert disputed is not None and disputed.verification == "disputed"
    assert "not believed" in disputed.verification_note
    assert league.order() == ["bob"]


def test_a_re_drive_of_a_model_the_racer_has_since_replaced_is_not_recorded(league: League) -> None:
    league.push("alice", [15.0], model_id="m-old")
    league.push("alice", [14.0], model_id="m-new")
    drive = VerifiedDrive(laps=1, laps_completed=1, best_lap_s=15.0, mean_lap_s=15.0)
    assert league.service.record_drive(REINVENT, "alice", "m-old", drive) is None
    assert league.service.latest(REINVENT, "alice").verification == "pending"
