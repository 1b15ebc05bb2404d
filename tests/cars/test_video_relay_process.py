"""The video relay seen from the car: its frames reach the live server from a process of its own, a live server that
stalls on a frame never holds up the drive loop, and the frame sent after the stall is the newest the loop made.

The live server here is a stand-in for drem's own (live/drem_live/video_routes.py: the demand long poll answers
{"wanted": true}, each frame POST answers whether the car is still wanted); it holds its first frame's answer until
the test lets it go."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import cv2
import numpy as np
import pytest

from drem_cars.video_relay import VideoRelay, VideoSettings
from drem_cars.video_sources import FrameTap
from tests.waiting import wait_until


class StallingLiveServer(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self) -> None:
        super().__init__(("127.0.0.1", 0), _Handler)
        self.release = threading.Event()
        self.frames: list[tuple[float, bytes]] = []  # (X-Frame-Time, JPEG) as received

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.server_address[1]}"


class _Handler(BaseHTTPRequestHandler):
    server: StallingLiveServer

    def log_message(self, *_: object) -> None: ...

    def do_GET(self) -> None:  # noqa: N802 - the stdlib's name
        self._answer({"wanted": True})

    def do_POST(self) -> None:  # noqa: N802
        body = self.rfile.read(int(self.headers["Content-Length"]))
        self.server.frames.append((float(self.headers["X-Frame-Time"]), body))
        if len(self.server.frames) == 1:
            self.server.release.wait(60)  # the network stalls on the first frame
        self._answer({"wanted": True})

    def _answer(self, body: dict[str, object]) -> None:
        data = json.dumps(body).encode()
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data)


@pytest.fixture
def live_server() -> Iterator[StallingLiveServer]:
    server = StallingLiveServer()
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield server
    server.release.set()
    server.shutdown()


def test_a_stalled_upload_never_holds_the_loop_and_the_newest_frame_goes_next(live_server: StallingLiveServer) -> None:
    tap = FrameTap()
    tap.run(np.zeros((120, 160), np.uint8))
    relay = VideoRelay(live_server.url, "car-1.secret", tap, VideoSettings(fps=30), demand_wait_s=5)
    relay.start()
    try:
        wait_until(lambda: live_server.frames, 60, "the first frame to reach the live server")
        assert relay.process_id not in (None, os.getpid())  # the upload is another process's work, and it gives way
        assert os.getpriority(os.PRIO_PROCESS, relay.process_id) > os.getpriority(os.PRIO_PROCESS, 0)  # to the loop
        assert os.sched_getscheduler(relay.process_id) == os.SCHED_IDLE  # only on CPU time the car does not want

        def drive_loop() -> None:  # the loop's ticks while the upload stalls: each hands its frame to the tap
            for value in range(1, 201):
                tap.run(np.full((120, 160), value, np.uint8))

        loop = threading.Thread(target=drive_loop)
        loop.start()
        loop.join(30)
        assert not loop.is_alive(), "the drive loop waited on the stalled upload"
        newest = tap.latest()
        assert newest is not None and len(live_server.frames) == 1  # still stalled: nothing queued behind it

        live_server.release.set()
        wait_until(lambda: len(live_server.frames) >= 2, 60, "the frame after the stall")
        taken_ms, jpeg = live_server.frames[1]
        assert taken_ms == pytest.approx(newest.taken_ms, abs=0.1)  # the newest, not the next in line
        picture = cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_GRAYSCALE)
        assert picture.shape == (360, 480) and int(picture.mean()) == pytest.approx(200, abs=2)
        wait_until(lambda: relay.sent >= 2 and relay.skipped >= 199, 30, "the relay to count the frames it skipped")
        assert relay.wanted
    finally:
        relay.stop()
    assert not relay.wanted


def test_stopping_a_relay_stuck_on_a_stalled_upload_ends_its_process(live_server: StallingLiveServer) -> None:
    tap = FrameTap()
    tap.run(np.zeros((120, 160), np.uint8))
    relay = VideoRelay(live_server.url, "car-1.secret", tap, VideoSettings(fps=15), demand_wait_s=5)
    relay.start()
    wait_until(lambda: live_server.frames, 60, "the first frame to reach the live server")
    pid = relay.process_id
    relay.stop()
    assert pid is not None and not os.path.exists(f"/proc/{pid}")  # ended and reaped: no orphan uploading on
    assert not relay.wanted


CAR_WITH_A_RELAY = """
import sys, time, numpy as np
from drem_cars.video_relay import VideoRelay
from drem_cars.video_sources import FrameTap
if __name__ == "__main__":
    tap = FrameTap()
    tap.run(np.zeros((120, 160), np.uint8))
    relay = VideoRelay(sys.argv[1], "car-1.secret", tap, demand_wait_s=5)
    relay.start()
    print(relay.process_id, flush=True)
    time.sleep(120)
"""


def test_a_car_killed_with_kill_9_leaves_no_relay_uploading(live_server: StallingLiveServer, tmp_path: Path) -> None:
    script = tmp_path / "car.py"
    script.write_text(CAR_WITH_A_RELAY)
    car = subprocess.Popen([sys.executable, str(script), live_server.url], stdout=subprocess.PIPE, text=True)
    try:
        assert car.stdout is not None
        relay_pid = int(car.stdout.readline())
        wait_until(lambda: live_server.frames, 60, "the relay's first frame (it is stalled there)")
        car.kill()
        car.wait(30)
        wait_until(lambda: not os.path.exists(f"/proc/{relay_pid}") or _state(relay_pid) == "Z", 30,
                   "the relay's process to end with its car")
    finally:
        car.kill()


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rpartition(")")[2].split()[0]
    except FileNotFoundError:
        return "gone"
