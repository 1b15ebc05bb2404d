"""JSON about accounts: who am I, and (admins) which roles a user has."""
from __future__ import annotations

from chalice import Blueprint

from chalicelib import services
from chalicelib.auth.access import ADMIN, SIGNED_IN, route
from chalicelib.core.principals import User

bp = Blueprint(__name__)


@route(bp, "/api/me", allow=SIGNED_IN)
def whoami(principal: User) -> dict:
    return {"sub": principal.sub, "username": principal.username, "groups": sorted(principal.groups),
            "roles": sorted(r.value for r in principal.roles)}


@route(bp, "/api/users/{username}/groups", allow={ADMIN})
def user_groups(principal: User, username: str) -> dict:
    return {"username": username, "groups": services.identity_provider().groups_of(username)}
