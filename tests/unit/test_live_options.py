"""Which live-region option sets exist (chalicelib.views.live_options): spellings of one HTML are one option set, and
the option sets drem's own pages and overlay links hand out are told apart from hand-made ones."""
from __future__ import annotations

from chalicelib.views.live_options import canonical, offered
from chalicelib.views.live_regions import LeaderboardQuery, OverlayQuery

TRACKS = ["1", "2"]


def overlay(**params: str) -> OverlayQuery:
    return canonical(OverlayQuery.model_validate(params))


def board(**params: str) -> LeaderboardQuery:
    return canonical(LeaderboardQuery.model_validate(params))


def test_spellings_of_the_same_overlay_are_one_option_set() -> None:
    plain = overlay(track="1", lang="de")
    for spelling in (overlay(trackId="1", lang="DE"), overlay(track="1", lang="de-AT", chroma="true",
                                                              chromaColor="#FF00FF")):
        assert spelling.model_dump_json() == plain.model_dump_json()
    assert overlay(track="1", lang="xx").lang == "en"  # an unknown language renders English: one option set
    assert overlay(track="1", gapToLeader="false").model_dump_json() != plain.model_dump_json()


def test_the_big_screens_qr_place_does_not_make_another_option_set() -> None:
    assert board(track="1", qr="header").model_dump_json() == board(track="1").model_dump_json()
    assert board(track="1", page_seconds="9").model_dump_json() != board(track="1").model_dump_json()


def test_what_the_link_builder_and_the_pages_hand_out_is_offered() -> None:
    assert offered(overlay(trackId="2", gapToLeader="false", showLeaderboard="false", lang="ja"), TRACKS)
    assert offered(board(track="1", tracks="1", lang="sv"), TRACKS)
    assert offered(board(track="combined", tracks="1,2"), TRACKS)
    many = [str(n) for n in range(1, 11)]  # the big screen's combined board shows the first 8 tracks' races
    assert offered(board(track="combined", tracks=",".join(many[:8])), many)


def test_hand_made_options_and_made_up_tracks_are_not_offered() -> None:
    assert not offered(overlay(track="1", format="average"), TRACKS)
    assert not offered(overlay(track="made-up"), TRACKS)
    assert not offered(board(track="1", page_seconds="3"), TRACKS)
    assert not offered(board(track="combined", tracks="2"), TRACKS)
    assert not offered(board(track="9"), TRACKS)
