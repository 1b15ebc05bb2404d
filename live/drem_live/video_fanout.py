"""The cars' camera frames written to their viewers by a process of their own, which takes only spare CPU time.

Writing 15 frames a second to 500 viewers is most of what the camera costs the live server (a copy into a socket per
viewer per frame). In the server's own process that work took the laptop's core from what a lap needs on its way to
the boards (the app's write, storage, the board push): bench/car_video.py measured lap-to-screen p95 1.5× slower with
500 viewers. Here the writing runs in a child process at SCHED_IDLE (`nice` where Linux has no SCHED_IDLE): whenever
the app, storage or the live server's own work wants the CPU it gets it at once, and the frames wait (latest frame wins,
so a viewer gets the newest frame when the burst is over, never a backlog).

The live server keeps everything else: who may watch, which car a viewer follows, the cars' demand. When a viewer's
stream starts, the server sends its response headers, then hands the worker a duplicate of the connection's socket
(SCM_RIGHTS) with the car it follows; the worker writes that car's frames to it (drem_live.video_feeds.Sink, the same
rules). The server still reads the connection (it notices the viewer leave) and tells the worker to let go of it.

Messages, server → worker on the control socket (SOCK_SEQPACKET, one message each, JSON, the socket as ancillary data):
`attach {viewer, device, chunked}` + fd, `follow {viewer, device}`, `detach {viewer, end}`; worker → server: `dropped
{viewer}` (the viewer fell too far behind: the server closes the connection). Frames travel on a second, stream socket
as `<length of header><header JSON><chunk><part>`: once per frame, whatever the number of viewers.
"""
from __future__ import annotations

import asyncio
import contextlib
import ctypes
import json
import logging
import os
import signal
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from typing import Any

from drem_live.video_feeds import FAN_OUT_SLICE, Frame, Sink

log = logging.getLogger("drem_live")
_HEADER = struct.Struct("!I")  # the length of a frame message's JSON header
_CONTROL_BYTES = 4096
_PR_SET_PDEATHSIG = 1
WORKER_ENV = "DREM_LIVE_VIDEO_WORKER"  # "0": the server writes the frames itself (tests of that path, no Linux)


def wanted() -> bool:
    return os.environ.get(WORKER_ENV, "1") != "0" and hasattr(socket, "send_fds")


class FanOutWorker:
    """The server's side: starts the worker and talks to it (all calls from the server's event loop)."""

    def __init__(self) -> None:
        self._control, control_child = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._frames, frames_child = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        self._frames.setblocking(False)
        self._process = subprocess.Popen(
            [sys.executable, "-m", "drem_live.video_fanout", str(control_child.fileno()), str(frames_child.fileno())],
            pass_fds=(control_child.fileno(), frames_child.fileno()), preexec_fn=_idle_child)
        control_child.close()
        frames_child.close()
        self._next_viewer = 0
        self._dropped: dict[int, Callable[[], None]] = {}
        self._pending = bytearray()  # frame bytes the socket did not take yet (the worker was starved meanwhile)

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._control.setblocking(False)
        loop.add_reader(self._control.fileno(), self._read_control)

    def attach(self, transport: asyncio.BaseTransport, chunked: bool, device_id: str,
               on_dropped: Callable[[], None]) -> int | None:
        """The worker writes `device_id`'s frames to this connection from now on; returns the viewer's number, or
        None when the worker cannot take it (gone, or its control queue full): the server then writes itself."""
        sock = transport.get_extra_info("socket")
        self._next_viewer += 1
        viewer = self._next_viewer
        message = json.dumps({"attach": viewer, "device": device_id, "chunked": chunked}).encode()
        try:
            socket.send_fds(self._control, [message], [sock.fileno()])  # the worker gets its own copy of the socket
        except OSError:
            return None
        self._dropped[viewer] = on_dropped
        return viewer

    def follow(self, viewer: int, device_id: str) -> None:
        self._send({"follow": viewer, "device": device_id})

    def detach(self, viewer: int, *, end: bool = False) -> None:
        """The worker lets go of the viewer's connection: at once (the viewer left), or with `end` after the frames it
        is still writing and the stream's end, so the viewer's player sees the stream finish, not break."""
        self._dropped.pop(viewer, None)
        self._send({"detach": viewer, "end": end})

    def frame(self, device_id: str, frame: Frame) -> None:
        if self._pending:
            return  # the worker has not taken the last frame yet: this one is skipped (latest frame wins)
        header = json.dumps({"device": device_id, "seq": frame.seq, "chunk": len(frame.chunk),
                             "part": len(frame.part)}).encode()
        message = _HEADER.pack(len(header)) + header + frame.chunk + frame.part
        try:
            sent = self._frames.send(message)
        except BlockingIOError:
            sent = 0
        except OSError:
            return  # the worker is gone: the viewers get no frames, the laps go on
        if sent < len(message):
            self._pending = bytearray(message[sent:])
            asyncio.get_running_loop().add_writer(self._frames.fileno(), self._flush)

    def stop(self) -> None:
        # At SCHED_IDLE the worker runs only when nothing else wants the CPU: beside three busy processes it took
        # 1.3-2.3 s to act on SIGTERM while this waited in the server's event loop. At normal priority: 7-32 ms.
        _normal_priority(self._process.pid)
        self._process.terminate()
        try:
            self._process.wait(5)
        except subprocess.TimeoutExpired:
            self._process.kill()
        self._control.close()
        self._frames.close()

    def _flush(self) -> None:
        try:
            sent = self._frames.send(self._pending)
        except BlockingIOError:
            return
        except OSError:
            sent = len(self._pending)
        del self._pending[:sent]
        if not self._pending:
            asyncio.get_running_loop().remove_writer(self._frames.fileno())

    def _send(self, message: dict[str, Any]) -> None:
        try:
            self._control.send(json.dumps(message).encode())
        except OSError:
            pass  # the worker is gone (or its control queue is full: it will drop the viewer by itself)

    def _read_control(self) -> None:
        while True:
            try:
                data = self._control.recv(_CONTROL_BYTES)
            except BlockingIOError:
                return
            if not data:
                asyncio.get_running_loop().remove_reader(self._control.fileno())
                return
            viewer = json.loads(data).get("dropped")
            on_dropped = self._dropped.pop(viewer, None)
            if on_dropped is not None:
                on_dropped()


def _idle_child() -> None:
    """In the worker before it runs: the lowest CPU priority, and it ends with the server."""
    try:
        os.nice(19)
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        pass  # not Linux: nice alone
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)
    except (OSError, AttributeError):
        pass


def _normal_priority(pid: int) -> None:
    """Undo `_idle_child` for a worker about to be stopped, so it is scheduled to act on the signal at once."""
    with contextlib.suppress(AttributeError, OSError):  # not Linux, already gone, or not allowed: it ends later
        os.sched_setscheduler(pid, os.SCHED_OTHER, os.sched_param(0))
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, pid, 0)


# --- the worker --------------------------------------------------------------------------------------------------

class _Reader(asyncio.Protocol):
    """The worker never reads a viewer's connection (the server does): it only learns when it is gone."""

    def __init__(self) -> None:
        self.sink: Sink | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        transport.pause_reading()  # type: ignore[attr-defined]

    def connection_lost(self, exc: Exception | None) -> None:
        if self.sink is not None:
            self.sink.closed.set()


class _Worker:
    def __init__(self, control: socket.socket, frames: socket.socket) -> None:
        self.control, self.frames = control, frames
        self.viewers: dict[int, tuple[Sink, str]] = {}  # viewer → (its connection, the device it follows)
        self.latest: dict[str, Frame] = {}

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        self.control.setblocking(False)
        loop.add_reader(self.control.fileno(), self._read_control)
        reader, _writer = await asyncio.open_unix_connection(sock=self.frames)
        while True:
            try:
                size = _HEADER.unpack(await reader.readexactly(_HEADER.size))[0]
                header = json.loads(await reader.readexactly(size))
                chunk = await reader.readexactly(header["chunk"])
                part = await reader.readexactly(header["part"])
            except asyncio.IncompleteReadError:
                return  # the server is gone
            frame = Frame(header["seq"], 0.0, time.time() * 1000, part, chunk)
            device = header["device"]
            self.latest[device] = frame
            self._report_dropped()  # once a frame, not once a slice
            self._fan_out(device, frame, [sink for sink, followed in self.viewers.values() if followed == device], 0)

    def _fan_out(self, device: str, frame: Frame, sinks: list[Sink], start: int) -> None:
        if frame is not self.latest.get(device):
            return  # a newer frame is on its way to every viewer
        now = time.monotonic()
        for sink in sinks[start:start + FAN_OUT_SLICE]:
            sink.offer(frame, now)
        rest = start + FAN_OUT_SLICE
        if rest < len(sinks):
            asyncio.get_running_loop().call_soon(self._fan_out, device, frame, sinks, rest)

    def _read_control(self) -> None:
        while True:
            try:
                data, fds, _flags, _addr = socket.recv_fds(self.control, _CONTROL_BYTES, 1)
            except BlockingIOError:
                return
            if not data:
                asyncio.get_running_loop().stop()  # the server is gone
                return
            message = json.loads(data)
            if "attach" in message and fds:
                asyncio.get_running_loop().create_task(self._attach(message, fds[0]))
            elif "follow" in message and message["follow"] in self.viewers:
                sink, _device = self.viewers[message["follow"]]
                sink.shown = 0
                self.viewers[message["follow"]] = (sink, message["device"])
                if (latest := self.latest.get(message["device"])) is not None:
                    sink.offer(latest, time.monotonic())
            elif "detach" in message:
                viewer = self.viewers.pop(message["detach"], None)
                if viewer is not None and message.get("end"):
                    sink = viewer[0]
                    if sink.chunked:
                        sink.transport.write(b"0\r\n\r\n")  # type: ignore[attr-defined]
                    sink.transport.close()  # after what is still buffered
                elif viewer is not None:
                    viewer[0].transport.abort()  # type: ignore[attr-defined]
            for fd in fds[1:] if "attach" in message else fds:
                os.close(fd)

    async def _attach(self, message: dict[str, Any], fd: int) -> None:
        sock = socket.socket(fileno=fd)
        protocol = _Reader()
        try:
            transport, _ = await asyncio.get_running_loop().connect_accepted_socket(lambda: protocol, sock)
        except OSError:
            sock.close()
            return
        sink = protocol.sink = Sink(transport, chunked=bool(message["chunked"]))
        self.viewers[message["attach"]] = (sink, message["device"])
        if (latest := self.latest.get(message["device"])) is not None:
            sink.offer(latest, time.monotonic())

    def _report_dropped(self) -> None:
        for viewer, (sink, _device) in list(self.viewers.items()):
            if sink.closed.is_set():
                del self.viewers[viewer]
                sink.transport.abort()  # type: ignore[attr-defined]
                try:
                    self.control.send(json.dumps({"dropped": viewer}).encode())
                except OSError:
                    pass


def main(argv: list[str]) -> int:
    control = socket.socket(fileno=int(argv[0]))
    frames = socket.socket(fileno=int(argv[1]))
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(asctime)s drem_live video %(message)s")
    try:
        asyncio.run(_Worker(control, frames).run())
    except (KeyboardInterrupt, RuntimeError):
        pass  # stopped with the server (RuntimeError: the loop was stopped when the server went)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
