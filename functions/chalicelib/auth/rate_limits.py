"""Rate limits on the doors a guesser would knock on: sign-in, sign-up and device activation.

Counted per app process in memory (sliding windows). Locally there is one app process, so the limits are exact.
On AWS each Lambda container counts for itself, so the effective limit is a multiple of these (Cognito throttles
sign-in attempts on its own as well). Over a limit the caller gets 429 with `Retry-After` and a plain message.

Why these numbers and shapes: a racer who mistypes a password a few times must never be locked out, a whole venue
behind one address (a NAT on AWS, or one phone among hundreds on the LAN) must be able to sign in at the start of the
event whatever one guesser does, and a guesser must not get far: at most 10 password checks a minute per account
from browsers new to it. A browser that signed in before (`auth.known_devices`) is checked first, so nobody can lock
a chosen account (the admin's) out. The client address is the real peer address the app server reports.
"""
from __future__ import annotations

import threading
import time
from collections import OrderedDict, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

from chalicelib.core.errors import InvalidCredentials, InvalidInput, RateLimited

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

    def record_then_require(self, key: str) -> None:
        """Count one more event; raise RateLimited if the window was already full before it."""
        wait = self.retry_after(key)
        self.record(key)
        if wait is not None:
            raise RateLimited(f"Too many {self.limit.what}; try again in {_duration(wait)}.", retry_after=wait)

    def _pruned(self, key: str) -> deque[float]:
        events = self._events.setdefault(key, deque())
        horizon = self._clock() - self.limit.window_s
        while events and events[0] <= horizon:
            events.popleft()
        return events


# A guesser's budget at one account, shared by every browser that has not signed in to it before (a legitimate
# first-time sign-in of an account under attack shares it too: the trade-off docs/security.md describes).
GUESSES_PER_ACCOUNT = SlidingWindow(Limit(10, 60, "wrong passwords for this account from new browsers"))
# A browser that signed in to the account before only answers for its own mistakes.
FAILURES_PER_KNOWN_DEVICE = SlidingWindow(Limit(10, 300, "wrong passwords from this browser"))
# Password spraying from one address: past this, its wrong passwords are answered 429 (a right one still signs in,
# or one phone could lock a whole venue out behind its NAT).
FAILURES_PER_ADDRESS = SlidingWindow(Limit(30, 300, "wrong passwords from this network address"))
SIGN_UPS_PER_ADDRESS = SlidingWindow(Limit(20, 600, "sign-ups from this device"))
ACTIVATION_FAILURES_PER_ADDRESS = SlidingWindow(Limit(10, 600, "wrong activation codes from this device"))
ALL = (GUESSES_PER_ACCOUNT, FAILURES_PER_KNOWN_DEVICE, FAILURES_PER_ADDRESS, SIGN_UPS_PER_ADDRESS,
       ACTIVATION_FAILURES_PER_ADDRESS)


def guarded_sign_in(sign_in: Callable[[], T], username: str, address: str, known_device: str | None = None) -> T:
    """Run `sign_in` unless the account's guess budget is spent; never refuse a known browser's right password.

    `known_device` is the id of a browser that signed in to this account before (`auth.known_devices`): its password
    is checked first, whatever anyone else did. Other attempts may check a password only while the account's
    budget for new browsers lasts (10 wrong per minute: all a guesser gets, however many phones share an address).
    A success does not reset the budget, or a guesser could wait for the owner to sign in and start over."""
    account = username.strip().casefold()
    if known_device is not None:
        FAILURES_PER_KNOWN_DEVICE.require(known_device)
        try:
            return sign_in()
        except InvalidCredentials:
            FAILURES_PER_KNOWN_DEVICE.record(known_device)
            raise
    GUESSES_PER_ACCOUNT.require(account)
    try:
        return sign_in()
    except InvalidCredentials:
        GUESSES_PER_ACCOUNT.record(account)
        FAILURES_PER_ADDRESS.record_then_require(address)
        raise


def guarded_sign_up(sign_up: Callable[[], T], address: str) -> T:
    SIGN_UPS_PER_ADDRESS.require(address)
    SIGN_UPS_PER_ADDRESS.record(address)
    return sign_up()


def guarded_activation(activate: Callable[[], T], address: str) -> T:
    """A valid code always activates (it is 100 random bits, not guessable); wrong ones are limited per address."""
    try:
        return activate()
    except InvalidInput as exc:
        if exc.field == "code":  # a wrong or used code: what a guesser produces
            ACTIVATION_FAILURES_PER_ADDRESS.record_then_require(address)
        raise


def client_address(request: object) -> str:
    """The caller's address as API Gateway or drem's app server report it (`sourceIp`; "unknown" if neither does)."""
    context = getattr(request, "context", None) or {}
    return str((context.get("identity") or {}).get("sourceIp") or "unknown")


def _duration(seconds: int) -> str:
    if seconds < 90:
        return f"{seconds} seconds"
    return f"{round(seconds / 60)} minutes"
