"""The car's camera to the live server, only while someone may watch it (the car is racing, or staff preview it).

One thread, apart from the drive loop and the agent's threads: it long-polls the live server's demand; while wanted,
every 1/fps it takes the source's newest frame (older ones are simply never sent: latest-frame-wins), makes it the
chosen size and view, and POSTs it with the car's device credential. One request in flight at most, each bounded by a
short timeout: a slow network costs frames, never memory or the control loop's time. The live server's answer to each
frame says whether the car is still wanted.

Staff choose the rate, size and view when they start the car (`drem car run --video-fps/--video-size/--video-view`):
`camera` (colour, 480×360 by default) or `model`, the model's own input (160×120 grey); and later on the Cars page,
whose choice the live server hands on with its answers: the relay sends at it from then on (a new size reopens the
source).
"""
from __future__ import annotations

import logging
import sys
import threading
import time
from dataclasses import dataclass, replace
from typing import Any, Literal

import requests

from drem_cars.video_sources import FrameSource, SourceFrame

log = logging.getLogger("drem_cars.video")

MODEL_VIEW_SIZE = (160, 120)
SWITCH_INTERVAL_S = 0.0005  # how long the control loop may wait for the GIL while the relay runs Python
View = Literal["camera", "model"]


@dataclass(frozen=True)
class VideoSettings:
    fps: float = 15.0
    width: int = 480
    height: int = 360
    view: View = "camera"
    jpeg_quality: int = 75

    @property
    def size(self) -> tuple[int, int]:
        return MODEL_VIEW_SIZE if self.view == "model" else (self.width, self.height)


def parse_size(text: str) -> tuple[int, int]:
    """`480x360` → (480, 360); a clear message for anything else."""
    width, _, height = text.lower().partition("x")
    if not (width.isdigit() and height.isdigit()) or not (16 <= int(width) <= 1920 and 16 <= int(height) <= 1080):
        raise ValueError(f"--video-size {text!r}: give WIDTHxHEIGHT, e.g. 480x360 (16..1920 by 16..1080)")
    return int(width), int(height)


def encode(frame: SourceFrame, settings: VideoSettings) -> bytes:
    """The frame as a JPEG of the chosen size and view; a JPEG from the car already at that size passes as is."""
    import cv2
    import numpy as np

    image = frame.image
    if isinstance(image, bytes):
        if settings.view == "camera":
            return image  # the console already streams the size asked for
        image = cv2.imdecode(np.frombuffer(image, np.uint8), cv2.IMREAD_COLOR)
    if settings.view == "model" and image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    width, height = settings.size
    if image.shape[1] != width or image.shape[0] != height:
        shrink = image.shape[1] > width
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, settings.jpeg_quality])
    if not ok:
        raise ValueError("the frame could not be encoded as JPEG")
    return bytes(jpeg.tobytes())


class VideoRelay:
    def __init__(self, live_url: str, credential: str, source: FrameSource,
                 settings: VideoSettings = VideoSettings(), *, timeout_s: float = 2.0, demand_wait_s: float = 20.0,
                 retry_s: float = 2.0) -> None:
        self.live_url = live_url.rstrip("/")
        self.source = source
        self.settings = settings
        self.timeout_s = timeout_s
        self.demand_wait_s = demand_wait_s
        self.retry_s = retry_s
        self._http = requests.Session()
        self._http.trust_env = False  # a proxy from the environment must never see the device credential
        self._http.headers["Authorization"] = f"Device {credential}"
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.wanted = False
        self.sent = 0
        self.skipped = 0  # frames the source had that were never sent (the relay took only the newest)
        self.last_error: str | None = None

    def start(self) -> None:
        # The relay shares its process with the car's control loop. Its HTTP client is pure Python and holds the GIL
        # for a millisecond or more per frame; at CPython's default switch interval (5 ms) the loop's tick could wait
        # that long for it. The loop takes the GIL back within SWITCH_INTERVAL_S instead.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        self._thread = threading.Thread(target=self._run, name="drem-video-relay", daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 3.0) -> None:
        self._stop.set()
        self.source.close()
        if self._thread is not None:
            self._thread.join(timeout_s)  # a long poll may hold it: a daemon thread, not waited for longer

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                if self.wanted:
                    self._stream()
                else:
                    self._await_demand()
            except (requests.RequestException, ValueError) as exc:
                self.last_error = str(exc)
                log.warning("video: %s (trying again in %.0f s)", exc, self.retry_s)
                self._stop.wait(self.retry_s)

    def _await_demand(self) -> None:
        reply = self._http.get(f"{self.live_url}/live/video/car/demand",
                               params={"wanted": "0", "wait_s": f"{self.demand_wait_s:g}"},
                               timeout=self.timeout_s + self.demand_wait_s)
        self.wanted = self._answer(reply)
        if not self.wanted and reply.status_code != 200:
            self._stop.wait(self.retry_s)

    def _stream(self) -> None:
        opened = self.settings.size
        self.source.open(*opened)
        last = 0
        try:
            while self.wanted and not self._stop.is_set():
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
                self._stop.wait(max(0.0, period - (time.monotonic() - started)))
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
