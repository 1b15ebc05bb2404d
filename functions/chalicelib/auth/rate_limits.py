"""Rate limits on the doors a guesser would knock on: sign-in, sign-up and device activation.

Counted per app process in memory (sliding windows). Locally there is one app process, so the limits are exact.
On AWS each Lambda container counts for itself, so the effective limit is a multiple of these (Cognito throttles
sign-in attempts on its own as well). Over a limit the caller gets 429 with `Retry-After` and a plain message.

Why these numbers: a racer who mistypes a password a few times must never be locked out, a whole venue behind one
NAT address (AWS) must be able to sign in at the start of the event, and a guesser must not get far: 10 wrong
passwords per account per 5 minutes is ~3,000 guesses a day instead of 64 a second.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from chalicelib.domain.errors import InvalidCredentials, InvalidInput, RateLimited

T = TypeVar("T")
_MAX_KEYS = 20_000  # memory bound: the oldest keys are forgotten first


@dataclass(frozen=True)
class Limit:
    events: int
    window_s: float
    what: str  # for the message: "sign-in attempts for this account"


class SlidingWindow:
    def __init__(self, limit: Limit, clock: Callable[[], float] = time.monotonic) -> None:
        self.limit = limit
        self._clock = clock
        self._lock = threading.Lock()
        self._events: OrderedDict[str, deque[float]] = OrderedDict()

    def retry_after(self, key: str) -> int | None:
        """Seconds until `key` may try again, or None when it may now."""
        with self._lock:
            events = self._pruned(key)
            if len(events) < self.limit.events:
                return None
            return max(1, int(events[0] + self.limit.window_s - self._clock()) + 1)

    def record(self, key: str) -> None:
        with self._lock:
            self._pruned(key).append(self._clock())
            self._events.move_to_end(key)
            while len(self._events) > _MAX_KEYS:
                self._events.popitem(last=False)

    def forget(self, key: str) -> None:
        with self._lock:
            self._events.pop(key, None)

    def clear(self) -> None:
        with self._lock:
            self._events.clear()

    def require(self, key: str) -> None:
        wait = self.retry_after(key)
        if wait is not None:
            raise RateLimited(f"Too many {self.limit.what}; try again in {_duration(wait)}.", retry_after=wait)

    def _pruned(self, key: str) -> deque[float]:
        events = self._events.setdefault(key, deque())
        horizon = self._clock() - self.limit.window_s
        while events and events[0] <= horizon:
            events.popleft()
        return events


SIGN_IN_FAILURES_PER_ACCOUNT = SlidingWindow(Limit(10, 300, "wrong passwords for this account"))
SIGN_IN_FAILURES_PER_ADDRESS = SlidingWindow(Limit(30, 300, "wrong passwords from this device"))
SIGN_UPS_PER_ADDRESS = SlidingWindow(Limit(20, 600, "sign-ups from this device"))
ACTIVATION_FAILURES_PER_ADDRESS = SlidingWindow(Limit(10, 600, "wrong activation codes from this device"))
ALL = (SIGN_IN_FAILURES_PER_ACCOUNT, SIGN_IN_FAILURES_PER_ADDRESS, SIGN_UPS_PER_ADDRESS,
       ACTIVATION_FAILURES_PER_ADDRESS)


def guarded_sign_in(sign_in: Callable[[], T], username: str, address: str) -> T:
    account = username.strip().casefold()
    SIGN_IN_FAILURES_PER_ACCOUNT.require(account)
    SIGN_IN_FAILURES_PER_ADDRESS.require(address)
    try:
        result = sign_in()
    except InvalidCredentials:
        SIGN_IN_FAILURES_PER_ACCOUNT.record(account)
        SIGN_IN_FAILURES_PER_ADDRESS.record(address)
        raise
    SIGN_IN_FAILURES_PER_ACCOUNT.forget(account)
    return result


def guarded_sign_up(sign_up: Callable[[], T], address: str) -> T:
    SIGN_UPS_PER_ADDRESS.require(address)
    SIGN_UPS_PER_ADDRESS.record(address)
    return sign_up()


def guarded_activation(activate: Callable[[], T], address: str) -> T:
    ACTIVATION_FAILURES_PER_ADDRESS.require(address)
    try:
        return activate()
    except InvalidInput as exc:
        if exc.field == "code":  # a wrong or used code: what a guesser produces
            ACTIVATION_FAILURES_PER_ADDRESS.record(address)
        raise


def client_address(request: object) -> str:
    """The caller's address as API Gateway / `chalice local` report it ("unknown" if neither does)."""
    context = getattr(request, "context", None) or {}
    return str((context.get("identity") or {}).get("sourceIp") or "unknown")


def _duration(seconds: int) -> str:
    if seconds < 90:
        return f"{seconds} seconds"
    return f"{round(seconds / 60)} minutes"
