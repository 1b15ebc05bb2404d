"""Racer profiles (JSON): your own, anyone's public view and identicon, and admins editing a racer's profile."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib import services
from chalicelib.auth.access import ADMIN, PUBLIC, SIGNED_IN, route
from chalicelib.core.principals import Principal, User
from chalicelib.domain.profiles import Profile, ProfileUpdate, PublicProfile, public_view

bp = Blueprint(__name__)


@route(bp, "/api/me/profile", allow=SIGNED_IN, response=Profile)
def own_profile(principal: User) -> dict:
    return services.profile_service().own(principal).model_dump()


@route(bp, "/api/me/profile", methods=["PUT"], allow=SIGNED_IN, body=ProfileUpdate, response=Profile)
def update_own_profile(principal: User, body: ProfileUpdate) -> dict:
    return services.profile_service().update_own(principal, body).model_dump()


@route(bp, "/api/users/{username}/profile", methods=["PUT"], allow={ADMIN}, body=ProfileUpdate,
       response=PublicProfile)
def update_user_profile(principal: User, username: str, body: ProfileUpdate) -> dict:
    return public_view(services.profile_service().update_for(principal, username, body)).model_dump()


@route(bp, "/api/profiles/{username}", allow=PUBLIC, response=PublicProfile)
def public_profile(principal: Principal, username: str) -> dict:
    return services.profile_service().public(username).model_dump()


@route(bp, "/api/profiles/{username}/avatar.svg", allow=PUBLIC)
def avatar(principal: Principal, username: str) -> Response:
    svg = services.profile_service().avatar_svg(username)
    return Response(body=svg, status_code=200, headers={
        "Content-Type": "image/svg+xml", "Cache-Control": "public, max-age=300",
        # An SVG opened directly must not run script, whatever it contains.
        "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'",
        "X-Content-Type-Options": "nosniff"})
