"""The car's eye with the live server in several processes, as `drem up` runs it on a multi-core machine
(`--live-workers`, one per core): the kernel spreads connections over the processes, yet the car uploads once and every
viewer, whichever process it reached, sees its frames (the first process holds the feeds; the others pass the camera
routes to it)."""
from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest

from drem_cars.drivers.deepracer_console import DeepRacerConsole
from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import ConsoleCamera
from drem_local import stack as local_stack
from tests.browser.console_api import call
from tests.cars.fake_deepracer_console import FakeConsole
from tests.integration.test_car_video import car_racing_on_track_1, frames, watch

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def two_workers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    from drem_local.bootstrap import generate_password

    config = local_stack.StackConfig(state_dir=tmp_path_factory.mktemp("video-workers") / "state",
                                     app_port=local_stack.free_port(), storage_port=local_stack.free_port(),
                                     live_port=local_stack.free_port(), live_workers=2)
    password = generate_password()
    running = local_stack.start_stack(config, "admin", password, timeout=60.0)
    try:
        yield config, password
    finally:
        running.stop()


def test_every_viewer_sees_the_one_upload_whichever_worker_it_reached(two_workers: Any) -> None:
    config, password = two_workers
    url = config.app_url
    admin = call(url, "POST", "/api/auth/token", body={"username": "admin", "password": password})["access_token"]
    call(url, "POST", "/api/users", token=admin, expect=201,
         body={"username": "wanda", "email": "wanda@example.test", "country_code": "SE"})
    racing = car_racing_on_track_1(url, admin, "wanda", "worker-car", "Two workers")
    credential, eid = racing.credential, racing.event_id
    with FakeConsole() as console:
        relay = VideoRelay(config.live_url, credential, ConsoleCamera(DeepRacerConsole(console.url, "car-password")),
                           VideoSettings(fps=15), demand_wait_s=5)
        relay.start()
        try:
            viewers = [watch(f"{config.live_url}/live/video/{eid}?track=1") for _ in range(6)]
            assert [v.status_code for v in viewers] == [200] * 6
            assert all(len(frames(v, 3)) == 3 for v in viewers)
            for viewer in viewers:
                viewer.close()
        finally:
            relay.stop()
        routes = [value for _m, path, value in console.state.calls if path == "/route"]
    assert len(routes) == 1  # one camera stream from the car, however many viewers and workers
