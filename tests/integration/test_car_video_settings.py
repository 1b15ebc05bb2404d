"""Staff choose a car's camera settings (frame rate, size, the model's own view) and the running car takes them up by
itself: set over HTTP as the Cars page and the API do, delivered by the live server with its answers to the car's
relay, and seen by a viewer of the stream. Racers may not choose; settings out of bounds get a message naming the
field."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import cv2
import numpy as np
import pytest

from drem_cars.drivers.deepracer_console import DeepRacerConsole
from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import ConsoleCamera
from tests.browser.console_api import access_token, call, create_user
from tests.cars.fake_deepracer_console import FakeConsole
from tests.integration.test_car_video import car_racing_on_track_1, frames, watch
from tests.waiting import wait_until

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def car_racing(live_stack: Any) -> Iterator[dict[str, Any]]:
    url = live_stack.url
    admin = call(url, "POST", "/api/auth/token", body={"username": live_stack.admin_username,
                                                       "password": live_stack.admin_password})["access_token"]
    racer = create_user(live_stack, "sven-settings", "racer")
    racing = car_racing_on_track_1(url, admin, racer, "settings-car", "Camera settings")
    credential, eid = racing.credential, racing.event_id
    with FakeConsole() as console:
        camera = ConsoleCamera(DeepRacerConsole(console.url, "car-password"))
        relay = VideoRelay(live_stack.live_url, credential, camera, VideoSettings(fps=15), demand_wait_s=5)
        relay.start()
        try:
            yield {"event_id": eid, "admin": admin, "racer": access_token(live_stack, racer), "relay": relay,
                   "device_id": credential.split(".")[0], "fleet_id": racing.fleet_id}
        finally:
            relay.stop()


def test_staff_choose_the_models_view_and_the_racing_car_sends_it(live_stack: Any, car_racing: Any) -> None:
    device_id, relay = car_racing["device_id"], car_racing["relay"]
    chosen = call(live_stack.url, "PUT", f"/api/devices/{device_id}/video", token=car_racing["admin"],
                  body={"fps": 10, "width": 320, "height": 240, "view": "model"})
    assert chosen == {"fps": 10, "width": 320, "height": 240, "view": "model"}

    wait_until(lambda: relay.settings.view == "model" and relay.settings.fps == 10, 60,
               "the car's relay takes up the settings staff chose")
    with watch(f"{live_stack.live_url}/live/video/{car_racing['event_id']}?track=1") as response:
        def model_view_shown() -> bool:
            jpeg, _taken = frames(response, 1)[0]
            image = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_UNCHANGED)
            return image.shape == (120, 160)  # 160×120, one channel: grey
        wait_until(model_view_shown, 30, "the viewer sees the model's own 160×120 grey view")


def test_staff_choose_for_a_whole_fleet_and_its_racing_car_sends_at_it(live_stack: Any, car_racing: Any) -> None:
    relay = car_racing["relay"]
    answer = call(live_stack.url, "PUT", f"/api/fleets/{car_racing['fleet_id']}/video", token=car_racing["admin"],
                  body={"fps": 20, "width": 640, "height": 480, "view": "camera"})
    assert answer["cars"] == [car_racing["device_id"]]
    wait_until(lambda: (relay.settings.fps, relay.settings.size, relay.settings.view) == (20, (640, 480), "camera"),
               60, "the fleet's car takes up the fleet's settings")


def test_racers_may_not_choose_a_cars_camera_settings(live_stack: Any, car_racing: Any) -> None:
    call(live_stack.url, "PUT", f"/api/devices/{car_racing['device_id']}/video", token=car_racing["racer"],
         body={"fps": 30, "width": 640, "height": 480, "view": "camera"}, expect=403)
    call(live_stack.url, "PUT", f"/api/fleets/{car_racing['fleet_id']}/video", token=car_racing["racer"],
         body={"fps": 30, "width": 640, "height": 480, "view": "camera"}, expect=403)


@pytest.mark.parametrize("body, field", [({"fps": 100}, "fps"), ({"width": 99999}, "width"),
                                         ({"view": "thermal"}, "view")])
def test_settings_out_of_bounds_are_refused_naming_the_field(live_stack: Any, car_racing: Any, body: dict,
                                                             field: str) -> None:
    answer = call(live_stack.url, "PUT", f"/api/devices/{car_racing['device_id']}/video", token=car_racing["admin"],
                  body=body, expect=400)
    assert field in str(answer)
