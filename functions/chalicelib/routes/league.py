"""The virtual league: the JSON API `drem league push|pull` talks to, and the public board page `/league/{track}`.

Who may call: anyone reads boards and a racer's latest submission (hyperparameters included: "what did the leader
use?"); any signed-in user pushes the files of an export (a .tar.gz the server reads and assembles), but only under
their own username (admins may push for anyone, decided in chalicelib.domain.league); only admins delete a racer's
submissions on a track.
"""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, PUBLIC, SIGNED_IN, body_bytes, route
from chalicelib.core.principals import Principal, User
from chalicelib.domain.league import Board, BoardQuery, LeaguePolicy, Submission
from chalicelib.domain.league_intake import UPLOAD_CONTENT_TYPES, PushOptions
from chalicelib.domain.league_tracks import RegisteredTrack
from chalicelib.views.league_views import board_view, submission_view
from drem_web import render

bp = Blueprint(__name__)


@route(bp, "/api/league/{track}/submissions", methods=["POST"], allow=SIGNED_IN, query=PushOptions,
       content_types=UPLOAD_CONTENT_TYPES, response=Submission, status_code=201, tags=("league",))
def push_submission(principal: User, track: str, query: PushOptions) -> Response:
    """Push an export's files as a .tar.gz (yours; admins may push for any racer); the server assembles them"""
    submission = services.league_intake().push_upload(principal, track, body_bytes(bp.current_request), query)
    return Response(body={"submission": submission.model_dump(mode="json"),
                          "entry": submission.entry().model_dump(mode="json")}, status_code=201)


@route(bp, "/api/league/{track}", allow=PUBLIC, query=BoardQuery, response=Board, tags=("league",))
def league_board(principal: Principal, track: str, query: BoardQuery) -> dict:
    """A track's board: each racer's latest submission, ranked, with each racer's display name"""
    board = services.league_service().board(track, query)
    names = services.league_shown_names([ranked.entry.racer for ranked in board.entries])
    return board.model_copy(update={"racer_names": names}).model_dump(mode="json")


@route(bp, "/api/league/{track}/racers/{racer}", allow=PUBLIC, response=Submission, tags=("league",))
def latest_submission(principal: Principal, track: str, racer: str) -> dict:
    """A racer's latest submission on a track, with every hyperparameter"""
    return {"submission": services.league_service().latest(track, racer).model_dump(mode="json")}


@route(bp, "/api/league-tracks/{track}", methods=["PUT"], allow={ADMIN}, body=RegisteredTrack,
       response=RegisteredTrack, tags=("league",))
def register_track(principal: User, track: str, body: RegisteredTrack) -> dict:
    """Register a track drem's set lacks, by its centre-line length (admins)"""
    return services.league_service().register_track(principal, track, body).model_dump(mode="json")


@route(bp, "/api/league/{track}/policy", methods=["PUT"], allow={ADMIN}, body=LeaguePolicy, response=LeaguePolicy,
       tags=("league",))
def set_policy(principal: User, track: str, body: LeaguePolicy) -> dict:
    """Choose what the board does with self-reported entries: shown, below_verified or refused (admins)"""
    return services.league_service().set_policy(principal, track, body).model_dump(mode="json")


@route(bp, "/api/league/{track}/racers/{racer}", methods=["DELETE"], allow={ADMIN}, tags=("league",))
def delete_racer(principal: User, track: str, racer: str) -> dict:
    """Remove a racer's submissions from a track (admins)"""
    return {"deleted": services.league_service().delete(principal, track, racer)}


@route(bp, "/league/{track}", allow=PUBLIC, query=BoardQuery)
def league_page(principal: Principal, track: str, query: BoardQuery) -> Response:
    """The public board page"""
    board = services.league_service().board(track, query)
    names = services.league_shown_names([ranked.entry.racer for ranked in board.entries])
    return render.page("league", view=board_view(board, query, names))


@route(bp, "/league/{track}/racers/{racer}", allow=PUBLIC)
def league_racer_fragment(principal: Principal, track: str, racer: str) -> Response:
    """The hyperparameters and trials behind a board row (htmx fragment)"""
    submission = services.league_service().latest(track, racer)
    shown = services.profile_service().shown_names([submission.racer])[submission.racer]
    return render.fragment("league_submission", view=submission_view(submission, shown))
