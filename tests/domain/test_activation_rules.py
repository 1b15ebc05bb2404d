"""The rules of activating a device, on the fast domain tier: ActivationService over the in-memory stores
(tests/in_memory), no moto and no HTTP. The credential at work on device routes, what is stored, request validation
and roles stay in tests/unit/test_activation_api.py."""
from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from chalicelib.core.errors import InvalidInput, NotAuthenticated
from chalicelib.core.principals import Device, User
from chalicelib.domain.activation import ActivationCodeRequest, ActivationExchange, ActivationService
from chalicelib.domain.devices import DeviceKind, Telemetry
from chalicelib.domain.fleets import FleetRecord
from tests.in_memory.devices import InMemoryDeviceStore
from tests.in_memory.events import InMemoryFleetStore

pytestmark = pytest.mark.domain

OPERATOR = User(sub="op-sub", username="op", groups=frozenset({"operator"}))
ATTEMPT = "attempt-0123456789abcdef"


@dataclass
class Clock:
    now_ms: int = 1_700_000_000_000

    def __call__(self) -> int:
        return self.now_ms


@dataclass
class Bench:
    """An operator issuing codes for fleet "f1" and devices redeeming them."""
    service: ActivationService
    devices: InMemoryDeviceStore
    clock: Clock = field(default_factory=Clock)

    def code(self, hostname: str = "car-01", kind: DeviceKind = DeviceKind.CAR, ttl_minutes: int = 60) -> str:
        request = ActivationCodeRequest(fleet_id="f1", hostname=hostname, device_kind=kind, ttl_minutes=ttl_minutes)
        return self.service.issue_code(OPERATOR, request).code

    def activate(self, code: str, hostname: str = "car-01", kind: DeviceKind = DeviceKind.CAR,
                 attempt_id: str | None = None) -> str:
        exchange = ActivationExchange(code=code, hostname=hostname, device_kind=kind, attempt_id=attempt_id)
        return self.service.activate(exchange).credential

    def refusal(self, code: str, **kwargs: object) -> InvalidInput:
        with pytest.raises(InvalidInput) as refused:
            self.activate(code, **kwargs)  # type: ignore[arg-type]
        return refused.value


@pytest.fixture
def bench() -> Bench:
    clock, devices, fleets = Clock(), InMemoryDeviceStore(), InMemoryFleetStore()
    fleets.put_fleet(FleetRecord(fleet_id="f1", name="North", created_at_ms=1, created_by="op"))
    return Bench(ActivationService(devices, fleets, clock), devices, clock)


def test_a_code_is_for_one_kind_and_host_and_a_mismatch_does_not_spend_it(bench: Bench) -> None:
    code = bench.code("timer-a", DeviceKind.TIMER)
    assert bench.refusal(code, hostname="timer-a", kind=DeviceKind.CAR).field == "device_kind"
    assert bench.refusal(code, hostname="timer-b", kind=DeviceKind.TIMER).field == "hostname"
    credential = bench.activate(code.lower().replace("-", " "), hostname="TIMER-A", kind=DeviceKind.TIMER)
    assert bench.service.verify(credential).device_kind == "timer"
    assert [line.hostname for line in bench.devices.status_board().values()] == ["TIMER-A"]


def test_a_code_is_used_once_and_refused_once_it_expires(bench: Bench) -> None:
    first, late = bench.code("car-01"), bench.code("car-02", ttl_minutes=5)
    bench.activate(first)
    assert "already been used" in str(bench.refusal(first))

    bench.clock.now_ms += 5 * 60_000  # the moment it expires
    refused = bench.refusal(late, hostname="car-02")
    assert "expired" in str(refused) and refused.field == "code"
    assert len(bench.devices.status_board()) == 1


def test_an_unknown_code_is_refused(bench: Bench) -> None:
    assert bench.refusal("AAAA-BBBB-CCCC-DDDD-EEEE").field == "code"


def test_a_lost_answer_is_resumed_by_the_same_attempt_until_the_device_is_heard_from(bench: Bench) -> None:
    code = bench.code()
    lost = bench.activate(code, attempt_id=ATTEMPT)  # ... but imagine the car never read this answer

    for other in (None, "someone-else-0123456789"):
        assert "already been used" in str(bench.refusal(code, attempt_id=other))
    assert bench.service.verify(lost)  # the refused tries changed nothing

    retry = bench.activate(code, attempt_id=ATTEMPT)
    assert retry.split(".")[0] == lost.split(".")[0]  # the same device, with a fresh secret
    assert bench.service.verify(retry)
    with pytest.raises(NotAuthenticated):
        bench.service.verify(lost)
    assert len(bench.devices.status_board()) == 1

    bench.devices.record_heartbeat(retry.split(".")[0], bench.clock(), Telemetry())  # the answer did arrive
    assert "already been used" in str(bench.refusal(code, attempt_id=ATTEMPT))
    assert bench.service.verify(retry)


def test_a_rotated_secret_replaces_the_old_one_at_once(bench: Bench) -> None:
    old = bench.activate(bench.code())
    device = bench.service.verify(old)
    new = bench.service.rotate(device).credential
    assert bench.service.verify(new) == device
    with pytest.raises(NotAuthenticated):
        bench.service.verify(old)

    bench.devices.delete_device(device.device_id)  # deregistered: nothing verifies, nothing rotates
    with pytest.raises(NotAuthenticated):
        bench.service.verify(new)
    with pytest.raises(NotAuthenticated):
        bench.service.rotate(Device(device_id=device.device_id, device_kind="car"))
