"""`GET /api/ping`: a fixed small JSON answer that reads nothing. It shows that the app answers at all (for a person
or a load balancer), and it is the yardstick of `bench/spectators.py`: a poll costs what the framework costs plus its
read."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import PUBLIC, route
from chalicelib.core.principals import Principal

bp = Blueprint(__name__)

PONG = '{"pong":true}'


@route(bp, "/api/ping", allow=PUBLIC)
def ping(principal: Principal) -> Response:
    """A constant answer: is the app server up (no storage read, no sign-in look-up)"""
    return Response(body=PONG, status_code=200, headers={"Content-Type": "application/json",
                                                         "Cache-Control": "no-store"})
