"""Who may send and see the cars' camera feeds, answered from the app's own code (chalicelib) and storage.

- A car sends its frames with its device credential (`Authorization: Device <id>.<secret>`, as it calls the app);
  checked by the app's ActivationService, and remembered for CREDENTIAL_TTL_S so 15 frames a second cost no reads
  (a revoked credential stops working here within that time).
- The public sees the car now racing on an event's track: the track's live race (the same pointer the overlay
  follows) names its car. Read at most once a second per track, shared by all viewers.
  The car's record also carries the camera settings staff chose (Cars page): every answer to the car hands them on.
- Staff (admin, operator) preview any car: their drem session cookie, resolved as the app does. Cookies ignore
  ports, so the session of the pages reaches the live server on its own port too.
All calls block (storage reads): the routes run them in the server's worker threads.
"""
from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass

from chalicelib import services  # noqa: E402
from chalicelib.auth.sessions import resolve_caller  # noqa: E402
from chalicelib.core.errors import DremError  # noqa: E402
from chalicelib.core.principals import Role  # noqa: E402
from drem_live import app_code  # noqa: F401  (puts functions/ on sys.path first)

CREDENTIAL_TTL_S = 10.0
STAFF_TTL_S = 10.0
RACING_TTL_S = 1.0
PREVIEW_ROLES = frozenset({Role.ADMIN, Role.OPERATOR})
_CACHE_CAP = 10_000


@dataclass(frozen=True)
class Car:
    device_id: str
    hostname: str
    video: dict | None = None  # the camera settings staff chose on the Cars page (None: the car's own)


class VideoAccess:
    def __init__(self) -> None:
        self._cars: dict[str, tuple[float, Car | None]] = {}
        self._staff: dict[str, tuple[float, bool]] = {}
        self._racing: dict[tuple[str, str], tuple[float, str | None]] = {}

    def car(self, authorization: str) -> Car | None:
        """The car behind `Authorization: Device …`, or None (not a car's valid credential)."""
        scheme, _, credential = authorization.strip().partition(" ")
        if scheme.lower() != "device" or not credential.strip():
            return None
        cached = self._cars.get(credential)
        if cached is not None and cached[0] > time.monotonic():
            return cached[1]
        try:
            device = services.activation_service().verify(credential.strip())
            record = services.device_store().get_device(device.device_id)
        except DremError:
            device, record = None, None
        car = (Car(record.device_id, record.hostname, record.video.model_dump(mode="json") if record.video else None)
               if device and record and device.device_kind == "car" else None)
        self._remember(self._cars, credential, car, CREDENTIAL_TTL_S)
        return car

    def is_staff(self, cookies: Mapping[str, str]) -> bool:
        key = "|".join(f"{k}={v}" for k, v in sorted(cookies.items()) if k.startswith("drem_"))
        if not key:
            return False
        cached = self._staff.get(key)
        if cached is not None and cached[0] > time.monotonic():
            return cached[1]
        try:
            principal = resolve_caller({}, cookies).principal
            allowed = bool(principal.roles & PREVIEW_ROLES)
        except DremError:
            allowed = False
        self._remember(self._staff, key, allowed, STAFF_TTL_S)
        return allowed

    def racing_car(self, event_id: str, track_id: str) -> str | None:
        """The name (device id or hostname) of the car of the track's live race, if the race names one."""
        key = (event_id, track_id)
        cached = self._racing.get(key)
        if cached is not None and cached[0] > time.monotonic():
            return cached[1]
        car: str | None = None
        try:
            race_id = services.race_store().live_race_id(event_id, track_id)
            record = services.race_store().get(event_id, race_id) if race_id else None
            car = record.race.car if record is not None else None
        except DremError:
            car = None
        self._remember(self._racing, key, car, RACING_TTL_S)
        return car

    @staticmethod
    def _remember(cache: dict, key: object, value: object, ttl_s: float) -> None:
        if len(cache) >= _CACHE_CAP:
            cache.clear()
        cache[key] = (time.monotonic() + ttl_s, value)
