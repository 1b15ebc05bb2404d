"""Racer profiles: highlight colour, avatar choice and the country copied from the account, keyed by Cognito sub.

A deleted user's profile becomes a tombstone `{deleted: true}`: past race results keep the sub, and renderers show
`anonymised_name(sub)` with no country, colour or avatar in place of the person.
"""
from __future__ import annotations

from datetime import UTC, datetime
from typing import Literal, Protocol

from pydantic import BaseModel, ConfigDict, Field, field_validator

from chalicelib.core.errors import InvalidInput, NotFound
from chalicelib.core.principals import Role, User
from chalicelib.domain.countries import normalise_country_code
from chalicelib.domain.names import check_display_name
from chalicelib.domain.ownership import require_owner_or_role
from chalicelib.domain.shown_names_cache import PROCESS_SHOWN_NAMES
from chalicelib.formats.avatars import avatar_seed, identicon_svg
from drem_leaderboard.names import told_apart
from drem_leaderboard.ranking import RacerProfile

# DREM's tail-light palette (website/src/constants/tailLightColours.ts). White is the car's "stop" colour.
HIGHLIGHT_PALETTE: tuple[str, ...] = ("#0000FF", "#FF0000", "#FF8200", "#800080",
                                      "#1E90FF", "#7CFC00", "#FF00FF", "#FFFF00")
AvatarChoice = Literal["identicon", "none"]


def anonymised_name(sub: str) -> str:
    """What results show for a deleted racer: stable per person, reveals nothing about them."""
    return f"Deleted racer {sub.replace('-', '')[:4]}"


def check_highlight_colour(value: str) -> str:
    colour = value.strip().upper()
    if colour not in HIGHLIGHT_PALETTE:
        raise InvalidInput(f"Pick a highlight colour from the palette: {' '.join(HIGHLIGHT_PALETTE)} "
                           "(white is reserved for the car's stop light).", field="highlight_colour")
    return colour


class Profile(BaseModel):
    model_config = ConfigDict(frozen=True)
    sub: str
    username: str | None = None
    # The racer's name as they write it (any script, NFC); None: the sign-in name is shown.
    display_name: str | None = None
    country_code: str | None = None
    highlight_colour: str | None = None
    avatar: AvatarChoice = "identicon"
    deleted: bool = False
    updated_at: str | None = None

    @property
    def shown_name(self) -> str:
        return self.display_name or self.username or anonymised_name(self.sub)


class ProfileUpdate(BaseModel):
    model_config = ConfigDict(extra="forbid")
    highlight_colour: str | None = Field(default=None, max_length=16)
    avatar: AvatarChoice | None = None
    # Shown next to the racer's name on boards and overlays; the account's sign-up country stays as it was.
    country_code: str | None = Field(default=None, max_length=64)
    display_name: str | None = Field(default=None, max_length=200)

    @field_validator("display_name")
    @classmethod
    def _display_name(cls, value: str | None) -> str | None:
        return None if value is None else check_display_name(value)

    @field_validator("country_code")
    @classmethod
    def _iso_country(cls, value: str | None) -> str | None:
        return None if value is None else normalise_country_code(value)

    @field_validator("highlight_colour")
    @classmethod
    def _palette(cls, value: str | None) -> str | None:
        return None if value is None else check_highlight_colour(value)


class PublicProfile(BaseModel):
    """The only profile fields anyone may see (leaderboards, overlays, GET /api/profiles/{username})."""
    username: str
    # What boards, overlays, PDFs and statistics print: the racer's own spelling, else the sign-in name.
    display_name: str = ""
    country_code: str | None = None
    highlight_colour: str | None = None
    avatar_url: str | None = None
    deleted: bool = False


def public_view(profile: Profile) -> PublicProfile:
    if profile.deleted or not profile.username:
        name = anonymised_name(profile.sub)
        return PublicProfile(username=name, display_name=name, deleted=profile.deleted)
    avatar = f"/api/profiles/{profile.username}/avatar.svg" if profile.avatar == "identicon" else None
    return PublicProfile(username=profile.username, display_name=profile.shown_name, country_code=profile.country_code,
                         highlight_colour=profile.highlight_colour, avatar_url=avatar)


class ProfileStore(Protocol):
    def get(self, sub: str) -> Profile | None: ...
    def put(self, profile: Profile) -> None: ...
    def sub_for_username(self, username: str) -> str | None: ...
    def link_username(self, username: str, sub: str) -> None: ...
    def unlink_username(self, username: str) -> None: ...


class AccountLookup(Protocol):
    """Finds an account's sub and country when a profile does not exist yet (e.g. the default admin)."""
    def get_user(self, username: str) -> object: ...


class BoardRows(Protocol):
    """Rebuilds a racer's rows on every board they are on (RaceService.refresh_racer_everywhere): board rows carry
    the racer's colour, country and name as they were when a race was published."""
    def refresh_racer_everywhere(self, racer_sub: str) -> int: ...


class ProfileService:
    def __init__(self, store: ProfileStore, accounts: AccountLookup | None = None, *,
                 boards: BoardRows | None = None) -> None:
        """`boards`: told after every profile change, so it reaches every leaderboard and overlay at once."""
        self._store = store
        self._accounts = accounts
        self._boards = boards

    def create_for(self, sub: str, username: str, country_code: str | None, display_name: str = "") -> Profile:
        profile = Profile(sub=sub, username=username, display_name=display_name or None, country_code=country_code,
                          updated_at=_now())
        self._store.put(profile)
        self._store.link_username(username, sub)
        return profile

    def shown_names(self, usernames: list[str]) -> dict[str, str]:
        """{sign-in name: what boards show} for racers shown together and named by their sign-in name (the league's
        rows): the display name, with the sign-in name after it when another of them goes by the same display name
        (drem_leaderboard.names). A name without a profile is shown as it is. Two batch reads (names to subs, then
        profiles) where the store offers them, however many racers."""
        unique = list(dict.fromkeys(usernames))
        get_subs = getattr(self._store, "subs_for_usernames", None)
        subs = get_subs(unique) if get_subs else {name.casefold(): sub for name in unique
                                                  if (sub := self._store.sub_for_username(name))}
        public = self.public_by_subs(list(dict.fromkeys(subs.values())))
        names = {}
        for username in unique:
            shown = public.get(subs.get(username.casefold(), ""))
            names[username] = (shown.display_name, shown.username) if shown else (username, username)
        return told_apart(names)

    def account_name(self, username: str) -> str | None:
        """The sign-in name as the account spells it, for a name typed in any case; None when there is none."""
        sub = self._store.sub_for_username(username)
        profile = self._store.get(sub) if sub else None
        return None if profile is None or profile.deleted else profile.username

    def own(self, caller: User) -> Profile:
        profile = self._store.get(caller.sub)
        if profile is not None and profile.deleted:
            # A token issued before the deletion must not bring the profile back.
            raise NotFound("This account has been deleted.")
        if profile is not None:
            return profile
        country = getattr(self._account(caller.username), "country_code", None) if self._accounts else None
        return self.create_for(caller.sub, caller.username, country)

    def update_own(self, caller: User, update: ProfileUpdate) -> Profile:
        return self._save(self.own(caller), update)

    def update_for(self, caller: User, username: str, update: ProfileUpdate) -> Profile:
        try:
            profile = self._by_username(username)
        except NotFound:
            # Accounts made outside drem (the default admin) get their profile on first use.
            account = self._account(username)
            if account is None:
                raise
            profile = self.create_for(account.sub, account.username, account.country_code)  # type: ignore[attr-defined]
        require_owner_or_role(caller, profile.sub, {Role.ADMIN})
        return self._save(profile, update)

    def public(self, username: str) -> PublicProfile:
        return public_view(self._by_username(username))

    def public_by_sub(self, sub: str) -> PublicProfile | None:
        """For leaderboard/race renderers: one GetItem; a deleted racer comes back anonymised."""
        profile = self._store.get(sub)
        return None if profile is None else public_view(profile)

    def public_by_subs(self, subs: list[str]) -> dict[str, PublicProfile]:
        """Many at once (one BatchGetItem per 100 racers where the store offers it); missing subs are left out."""
        get_many = getattr(self._store, "get_many", None)
        profiles = get_many(subs) if get_many else {s: p for s in subs if (p := self._store.get(s)) is not None}
        return {sub: public_view(profile) for sub, profile in profiles.items()}

    def avatar_svg(self, username: str) -> str:
        profile = self._by_username(username)
        if profile.avatar != "identicon":
            raise NotFound(f"{profile.username} has no avatar.", field="username")
        return identicon_svg(avatar_seed(profile.username or profile.sub), profile.highlight_colour,
                             profile.shown_name)

    def tombstone(self, sub: str, username: str) -> None:
        self._store.put(Profile(sub=sub, deleted=True, avatar="none", updated_at=_now()))
        self._store.unlink_username(username)
        PROCESS_SHOWN_NAMES.clear()  # the league board no longer shows the deleted racer's name

    def _by_username(self, username: str) -> Profile:
        sub = self._store.sub_for_username(username)
        profile = self._store.get(sub) if sub else None
        if profile is None or profile.deleted:
            raise NotFound(f"There is no racer {username!r}.", field="username")
        return profile

    def _account(self, username: str) -> object:
        return self._accounts.get_user(username) if self._accounts else None

    def _save(self, profile: Profile, update: ProfileUpdate) -> Profile:
        changes = {k: v for k, v in update.model_dump(exclude_unset=True).items() if v is not None}
        saved = profile.model_copy(update={**changes, "updated_at": _now()})
        self._store.put(saved)
        PROCESS_SHOWN_NAMES.clear()  # the league board shows the change at once (other processes within seconds)
        if self._boards is not None:
            self._boards.refresh_racer_everywhere(saved.sub)
        return saved


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


class ProfilesForBoards:
    """Board names, flags and colours from racer profiles; a deleted racer comes back anonymised."""

    def __init__(self, profiles: ProfileService) -> None:
        self._profiles = profiles

    def racer_profile(self, sub: str, fallback_username: str) -> RacerProfile:
        public = self._profiles.public_by_sub(sub)
        if public is None:
            return RacerProfile(username=fallback_username)
        # Boards key and show racers by the shown name; the avatar keeps the account's address.
        return RacerProfile(username=public.display_name or public.username, country_code=public.country_code,
                            highlight_colour=public.highlight_colour, avatar_url=public.avatar_url)
