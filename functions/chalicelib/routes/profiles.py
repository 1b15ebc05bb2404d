"""Racer profiles (JSON): your own, anyone's public view and identicon, and admins editing a racer's profile."""
from __future__ import annotations

from chalice import Blueprint, Response

from chalicelib.auth.access import ADMIN, PUBLIC, SIGNED_IN, route
from chalicelib.auth.principals import Principal, User
from chalicelib.domain.profiles import Profile, ProfileService, ProfileUpdate, PublicProfile, public_view
from chalicelib.routes.users import user_directory
from chalicelib.settings import get_settings
from chalicelib.storage import clients
from chalicelib.storage.profiles import DynamoProfileStore

bp = Blueprint(__name__)


def profile_service() -> ProfileService:
    settings = get_settings()
    store = DynamoProfileStore(clients.dynamodb(), settings.table("profiles"))
    return ProfileService(store, user_directory(settings))


def shown_on_boards(profile: Profile) -> Profile:
    """Board rows carry the racer's colour and country as they were when a race was published: refresh them so a
    change reaches every leaderboard and overlay the racer is on."""
    from chalicelib.routes.races import race_service  # races → profiles already; import here, not at the top

    race_service().refresh_racer_everywhere(profile.sub)
    return profile


@route(bp, "/api/me/profile", allow=SIGNED_IN, response=Profile)
def own_profile(principal: User) -> dict:
    return profile_service().own(principal).model_dump()


@route(bp, "/api/me/profile", methods=["PUT"], allow=SIGNED_IN, body=ProfileUpdate, response=Profile)
def update_own_profile(principal: User, body: ProfileUpdate) -> dict:
    return shown_on_boards(profile_service().update_own(principal, body)).model_dump()


@route(bp, "/api/users/{username}/profile", methods=["PUT"], allow={ADMIN}, body=ProfileUpdate,
       response=PublicProfile)
def update_user_profile(principal: User, username: str, body: ProfileUpdate) -> dict:
    return public_view(shown_on_boards(profile_service().update_for(principal, username, body))).model_dump()


@route(bp, "/api/profiles/{username}", allow=PUBLIC, response=PublicProfile)
def public_profile(principal: Principal, username: str) -> dict:
    return profile_service().public(username).model_dump()


@route(bp, "/api/profiles/{username}/avatar.svg", allow=PUBLIC)
def avatar(principal: Principal, username: str) -> Response:
    svg = profile_service().avatar_svg(username)
    return Response(body=svg, status_code=200, headers={
        "Content-Type": "image/svg+xml", "Cache-Control": "public, max-age=300",
        # An SVG opened directly must not run script, whatever it contains.
        "Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'",
        "X-Content-Type-Options": "nosniff"})
