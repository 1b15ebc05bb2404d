"""The car's eye end to end: a stock DeepRacer (the tests' fake console, serving its camera as the car's
web_video_server does) relayed by the car's video relay to the live server of a running stack, and out to viewers
as MJPEG.

What a user notices: the overlay's viewers see the racing car's camera, frames keep coming; the car sends nothing while
nobody may watch; a car that is not racing is never shown publicly, and a preview is staff-only."""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
import pytest
import requests

from drem_cars.drivers.deepracer_console import DeepRacerConsole
from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import ConsoleCamera, mjpeg_frames
from tests.browser.console_api import access_token, call, create_user
from tests.cars.fake_deepracer_console import FakeConsole
from tests.waiting import wait_until

pytestmark = pytest.mark.integration
NO_PROXY = {"http": "", "https": ""}


def activate_car(url: str, token: str, fleet_id: str, hostname: str, kind: str = "car") -> str:
    code = call(url, "POST", "/api/devices/activation-codes", token=token, expect=201,
                body={"fleet_id": fleet_id, "hostname": hostname, "device_kind": kind})["code"]
    return str(call(url, "POST", "/api/devices/activate", expect=201,
                    body={"code": code, "hostname": hostname, "device_kind": kind})["credential"])


@dataclass(frozen=True)
class CarRacing:
    event_id: str
    fleet_id: str
    credential: str  # the racing car's device credential


def car_racing_on_track_1(url: str, admin: str, racer: str, car: str, event_name: str) -> CarRacing:
    """An event whose track 1 has a started race of `racer` on `car`, a car activated in the event's fleet."""
    fleet = call(url, "POST", "/api/fleets", token=admin, body={"name": f"{event_name} cars"}, expect=201)
    event = call(url, "POST", "/api/events", token=admin, expect=201, body={
        "name": event_name, "event_type": "AWS_SUMMIT", "date": "2026-05-14", "country_code": "SE",
        "race_config": {"race_time_min": 3}, "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]})
    credential = activate_car(url, admin, fleet["fleet_id"], car)
    eid = event["event_id"]
    race = call(url, "POST", f"/api/events/{eid}/races", token=admin, expect=201,
                body={"track_id": "1", "racer_username": racer, "car": car})
    call(url, "POST", f"/api/events/{eid}/races/{race['race_id']}/commands", token=admin, body={"kind": "start"})
    return CarRacing(eid, fleet["fleet_id"], credential)


@pytest.fixture(scope="module")
def racing(live_stack: Any) -> Iterator[dict[str, Any]]:
    """An event whose track 1 races `video-car-1` (a stock car behind a fake console, its relay running), and a second
    activated car that races nothing."""
    url = live_stack.url
    admin = call(url, "POST", "/api/auth/token", body={"username": live_stack.admin_username,
                                                       "password": live_stack.admin_password})["access_token"]
    racer = create_user(live_stack, "vera-video", "racer")
    racing = car_racing_on_track_1(url, admin, racer, "video-car-1", "Car's eye")
    car, eid = racing.credential, racing.event_id
    idle_car = activate_car(url, admin, racing.fleet_id, "video-car-2")
    with FakeConsole() as console:
        camera = ConsoleCamera(DeepRacerConsole(console.url, "car-password"))
        relay = VideoRelay(live_stack.live_url, car, camera, VideoSettings(fps=15), demand_wait_s=5)
        relay.start()
        try:
            yield {"event_id": eid, "admin": admin, "racer": access_token(live_stack, racer), "car": car,
                   "idle_car": idle_car, "console": console, "relay": relay}
        finally:
            relay.stop()


def frames(response: requests.Response, count: int) -> list[tuple[bytes, float]]:
    got: list[tuple[bytes, float]] = []
    for frame in mjpeg_frames(response.iter_content(None), response.headers):
        got.append(frame)
        if len(got) >= count:
            break
    return got


def watch(url: str, **kwargs: Any) -> requests.Response:
    # The read deadline is a loaded machine's: before the first frame the car's relay process starts, hears it is
    # wanted (from another live server: a peer's report, sent again every 5 s) and logs in to the console; with two
    # CPU-bound processes beside the suite that took over 15 s once.
    return requests.get(url, stream=True, timeout=(10, 60), proxies=NO_PROXY, **kwargs)


def test_the_overlay_viewer_sees_the_racing_cars_camera_frame_after_frame(live_stack: Any, racing: Any) -> None:
    with watch(f"{live_stack.live_url}/live/video/{racing['event_id']}?track=1") as response:
        assert response.status_code == 200
        assert response.headers["Content-Type"].startswith("multipart/x-mixed-replace")
        got = frames(response, 5)
    images = [cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR) for jpeg, _ in got]
    assert all(image.shape == (360, 480, 3) for image in images)  # the console streamed the size asked for
    assert len({image.tobytes() for image in images}) > 1  # a moving picture, not one still
    assert any("width=480&height=360" in str(value) for _m, path, value in racing["console"].state.calls
               if path == "/route")


def test_the_car_sends_nothing_while_nobody_may_watch(live_stack: Any, racing: Any) -> None:
    relay = racing["relay"]
    wait_until(lambda: not relay.wanted, 20, "the relay to stop sending after the viewer left")
    sent = relay.sent
    demand = requests.get(f"{live_stack.live_url}/live/video/car/demand?wanted=1", proxies=NO_PROXY, timeout=10,
                          headers={"Authorization": f"Device {racing['car']}"}).json()
    assert demand == {"wanted": False}
    assert relay.sent - sent <= 1  # at most the frame in flight when the last viewer left


def test_a_car_that_is_not_racing_is_never_public(live_stack: Any, racing: Any) -> None:
    idle = racing["idle_car"].split(".")[0]
    anonymous = watch(f"{live_stack.live_url}/live/video/cars/{idle}")
    assert anonymous.status_code == 403
    no_race = watch(f"{live_stack.live_url}/live/video/{racing['event_id']}?track=2")
    assert no_race.status_code == 204  # no race on that track: nothing to show, and no error
    forged = requests.post(f"{live_stack.live_url}/live/video/car/frame", data=b"\xff\xd8\xff\xd9",
                           headers={"Authorization": "Device car-nobody.secret", "X-Frame-Time": "1"},
                           proxies=NO_PROXY, timeout=10)
    assert forged.status_code == 401


def test_a_preview_is_for_staff_only(live_stack: Any, racing: Any) -> None:
    idle = racing["idle_car"].split(".")[0]
    as_racer = watch(f"{live_stack.live_url}/live/video/cars/{idle}", cookies={"drem_session": racing["racer"]})
    assert as_racer.status_code == 403
    car = racing["car"].split(".")[0]
    with watch(f"{live_stack.live_url}/live/video/cars/{car}", cookies={"drem_session": racing["admin"]}) as staff:
        assert staff.status_code == 200
        assert len(frames(staff, 2)) == 2
        assert "Access-Control-Allow-Origin" not in staff.headers  # no other site may read a preview
