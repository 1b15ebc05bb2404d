"""The in-memory league store of the fast domain tier (tests/in_memory/league.py) behaves as DynamoLeagueStore does
(over moto) on every point LeagueService relies on: each assertion here runs against both."""
from __future__ import annotations

from typing import Any

import pytest

from chalicelib.domain.league import EvaluationTrial, EvidenceTaken, LeaguePolicy, SelfReported, Submission
from chalicelib.domain.league_tracks import RegisteredTrack
from tests.in_memory.league import InMemoryLeagueStore

pytestmark = pytest.mark.unit

TRACK = "reinvent_base"


@pytest.fixture(params=["in_memory", "dynamodb"])
def store(request: pytest.FixtureRequest) -> Any:
    if request.param == "in_memory":
        return InMemoryLeagueStore()
    from chalicelib import services

    request.getfixturevalue("stack")
    return services.league_service().store


def a_submission(racer: str = "alice", at: str = "2026-05-14T10:00:00.000000Z", digest: str = "a" * 64,
                 best_s: float = 12.0, track: str = TRACK) -> Submission:
    return Submission(racer=racer, track=track, model_name="m1", layout="drfc", sensor=["FRONT_FACING_CAMERA"],
                      algorithm="clipped_ppo", action_space_type="discrete", action_space="10 actions",
                      hyperparameters={"lr": 0.0003}, training_episodes=10,
                      trials=[EvaluationTrial(trial=1, time_s=best_s, completion_pct=100)], top_speed_m_s=2.0,
                      evidence_digest=digest, submission_id=at, submitted_at=at, submitted_by=racer)


def test_a_recorded_submission_is_on_the_board_and_in_the_history(store: Any) -> None:
    assert store.board(TRACK) == {}
    assert store.submission(TRACK, "alice", "2026-05-14T10:00:00.000000Z") is None
    store.record(a_submission())
    assert store.board(TRACK) == {"alice": a_submission().entry()}
    assert store.submission(TRACK, "alice", "2026-05-14T10:00:00.000000Z") == a_submission()
    assert store.evidence_owner("a" * 64) == "alice"
    assert store.board("Spain_track") == {}


def test_a_newer_push_replaces_the_board_entry_and_both_stay_in_the_history(store: Any) -> None:
    store.record(a_submission())
    later = a_submission(at="2026-05-15T10:00:00.000000Z", best_s=11.0)
    store.record(later)
    assert store.board(TRACK) == {"alice": later.entry()}
    assert store.submission(TRACK, "alice", "2026-05-14T10:00:00.000000Z") == a_submission()


def test_anothers_digest_is_refused_storing_nothing_and_the_owners_own_push_is_taken(store: Any) -> None:
    store.record(a_submission())
    with pytest.raises(EvidenceTaken) as refused:
        store.record(a_submission(racer="bob", at="2026-05-14T11:00:00.000000Z"))
    assert refused.value.owner == "alice"
    assert list(store.board(TRACK)) == ["alice"]
    assert store.submission(TRACK, "bob", "2026-05-14T11:00:00.000000Z") is None
    store.record(a_submission(at="2026-05-14T12:00:00.000000Z"))
    assert store.board(TRACK)["alice"].submission_id == "2026-05-14T12:00:00.000000Z"


def test_replace_moves_the_board_only_for_the_latest_and_is_false_when_gone(store: Any) -> None:
    first, latest = a_submission(), a_submission(at="2026-05-15T10:00:00.000000Z", best_s=11.0)
    store.record(first)
    store.record(latest)
    assert store.replace(first.model_copy(update={"verification": "disputed"})) is True
    assert store.submission(TRACK, "alice", first.submission_id).verification == "disputed"
    assert store.board(TRACK)["alice"] == latest.entry()  # not the latest: the board keeps the newer one
    assert store.replace(latest.model_copy(update={"verification": "not_verified"})) is True
    assert store.board(TRACK)["alice"].verification == "not_verified"
    assert store.replace(a_submission(at="2020-01-01T00:00:00.000000Z")) is False
    assert store.submission(TRACK, "alice", "2020-01-01T00:00:00.000000Z") is None


def test_removing_a_racer_counts_their_submissions_and_frees_their_digests(store: Any) -> None:
    store.record(a_submission(racer="bob"))
    store.record(a_submission(racer="bob", at="2026-05-15T10:00:00.000000Z", digest="b" * 64))
    store.record(a_submission(racer="carol", digest="c" * 64))
    assert store.remove_racer(TRACK, "bob") == 2
    assert list(store.board(TRACK)) == ["carol"]
    assert store.evidence_owner("a" * 64) is None and store.evidence_owner("b" * 64) is None
    assert store.evidence_owner("c" * 64) == "carol"
    assert store.remove_racer(TRACK, "bob") == 0
    store.record(a_submission(racer="alice"))  # the freed logs go to whoever pushes them next
    assert store.evidence_owner("a" * 64) == "alice"


def test_policies_and_registered_tracks_read_back_with_defaults(store: Any) -> None:
    assert store.policy(TRACK) == LeaguePolicy()
    store.set_policy(TRACK, LeaguePolicy(self_reported=SelfReported.REFUSED))
    assert store.policy(TRACK).self_reported is SelfReported.REFUSED
    assert store.policy("Spain_track") == LeaguePolicy()
    assert store.registered_tracks() == {}
    store.register_track("venue_figure8", RegisteredTrack(length_m=21.5))
    store.register_track("venue_figure8", RegisteredTrack(length_m=22.0))  # registering again overwrites
    assert store.registered_tracks() == {"venue_figure8": RegisteredTrack(length_m=22.0)}


def test_reads_hand_out_copies_the_caller_cannot_change_the_store_through(store: Any) -> None:
    store.record(a_submission())
    board = store.board(TRACK)
    board.pop("alice")
    assert list(store.board(TRACK)) == ["alice"]
