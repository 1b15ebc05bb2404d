"""The virtual league: the JSON API `drem league push|pull` talks to, and the public board page `/league/{track}`.

Who may call: anyone reads boards and a racer's latest submission (hyperparameters included: "what did the leader
use?"); any signed-in user pushes, but only under their own username (admins may push for anyone, decided in
chalicelib.domain.league); only admins delete a racer's submissions on a track.
"""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, PUBLIC, SIGNED_IN, route
from chalicelib.auth.principals import Principal, User
from chalicelib.domain.league import Board, BoardQuery, Submission, SubmissionInput
from chalicelib.views.league_views import board_view, submission_view
from drem_web import render

bp = Blueprint(__name__)


@route(bp, "/api/league/{track}/submissions", methods=["POST"], allow=SIGNED_IN, body=SubmissionInput,
       response=Submission, status_code=201, tags=("league",))
def push_submission(principal: User, track: str, body: SubmissionInput) -> Response:
    """Push a submission (your own; admins may push for any racer)"""
    submission = services.league_service().push(principal, track, body)
    return Response(body={"submission": submission.model_dump(mode="json"),
                          "entry": submission.entry().model_dump(mode="json")}, status_code=201)


@route(bp, "/api/league/{track}", allow=PUBLIC, query=BoardQuery, response=Board, tags=("league",))
def league_board(principal: Principal, track: str, query: BoardQuery) -> dict:
    """A track's board: each racer's latest submission, ranked"""
    return services.league_service().board(track, query).model_dump(mode="json")


@route(bp, "/api/league/{track}/racers/{racer}", allow=PUBLIC, response=Submission, tags=("league",))
def latest_submission(principal: Principal, track: str, racer: str) -> dict:
    """A racer's latest submission on a track, with every hyperparameter"""
    return {"submission": services.league_service().latest(track, racer).model_dump(mode="json")}


@route(bp, "/api/league/{track}/racers/{racer}", methods=["DELETE"], allow={ADMIN}, tags=("league",))
def delete_racer(principal: User, track: str, racer: str) -> dict:
    """Remove a racer's submissions from a track (admins)"""
    return {"deleted": services.league_service().delete(principal, track, racer)}


@route(bp, "/league/{track}", allow=PUBLIC, query=BoardQuery)
def league_page(principal: Principal, track: str, query: BoardQuery) -> Response:
    """The public board page"""
    board = services.league_service().board(track, query)
    names = services.profile_service().shown_names([ranked.entry.racer for ranked in board.entries])
    return render.page("league", view=board_view(board, query, names))


@route(bp, "/league/{track}/racers/{racer}", allow=PUBLIC)
def league_racer_fragment(principal: Principal, track: str, racer: str) -> Response:
    """The hyperparameters and trials behind a board row (htmx fragment)"""
    return render.fragment("league_submission", view=submission_view(services.league_service().latest(track, racer)))
