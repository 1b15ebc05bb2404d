"""The car's eye across live servers, as on AWS with several live tasks behind the load balancer: the car's
connection reaches one server, a viewer's another, yet the viewer sees the car (the servers know each other as peers,
drem_live.video_peers). The first server here also runs two worker processes (`--live-workers 2`), so the hub and its
peers are tested together.

What a user notices: a viewer on the other server sees the racing car's camera, although only that viewer wants it
(the car, asking its own server, is told it is wanted); a request to the peer port without the shared secret is
refused."""
from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from typing import Any

import pytest
import requests

from drem_cars.drivers.deepracer_console import DeepRacerConsole
from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import ConsoleCamera
from drem_live.video_peers import PEER_LISTEN_ENV, PEER_SECRET_ENV, PEERS_ENV
from drem_local import stack as local_stack
from tests.browser.console_api import call
from tests.cars.fake_deepracer_console import FakeConsole
from tests.integration.test_car_video import NO_PROXY, car_racing_on_track_1, frames, watch

pytestmark = pytest.mark.integration
SECRET = "peer-secret-for-the-tests-only"


@pytest.fixture(scope="module")
def two_servers(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Any]:
    """A local stack whose live server (two workers) and a second live server are each other's peers."""
    from drem_local.bootstrap import generate_password

    config = local_stack.StackConfig(state_dir=tmp_path_factory.mktemp("video-peers") / "state",
                                     app_port=local_stack.free_port(), storage_port=local_stack.free_port(),
                                     live_port=local_stack.free_port(), live_workers=2)
    first_peer, second_peer, second_port = (local_stack.free_port() for _ in range(3))
    peer_env = {PEERS_ENV: f"127.0.0.1:{first_peer},127.0.0.1:{second_peer}", PEER_SECRET_ENV: SECRET,
                PEER_LISTEN_ENV: f"127.0.0.1:{first_peer}"}
    saved = {name: os.environ.get(name) for name in peer_env}
    os.environ.update(peer_env)  # the stack's children take the test process's environment
    password = generate_password()
    try:
        running = local_stack.start_stack(config, "admin", password, timeout=60.0)
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
    second_env = {**running.env, **peer_env, PEER_LISTEN_ENV: f"127.0.0.1:{second_peer}"}
    second = local_stack.spawn("second live server", [
        sys.executable, "-m", "drem_live", "--host", "127.0.0.1", "--port", str(second_port)],
        config.log_dir / "live-second.log", env=second_env)
    try:
        local_stack.wait_for_ok(f"http://127.0.0.1:{second_port}/live/healthz", second, 60.0)
        yield config, password, f"http://127.0.0.1:{second_port}", second_peer
    finally:
        second.stop(5)
        running.stop()


def test_a_viewer_on_another_server_gets_the_car_it_alone_wants(two_servers: Any) -> None:
    config, password, second_url, _ = two_servers
    url = config.app_url
    admin = call(url, "POST", "/api/auth/token", body={"username": "admin", "password": password})["access_token"]
    call(url, "POST", "/api/users", token=admin, expect=201,
         body={"username": "petra", "email": "petra@example.test", "country_code": "SE"})
    racing = car_racing_on_track_1(url, admin, "petra", "peer-car", "Two tasks")
    credential, eid = racing.credential, racing.event_id
    with FakeConsole() as console:
        # The car reaches the stack's live server only; the viewers reach only the second one.
        relay = VideoRelay(config.live_url, credential, ConsoleCamera(DeepRacerConsole(console.url, "car-password")),
                           VideoSettings(fps=15), demand_wait_s=5)
        relay.start()
        try:
            viewers = [watch(f"{second_url}/live/video/{eid}?track=1") for _ in range(3)]
            assert [v.status_code for v in viewers] == [200] * 3
            assert all(len(frames(v, 3)) == 3 for v in viewers)
            for viewer in viewers:
                viewer.close()
        finally:
            relay.stop()


def test_the_peer_port_refuses_requests_without_the_shared_secret(two_servers: Any) -> None:
    *_, second_peer = two_servers
    jpeg = b"\xff\xd8\xff\xe0" + b"x" * 10 + b"\xff\xd9"
    for secret in ({}, {"X-Drem-Peer-Secret": "guessed-wrong-secret"}):
        answer = requests.post(f"http://127.0.0.1:{second_peer}/peer/frame", data=jpeg, timeout=10, proxies=NO_PROXY,
                               headers={**secret, "X-Drem-Car": "peer-car", "X-Frame-Time": "1"})
        assert answer.status_code == 403
