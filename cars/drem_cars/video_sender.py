"""The video relay's work, in a process of its own (started by drem_cars.video_relay): demand, resize, JPEG, HTTP.

It long-polls the live server's demand; while wanted, every 1/fps it asks the car's process for the source's newest
frame (older ones are simply never sent: latest-frame-wins), makes it the chosen size and view, and POSTs it with the
car's device credential. One request in flight at most, each bounded by a short timeout: a slow network costs frames,
never memory or the control loop's time. The live server's answer to each frame says whether the car is still wanted,
and may carry the settings staff chose on the Cars page.

Its state (wanted, sent, skipped, last error, settings) goes back to the car's process after each change.
"""
from __future__ import annotations

import logging
import os
import threading
import time
from dataclasses import dataclass, replace
from multiprocessing import connection, parent_process
from typing import Any

import requests

from drem_cars.video_settings import VideoSettings, encode
from drem_cars.video_sources import SourceFrame

log = logging.getLogger("drem_cars.video")
VIDEO_NICENESS = 10  # the sender's CPU priority below the car's process (0 normal, 19 lowest)


def give_way_to_the_car() -> None:
    """The sender takes only CPU time the car's own work does not want: `nice`, then SCHED_IDLE where Linux offers it.
    With `nice` alone the sender still kept a share of the core and the drive loop, waking for its next tick, could
    wait for the scheduler's wake-up granularity behind a JPEG encode; a SCHED_IDLE task gives the CPU up at once to
    any task that wakes. A starved sender only sends fewer frames (latest-frame-wins), it never queues any."""
    os.nice(VIDEO_NICENESS)
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass  # not Linux: the nice value stands


@dataclass(frozen=True)
class SenderConfig:
    live_url: str
    credential: str
    settings: VideoSettings
    timeout_s: float
    demand_wait_s: float
    retry_s: float


class PipedSource:
    """The car process's frame source, seen from the sender: each `latest` asks for the newest frame then and there."""

    def __init__(self, pipe: connection.Connection) -> None:
        self._pipe = pipe

    def latest(self) -> SourceFrame | None:
        self._pipe.send(("frame",))
        frame: SourceFrame | None = self._pipe.recv()
        return frame

    def open(self, width: int, height: int) -> None:
        self._pipe.send(("open", width, height))

    def close(self) -> None:
        self._pipe.send(("close",))


class VideoSender:
    def __init__(self, config: SenderConfig, pipe: connection.Connection) -> None:
        self.live_url = config.live_url.rstrip("/")
        self.settings = config.settings
        self.timeout_s = config.timeout_s
        self.demand_wait_s = config.demand_wait_s
        self.retry_s = config.retry_s
        self.source = PipedSource(pipe)
        self._pipe = pipe
        self._http = requests.Session()
        self._http.trust_env = False  # a proxy from the environment must never see the device credential
        self._http.headers["Authorization"] = f"Device {config.credential}"
        self.wanted = False
        self.sent = 0
        self.skipped = 0  # frames the source had that were never sent (the relay took only the newest)
        self.last_error: str | None = None

    def run(self) -> None:
        while True:
            try:
                if self.wanted:
                    self._stream()
                else:
                    self._await_demand()
            except (requests.RequestException, ValueError) as exc:
                self.last_error = str(exc)
                self._report()
                log.warning("video: %s (trying again in %.0f s)", exc, self.retry_s)
                time.sleep(self.retry_s)

    def _report(self) -> None:
        self._pipe.send(("status", self.wanted, self.sent, self.skipped, self.last_error, self.settings))

    def _await_demand(self) -> None:
        reply = self._http.get(f"{self.live_url}/live/video/car/demand",
                               params={"wanted": "0", "wait_s": f"{self.demand_wait_s:g}"},
                               timeout=self.timeout_s + self.demand_wait_s)
        self.wanted = self._answer(reply)
        self._report()
        if not self.wanted and reply.status_code != 200:
            time.sleep(self.retry_s)

    def _stream(self) -> None:
        opened = self.settings.size
        self.source.open(*opened)
        last = 0
        try:
            while self.wanted:
                started = time.monotonic()
                if self.settings.size != opened:  # staff chose another size: the source delivers that from now on
                    self.source.close()
                    opened = self.settings.size
                    self.source.open(*opened)
                period = 1.0 / max(0.5, self.settings.fps)
                frame = self.source.latest()
                if frame is not None and frame.number != last:
                    self.skipped += max(0, frame.number - last - 1) if last else 0
                    last = frame.number
                    self.wanted = self._send(frame)
                    self._report()
                time.sleep(max(0.0, period - (time.monotonic() - started)))
        finally:
            if not self.wanted:
                self.source.close()

    def _send(self, frame: SourceFrame) -> bool:
        reply = self._http.post(f"{self.live_url}/live/video/car/frame", data=encode(frame, self.settings),
                                headers={"Content-Type": "image/jpeg", "X-Frame-Time": f"{frame.taken_ms:.1f}"},
                                timeout=self.timeout_s)
        self.sent += 1
        return self._answer(reply)

    def _answer(self, reply: requests.Response) -> bool:
        if reply.status_code != 200:
            self.last_error = f"the live server answered HTTP {reply.status_code}: {reply.text[:200]}"
            log.warning("video: %s", self.last_error)
            return False
        body: Any = reply.json()
        if isinstance(body, dict) and isinstance(body.get("video"), dict):
            self._apply(body["video"])
        return bool(isinstance(body, dict) and body.get("wanted"))

    def _apply(self, chosen: dict[str, Any]) -> None:
        """The settings staff chose on the Cars page, as the live server hands them on; anything malformed is ignored
        (the car keeps what it sends at)."""
        try:
            settings = replace(self.settings, fps=float(chosen["fps"]), width=int(chosen["width"]),
                               height=int(chosen["height"]), view=chosen["view"])
        except (KeyError, TypeError, ValueError):
            return
        if (settings.view not in ("camera", "model") or not 1 <= settings.fps <= 30
                or not (16 <= settings.width <= 1920 and 16 <= settings.height <= 1080)):
            return
        if settings != self.settings:
            log.info("video: staff chose %g fps, %dx%d, %s view", settings.fps, settings.width, settings.height,
                     settings.view)
            self.settings = settings


def run_sender(config: SenderConfig, pipe: connection.Connection) -> None:
    """The child process's whole life: send until the car's process stops it or goes away (even by kill -9)."""
    give_way_to_the_car()  # on a busy car the control loop, lap timing and uploads of laps come first; video waits
    parent = parent_process()
    if parent is not None:
        threading.Thread(target=_exit_with, args=(parent.sentinel,), name="drem-video-orphan-watch",
                         daemon=True).start()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    try:
        VideoSender(config, pipe).run()
    except (EOFError, OSError):
        pass  # the car's process closed its end: nothing left to relay for


def _exit_with(sentinel: int) -> None:
    connection.wait([sentinel])
    os._exit(0)  # a sender in a long poll would otherwise outlive its car
