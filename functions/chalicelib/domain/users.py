"""User accounts: self sign-up, staff registration, listing, roles, enabling and self-deletion.

Pure: the account directory (Cognito) and the profile store arrive as protocols, so the rules are testable and the
storage adapters stay the only code that talks to AWS.
"""
from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta
from typing import Annotated, Protocol

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, field_validator

from chalicelib.core.errors import Conflict, Forbidden, InvalidInput, NotFound
from chalicelib.core.principals import USER_ROLES, Role, User
from chalicelib.domain.countries import normalise_country_code
from chalicelib.domain.identity import password_policy_text
from chalicelib.domain.names import check_display_name, check_sign_in_name
from drem_infra import resources

# Deliberately simple: the directory sends a code to it, which is the real check.
_EMAIL = re.compile(r"^[^@\s<>\"']+@[^@\s<>\"']+\.[^@\s<>\"']+$")
MAX_PAGE = 60
# Cognito's status of a self sign-up whose emailed code has not been entered yet.
UNCONFIRMED = "UNCONFIRMED"


def check_email(email: str) -> str:
    email = email.strip()
    if len(email) > 254 or not _EMAIL.match(email):
        raise InvalidInput("Enter a valid email address, like racer@example.com.", field="email")
    return email


def check_password(password: str, field: str = "password") -> str:
    policy = resources.USER_POOL.password_policy
    missing = (len(password) < policy.minimum_length
               or (policy.require_lowercase and not re.search(r"[a-z]", password))
               or (policy.require_uppercase and not re.search(r"[A-Z]", password))
               or (policy.require_digits and not re.search(r"[0-9]", password))
               or (policy.require_symbols and not re.search(r"[^a-zA-Z0-9\s]", password)))
    if missing:
        raise InvalidInput(f"This password is too weak. {password_policy_text()}", field=field)
    return password


# The checks raise InvalidInput (not ValueError) so the 400 carries DREM's own wording for each rule.
EmailAddress = Annotated[str, Field(max_length=254), AfterValidator(check_email)]
CountryCode = Annotated[str, Field(max_length=8), AfterValidator(normalise_country_code)]


class SignUpForm(BaseModel):
    model_config = ConfigDict(extra="forbid")
    username: str = Field(max_length=128)
    email: EmailAddress
    country_code: CountryCode
    password: str = Field(max_length=256)
    # The name boards and certificates show, in any script; empty: the sign-in name.
    display_name: str = Field(default="", max_length=200)

    @field_validator("username")
    @classmethod
    def _username(cls, value: str) -> str:
        return check_sign_in_name(value.strip())

    @field_validator("display_name")
    @classmethod
    def _display_name(cls, value: str) -> str:
        return check_display_name(value) if value.strip() else ""

    @field_validator("password")
    @classmethod
    def _password(cls, value: str) -> str:
        return check_password(value)


class ConfirmSignUpForm(BaseModel):
    model_config = ConfigDict(extra="forbid")
    username: str = Field(min_length=1, max_length=128)
    code: str = Field(min_length=1, max_length=32, pattern=r"^\s*[0-9A-Za-z]+\s*$")


class StaffRegistrationForm(BaseModel):
    model_config = ConfigDict(extra="forbid")
    username: str = Field(max_length=128)
    email: EmailAddress
    country_code: CountryCode
    display_name: str = Field(default="", max_length=200)

    @field_validator("username")
    @classmethod
    def _username(cls, value: str) -> str:
        return check_sign_in_name(value.strip())

    @field_validator("display_name")
    @classmethod
    def _display_name(cls, value: str) -> str:
        return check_display_name(value) if value.strip() else ""


class RoleChange(BaseModel):
    model_config = ConfigDict(extra="forbid")
    role: Role

    @field_validator("role")
    @classmethod
    def _user_role(cls, role: Role) -> Role:
        if role not in USER_ROLES:
            raise ValueError(f"Choose one of: {', '.join(sorted(r.value for r in USER_ROLES))}.")
        return role


class DeleteSelfForm(BaseModel):
    """Typing the username (or the password) proves the click was meant."""
    model_config = ConfigDict(extra="forbid")
    confirm: str = Field(min_length=1, max_length=256)


class DirectoryUser(BaseModel):
    model_config = ConfigDict(frozen=True)
    username: str
    sub: str
    email: str | None = None
    country_code: str | None = None
    enabled: bool = True
    status: str = "CONFIRMED"
    created_at: str | None = None


class UserPage(BaseModel):
    users: list[DirectoryUser]
    next_token: str | None = None


class SignUpResult(BaseModel):
    username: str
    sub: str
    confirmed: bool
    message: str


class RegisteredUser(BaseModel):
    username: str
    sub: str
    email: str
    country_code: str
    display_name: str = ""
    role: Role = Role.RACER
    # Shown once: drem does not store it and Cognito will not return it again.
    temporary_password: str
    # True when this finished a registration that was interrupted earlier (the password is a new one).
    resumed: bool = False


class UserDirectory(Protocol):
    def sign_up(self, username: str, password: str, email: str, country_code: str) -> str: ...
    def confirm_sign_up(self, username: str, code: str) -> None: ...
    def confirm_without_code(self, username: str) -> None: ...
    def create_user(self, username: str, email: str, country_code: str, temporary_password: str) -> str: ...
    def get_user(self, username: str) -> DirectoryUser: ...
    def groups_of(self, username: str) -> list[str]: ...
    def members_of(self, group: str) -> set[str]: ...
    def reset_temporary_password(self, username: str, temporary_password: str) -> None: ...
    def list_users(self, prefix: str | None, limit: int, next_token: str | None) -> UserPage: ...
    def set_only_group(self, username: str, group: str) -> None: ...
    def set_enabled(self, username: str, enabled: bool) -> None: ...
    def delete_user(self, username: str) -> None: ...
    def password_matches(self, username: str, password: str) -> bool: ...


class ProfileKeeper(Protocol):
    """What account changes need from profiles (satisfied by `chalicelib.domain.profiles.ProfileService`)."""
    def create_for(self, sub: str, username: str, country_code: str | None, display_name: str = "") -> object: ...
    def account_name(self, username: str) -> str | None: ...
    def tombstone(self, sub: str, username: str) -> None: ...


class SessionEnder(Protocol):
    """Makes already issued tokens stop working (satisfied by chalicelib.services.RevokingSessions)."""
    def ended(self, sub: str) -> None: ...
    def reopened(self, sub: str) -> None: ...
    def roles_changed(self, sub: str, groups: frozenset[str]) -> None: ...


class _KeepSessions:
    def ended(self, sub: str) -> None:
        pass

    def reopened(self, sub: str) -> None:
        pass

    def roles_changed(self, sub: str, groups: frozenset[str]) -> None:
        pass


_KEEP_SESSIONS = _KeepSessions()


class OwnedDataEraser(Protocol):
    """Removes or anonymises what a user owns (their models) when they delete themselves; returns how many items."""
    def erase_owned_by(self, sub: str) -> int: ...


class ModelsEraser:
    """Satisfies OwnedDataEraser over `chalicelib.domain.racer_models.ModelService`: every model the user owns is
    deleted
    (its archive removed, the record kept as DELETED under an anonymised owner name, so race history stays whole),
    including models the racer had already soft-deleted (those keep their archive and name until now).
    Best moved into the models service as `erase_owned_by` — it reaches into the service's store and files."""

    def __init__(self, service: object) -> None:
        self._service = service

    def erase_owned_by(self, sub: str) -> int:
        from chalicelib.domain.profiles import anonymised_name
        from chalicelib.domain.racer_models import ModelChanged, ModelStatus

        store, files = self._service.store, self._service.files  # type: ignore[attr-defined]
        erased, token = 0, None
        while True:
            page = store.list_owner(sub, limit=100, next_token=token, include_deleted=True)
            for record in page.models:
                stored = {record.s3_key, record.upload_key, record.converted_key, record.scrutineer_clip_key}
                for key in stored - {None}:
                    files.delete(key)
                gone = record.model_copy(update={"status": ModelStatus.DELETED, "owner_username": anonymised_name(sub)})
                try:
                    store.replace(gone, expected_status=record.status)
                except ModelChanged as exc:
                    raise Conflict("A model changed while your account was being deleted; try again.") from exc
                erased += 1
            token = page.next_token
            if not token:
                return erased


def _created_before(user: DirectoryUser, cutoff: datetime) -> bool:
    if not user.created_at:
        return True  # no creation time to go by: old enough
    created = datetime.fromisoformat(user.created_at.replace("Z", "+00:00"))
    return (created if created.tzinfo else created.replace(tzinfo=UTC)) <= cutoff


class UserService:
    def __init__(self, directory: UserDirectory, profiles: ProfileKeeper,
                 erasers: tuple[OwnedDataEraser, ...] = (), *, confirm_sign_ups: bool = False,
                 sessions: SessionEnder = _KEEP_SESSIONS) -> None:
        self._directory = directory
        self._sessions = sessions
        self._profiles = profiles
        self._erasers = erasers
        # Local stacks send no email, so no code could ever arrive: a self sign-up is confirmed at once (it only
        # ever gets the racer role; staff can disable it). On AWS, Cognito emails the code and checks it.
        self._confirm_sign_ups = confirm_sign_ups

    # Registrations are three writes (account, profile, role group), in that order: an account is complete once it
    # has a group, so "no group" marks one a crash interrupted. Repeating the same registration finishes it
    # (`_resume`), races refuse a racer without a group, and `finish_interrupted_registrations` repairs them (at the
    # app's start and every REGISTRATION_REPAIR_S after, in drem_local.appserver).

    def sign_up(self, form: SignUpForm) -> SignUpResult:
        self._not_taken_in_another_case(form.username)
        resumed = False
        try:
            sub = self._directory.sign_up(form.username, form.password, form.email, form.country_code)
            username = form.username
        except Conflict:
            # The same sign-up again: finish what a crash left (no group yet), or, locally, the confirmation that
            # never came. A complete sign-up of someone else, or one awaiting its emailed code, stays "taken".
            existing = self._resumable(form.username, form.email, status=UNCONFIRMED)
            if self._directory.groups_of(existing.username) and not self._confirm_sign_ups:
                raise
            username, sub, resumed = existing.username, existing.sub, True
        self._finish(username, sub, form.country_code, form.display_name)
        started = "This sign-up was already started. " if resumed else ""
        if self._confirm_sign_ups:
            self._directory.confirm_without_code(username)
            return SignUpResult(username=username, sub=sub, confirmed=True,
                                message=f"{started}Your account is ready; you can sign in now.")
        return SignUpResult(username=username, sub=sub, confirmed=False,
                            message=f"{started}Check {form.email} for a confirmation code, then confirm your account.")

    def confirm_sign_up(self, form: ConfirmSignUpForm) -> dict[str, str]:
        self._directory.confirm_sign_up(form.username.strip(), form.code.strip())
        return {"username": form.username.strip(), "message": "Your account is confirmed; you can sign in now."}

    def register_racer(self, form: StaffRegistrationForm) -> RegisteredUser:
        """Create the account, profile and racer group. Registering the same name and email again while the racer
        has never signed in finishes whatever is missing and shows a new temporary password (the answer of the
        first attempt may never have reached the desk)."""
        self._not_taken_in_another_case(form.username)
        password = resources.USER_POOL.password_policy.random_password()
        resumed = False
        try:
            sub = self._directory.create_user(form.username, form.email, form.country_code, password)
        except Conflict:
            existing = self._resumable(form.username, form.email, status="FORCE_CHANGE_PASSWORD")
            self._directory.reset_temporary_password(existing.username, password)
            sub, resumed = existing.sub, True
        self._finish(form.username, sub, form.country_code, form.display_name)
        return RegisteredUser(username=form.username, sub=sub, email=form.email, country_code=form.country_code,
                              display_name=form.display_name or form.username, temporary_password=password,
                              resumed=resumed)

    def finish_interrupted_registrations(self, *, older_than_s: float = 0.0, now: datetime | None = None) -> list[str]:
        """Accounts without a role group were cut off mid-registration: give them their profile and the racer
        group. Returns their usernames (the caller says so in plain words). The app runs this at start (`older_than_s`
        0: nothing is in flight) and then every little while, skipping accounts created in the last `older_than_s`
        seconds, whose registration may still be running. Cheap enough to repeat: one listing of each role group
        and of the accounts, and a group lookup only for an account in none of them."""
        grouped: set[str] = set()
        for role in USER_ROLES:
            grouped |= self._directory.members_of(role.value)
        cutoff = (now or datetime.now(UTC)) - timedelta(seconds=older_than_s)
        finished, token = [], None
        while True:
            page = self._directory.list_users(None, MAX_PAGE, token)
            for user in page.users:
                if user.username in grouped or (older_than_s and not _created_before(user, cutoff)):
                    continue
                if not self._directory.groups_of(user.username):  # the listing is not a snapshot: ask again
                    self._finish(user.username, user.sub, user.country_code)
                    finished.append(user.username)
            token = page.next_token
            if not token:
                return finished

    def _resumable(self, username: str, email: str, *, status: str) -> DirectoryUser:
        """The existing account, if this is a repeat of its own unfinished registration; else the name is taken."""
        existing = self._directory.get_user(username)
        if existing.status != status or (existing.email or "").casefold() != email.casefold():
            raise Conflict(f"The user name '{username}' is taken.", field="username")
        return existing

    def account_name(self, username: str) -> str | None:
        """The account's own spelling of a sign-in name typed in any case (Cognito's pool is case-insensitive; the
        local one is not): the profiles' case-folded index, else, for an account made outside drem without a
        profile yet (the first admin), its lower-case spelling in the directory."""
        owner = self._profiles.account_name(username)
        if owner is None and username != username.lower():
            owner = self._existing_name(username.lower())
        return owner

    def _not_taken_in_another_case(self, username: str) -> None:
        """'ADMIN' beside 'admin' would be two people nobody can tell apart at the desk."""
        owner = self.account_name(username)
        if owner is not None and owner != username:
            raise Conflict(f"The user name '{username}' is taken.", field="username")

    def _existing_name(self, username: str) -> str | None:
        try:
            return self._directory.get_user(username).username
        except NotFound:
            return None

    def _finish(self, username: str, sub: str, country_code: str | None, display_name: str = "") -> None:
        self._profiles.create_for(sub, username, country_code, display_name)
        if not self._directory.groups_of(username):  # a role given meanwhile (say, operator) is kept
            self._directory.set_only_group(username, Role.RACER.value)

    def list_users(self, prefix: str | None = None, limit: int = MAX_PAGE, next_token: str | None = None) -> UserPage:
        prefix = (prefix or "").strip() or None
        if prefix is not None and not re.fullmatch(r"[a-zA-Z0-9._-]{1,128}", prefix):
            raise InvalidInput("Search with the start of a username (letters, digits, '.', '_', '-').",
                               field="prefix")
        if not 1 <= limit <= MAX_PAGE:
            raise InvalidInput(f"limit is between 1 and {MAX_PAGE}.", field="limit")
        return self._directory.list_users(prefix, limit, next_token or None)

    def change_role(self, caller: User, username: str, change: RoleChange) -> dict[str, str]:
        self._not_self(caller, username, "change your own role")
        target = self._directory.get_user(username)
        self._directory.set_only_group(target.username, change.role.value)
        # A demoted admin's token must not stay admin for the rest of its hour.
        self._sessions.roles_changed(target.sub, frozenset({change.role.value}))
        return {"username": target.username, "role": change.role.value}

    def set_enabled(self, caller: User, username: str, enabled: bool) -> DirectoryUser:
        self._not_self(caller, username, "disable or enable yourself")
        target = self._directory.get_user(username)
        self._directory.set_enabled(target.username, enabled)
        if enabled:
            self._sessions.reopened(target.sub)
        else:
            self._sessions.ended(target.sub)
        return target.model_copy(update={"enabled": enabled})

    def confirm_account(self, username: str) -> DirectoryUser:
        """Staff confirm a self sign-up still waiting for its emailed code (on AWS without SES, or with a mistyped
        address, the code never arrives); the racer can sign in with the password they chose. Only an account in
        that state: a staff-registered one waits for its new password instead, which this would not give it."""
        target = self._directory.get_user(username)
        if target.status != UNCONFIRMED:
            raise Conflict(f"{target.username} is not waiting for an emailed code; there is nothing to confirm.",
                           field="username")
        self._directory.confirm_without_code(target.username)
        if not self._directory.groups_of(target.username):  # a sign-up cut off before its profile and role
            self._finish(target.username, target.sub, target.country_code)
        return target.model_copy(update={"status": "CONFIRMED"})

    def delete_self(self, caller: User, form: DeleteSelfForm) -> dict[str, object]:
        confirmed = (form.confirm.strip().casefold() == caller.username.casefold()
                     or self._directory.password_matches(caller.username, form.confirm))
        if not confirmed:
            raise InvalidInput("Type your username (or your password) to confirm deleting your account.",
                               field="confirm")
        erased = sum(eraser.erase_owned_by(caller.sub) for eraser in self._erasers)
        self._profiles.tombstone(caller.sub, caller.username)
        # Last, so a failure above leaves an account the user can retry the deletion with.
        self._directory.delete_user(caller.username)
        self._sessions.ended(caller.sub)
        return {"deleted": caller.username, "items_erased": erased}

    @staticmethod
    def _not_self(caller: User, username: str, what: str) -> None:
        # An admin locking themselves out could leave the event with no admin at all.
        if caller.username.casefold() == username.casefold():
            raise Forbidden(f"You cannot {what}; ask another admin.")
