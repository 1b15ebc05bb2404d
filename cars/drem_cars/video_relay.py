"""The car's camera to the live server, only while someone may watch it (the car is racing, or staff preview it).

The relay's work (demand long poll, resize, JPEG encoding, HTTP: drem_cars.video_sender) runs in a child process of
its own, so none of it ever holds the car's control loop's GIL or CPU. In the car's process one small thread answers the
child: when it asks for a frame, it sends the source's newest one (latest-frame-wins: there is never more than one
frame in the pipe, and older frames are never sent); when it is wanted or staff chose a new size, it opens or closes
the source. The drive loop itself only swaps a reference in its camera tap (drem_cars.video_sources.FrameTap).

Staff choose the rate, size and view when they start the car (`drem car run --video-fps/--video-size/--video-view`):
`camera` (colour, 480×360 by default) or `model`, the model's own input (160×120 grey); and later on the Cars page,
whose choice the live server hands on with its answers: the relay sends at it from then on (a new size reopens the
source).
"""
from __future__ import annotations

import multiprocessing
import sys
import threading
from multiprocessing import connection
from multiprocessing.process import BaseProcess

from drem_cars.video_sender import SenderConfig, run_sender
from drem_cars.video_settings import MODEL_VIEW_SIZE, VideoSettings, View, encode, parse_size
from drem_cars.video_sources import FrameSource

__all__ = ["MODEL_VIEW_SIZE", "VideoRelay", "VideoSettings", "View", "encode", "parse_size"]

DEFAULT_SETTINGS = VideoSettings()  # 15 fps, 480×360, the camera's view
SWITCH_INTERVAL_S = 0.0005  # how long the control loop may wait for the GIL while the frame thread runs Python


class VideoRelay:
    def __init__(self, live_url: str, credential: str, source: FrameSource,
                 settings: VideoSettings = DEFAULT_SETTINGS, *, timeout_s: float = 2.0, demand_wait_s: float = 20.0,
                 retry_s: float = 2.0) -> None:
        self.source = source
        self.settings = settings
        self._config = SenderConfig(live_url, credential, settings, timeout_s, demand_wait_s, retry_s)
        self._pipe: connection.Connection | None = None
        self._process: BaseProcess | None = None
        self._thread: threading.Thread | None = None
        # What the sender last reported (it runs in the child process; these are its figures, as of its last change).
        self.wanted = False
        self.sent = 0
        self.skipped = 0  # frames the source had that were never sent (the relay took only the newest)
        self.last_error: str | None = None

    def start(self) -> None:
        # The thread that hands frames to the child runs Python in the car's process (pickling a frame, the pipe);
        # at CPython's default switch interval (5 ms) the loop's tick could wait that long for the GIL after it.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        spawn = multiprocessing.get_context("spawn")  # not fork: the car's threads and sockets stay in the car
        self._pipe, child_end = spawn.Pipe()
        self._process = spawn.Process(target=run_sender, args=(self._config, child_end), name="drem-video-relay",
                                      daemon=True)
        self._process.start()
        child_end.close()
        self._thread = threading.Thread(target=self._answer_sender, args=(self._pipe,), name="drem-video-frames",
                                        daemon=True)
        self._thread.start()

    def stop(self, timeout_s: float = 3.0) -> None:
        """Stop sending at once: the child may be mid-request or in a long poll, and nothing it holds needs keeping."""
        if self._process is not None:
            self._process.terminate()
            self._process.join(timeout_s)
        if self._pipe is not None:
            self._pipe.close()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self.source.close()
        self.wanted = False

    @property
    def process_id(self) -> int | None:
        return self._process.pid if self._process is not None else None

    def _answer_sender(self, pipe: connection.Connection) -> None:
        while True:
            try:
                message = pipe.recv()
                kind = message[0]
                if kind == "frame":
                    pipe.send(self.source.latest())  # the newest frame as of now, whatever the loop made before
                elif kind == "open":
                    self.source.open(message[1], message[2])
                elif kind == "close":
                    self.source.close()
                elif kind == "status":
                    _, self.wanted, self.sent, self.skipped, self.last_error, self.settings = message
            except (EOFError, OSError):
                self.wanted = False
                return  # the sender is gone (stopped, or it died: the car races on without video)
