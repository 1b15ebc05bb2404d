"""Domain errors: what went wrong, in the user's terms. `chalicelib.http_errors` is the one place that maps them to
HTTP; storage adapters translate AWS error codes into them. Never branch on an error's message text."""
from __future__ import annotations


class DremError(Exception):
    """Base of every error a user may see. `field` names the form/JSON field at fault, when there is one."""

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.field = field


class InvalidInput(DremError):
    """The request is malformed or a value breaks a rule (names the field)."""


class NotAuthenticated(DremError):
    """No credentials, or credentials that could not be verified."""


class TokenExpired(NotAuthenticated):
    """A well-formed, correctly signed token past its `exp` (a refresh may help)."""


class InvalidCredentials(NotAuthenticated):
    """Sign-in with a wrong username or password (deliberately not saying which)."""


class AccountNotReady(DremError):
    """The account exists but cannot sign in yet (unconfirmed, or a password reset is pending)."""


class Forbidden(DremError):
    """Signed in, but not allowed to do this."""


class CsrfRejected(Forbidden):
    """A state-changing browser request without a matching CSRF token."""


class NotFound(DremError):
    pass


class Conflict(DremError):
    pass


class PayloadTooLarge(DremError):
    pass


class RateLimited(DremError):
    """Too many attempts (or a busy backend); `retry_after` seconds, when known, become the Retry-After header."""

    def __init__(self, message: str, *, field: str | None = None, retry_after: int | None = None) -> None:
        super().__init__(message, field=field)
        self.retry_after = retry_after


class ServiceUnavailable(DremError):
    """A backing service (storage, identity provider) cannot be reached or is not configured."""


class StorageDiskFull(ServiceUnavailable):
    """The storage server's disk is full or read-only: the change was not stored; the message (the storage
    server's own, naming the path) says what to free, and that nothing stored before is lost."""


class MaybeStored(ServiceUnavailable):
    """Storage went away during a write: the change may or may not have been stored (the message says how to
    find out, and whether a retry is safe)."""


class UpstreamError(DremError):
    """A backing service answered with an error drem does not know how to explain."""
