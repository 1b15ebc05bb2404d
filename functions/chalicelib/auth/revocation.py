"""Tokens end within seconds of sign-out, disable, role change or deletion, not when they expire (up to 1 h).

Access tokens are JWTs checked offline, so Cognito's own revocation (GlobalSignOut revokes refresh tokens) does not
reach an access token already issued. drem keeps one small record per user (a `RevocationMark`, table `sessions`)
and refuses a token of that user issued before the mark. Each app process caches the mark for `CACHE_TTL_S`
seconds (a hit costs a dict look-up, a miss one DynamoDB GetItem: figures in docs/security.md), so a change made
through another process (another Lambda container) takes effect within that time; in the process that made it, at
once.

Token `iat` has one-second resolution. Within the mark's own second, what tells tokens issued before the change from
those issued after it:
* sign-out: the signed-out session's `origin_jti` (shared by every token of one sign-in, refreshes included);
* role change: the groups; a token carrying other groups than the new ones is from before;
* disable and deletion: nothing is needed: no token can be issued after them, so the whole second is revoked
  (re-enabling opens the second again).
"""
from __future__ import annotations

import math
import threading
import time
from typing import Protocol

from pydantic import BaseModel

from chalicelib.core.errors import NotAuthenticated

CACHE_TTL_S = 5.0


class RevocationMark(BaseModel):
    not_before: int  # epoch second: tokens issued earlier are revoked
    whole_second: bool = False  # tokens issued during `not_before` itself are revoked too
    ended_sessions: frozenset[str] = frozenset()  # origin_jti of signed-out sessions (for the second `not_before`)
    groups: frozenset[str] | None = None  # the groups after a role change (for the second `not_before`)

    def revokes(self, issued_at: object, origin_jti: object, groups: frozenset[str]) -> bool:
        if not isinstance(issued_at, (int, float)) or issued_at < self.not_before:
            return True
        if issued_at >= self.not_before + 1:
            return False
        return (self.whole_second or origin_jti in self.ended_sessions
                or (self.groups is not None and groups != self.groups))

    def then(self, later: RevocationMark) -> RevocationMark:
        """This mark followed by `later` (the same user, a second change)."""
        if later.not_before > self.not_before:
            return later
        if later.not_before < self.not_before:  # clocks of two processes disagree: keep the stricter mark
            return self.model_copy(update={"ended_sessions": self.ended_sessions | later.ended_sessions})
        return RevocationMark(not_before=self.not_before, whole_second=later.whole_second,
                              ended_sessions=self.ended_sessions | later.ended_sessions,
                              groups=later.groups if later.groups is not None else self.groups)


class RevocationStore(Protocol):
    def mark(self, sub: str) -> RevocationMark | None: ...
    def put_mark(self, sub: str, mark: RevocationMark) -> None: ...


class RevocationList:
    def __init__(self, ttl_s: float = CACHE_TTL_S) -> None:
        self._ttl_s = ttl_s
        self._lock = threading.Lock()
        self._cached: dict[str, tuple[float, RevocationMark | None]] = {}

    def signed_out(self, store: RevocationStore, sub: str, origin_jti: str | None) -> None:
        self._add(store, sub, RevocationMark(not_before=_this_second(),
                                             ended_sessions=frozenset({origin_jti} if origin_jti else ())))

    def ended(self, store: RevocationStore, sub: str) -> None:
        """Disabled or deleted: no token of `sub` issued so far is honoured."""
        self._add(store, sub, RevocationMark(not_before=_this_second(), whole_second=True))

    def reopened(self, store: RevocationStore, sub: str) -> None:
        """Enabled again: tokens issued from now on are fine."""
        self._add(store, sub, RevocationMark(not_before=_this_second(), whole_second=False))

    def roles_changed(self, store: RevocationStore, sub: str, groups: frozenset[str]) -> None:
        """Tokens carrying the old groups are refused; the browser's refresh token brings the new ones."""
        self._add(store, sub, RevocationMark(not_before=_this_second(), groups=groups))

    def require_current(self, store: RevocationStore, sub: str, claims: dict) -> None:
        mark = self._mark(store, sub)
        groups = claims.get("cognito:groups") or []
        if mark is not None and mark.revokes(claims.get("iat"), claims.get("origin_jti"),
                                             frozenset(str(g) for g in groups if isinstance(groups, list))):
            raise NotAuthenticated("This session has ended; sign in again.")

    def clear(self) -> None:
        with self._lock:
            self._cached.clear()

    def _add(self, store: RevocationStore, sub: str, change: RevocationMark) -> None:
        current = store.mark(sub)
        mark = current.then(change) if current is not None else change
        store.put_mark(sub, mark)
        with self._lock:
            self._cached[sub] = (time.monotonic(), mark)

    def _mark(self, store: RevocationStore, sub: str) -> RevocationMark | None:
        now = time.monotonic()
        with self._lock:
            hit = self._cached.get(sub)
        if hit is not None and now - hit[0] < self._ttl_s:
            return hit[1]
        mark = store.mark(sub)  # outside the lock: a slow read must not stall every other request
        with self._lock:
            self._cached[sub] = (now, mark)
        return mark


def _this_second() -> int:
    return math.floor(time.time())


REVOKED = RevocationList()
