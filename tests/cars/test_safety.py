from __future__ import annotations

import pytest

from drem_cars.parts.safety import Safety

pytestmark = pytest.mark.unit


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_fresh_frame_drives_with_the_staff_cap_applied() -> None:
    clock = FakeClock()
    safety = Safety(clock=clock, throttle_cap_pct=50)
    assert safety.run(0.4, 0.8, clock.now - 0.1) == (0.4, pytest.approx(0.4), False, None)


def test_a_frame_older_than_half_a_second_stops_the_car() -> None:
    clock = FakeClock()
    steering, throttle, stopped, reason = Safety(clock=clock).run(0.5, 1.0, clock.now - 0.6)
    assert (steering, throttle, stopped) == (0.0, 0.0, True)
    assert "camera frame is 0.60 s old" in reason
    assert Safety(clock=clock).run(0.5, 1.0, None)[2], "no frame at all: stopped"


def test_lost_contact_with_the_server_beyond_the_limit_stops_the_car_until_a_heartbeat_gets_through() -> None:
    clock = FakeClock()
    safety = Safety(clock=clock, heartbeat_limit_s=10)
    clock.now += 9
    assert not safety.run(0.0, 1.0, clock.now)[2], "within the limit the race goes on"
    clock.now += 2
    _, throttle, stopped, reason = safety.run(0.0, 1.0, clock.now)
    assert stopped and throttle == 0.0 and "no contact with the server for 11 s" in reason
    safety.heartbeat_ok()
    assert safety.run(0.0, 1.0, clock.now)[:3] == (0.0, 1.0, False)


def test_emergency_stop_latches_until_cleared() -> None:
    clock = FakeClock()
    safety = Safety(clock=clock)
    safety.emergency_stop()
    safety.heartbeat_ok()
    assert safety.run(0.0, 1.0, clock.now)[2:] == (True, "emergency stop")
    safety.clear_emergency_stop()
    assert safety.run(0.0, 1.0, clock.now)[2] is False


def test_throttle_cap_is_a_percentage_and_zero_means_no_throttle() -> None:
    clock = FakeClock()
    safety = Safety(clock=clock)
    safety.set_throttle_cap(0)
    assert safety.run(1.0, 1.0, clock.now)[1] == 0.0
    with pytest.raises(ValueError, match="0 to 100"):
        safety.set_throttle_cap(101)
