"""The car for bench/car_video.py, in a process of its own: on a venue the car is a computer of its own, so its drive
loop must not share a GIL with the bench's browser driver and timer stand-in. It runs a sim car's drive loop (camera,
pilot, safety, actuator and the camera tap the relay reads) at 15 Hz for the whole run, and on the bench's word starts
the car's video relay (drem_cars.video_relay, its own child process, as `drem car run` starts it).

Commands on the pipe: ("mark",) → ticks so far; ("jitter", since) → the loop's lateness (ms) of each tick since then;
("relay", live_url, credential) → starts the relay; ("sent",) → (frames sent, frames skipped); ("stop",).
"""
from __future__ import annotations

import threading
from multiprocessing import connection
from typing import Any


def run_car(pipe: connection.Connection, car_id: str) -> None:
    from drem_cars.parts.safety import Safety
    from drem_cars.sim_car import build_sim_car
    from drem_cars.video_relay import VideoRelay, VideoSettings
    from drem_sim.tracks import default_track_name

    car = build_sim_car(default_track_name(), device_id=car_id,  # no agent: the bench runs the drive loop alone
                        safety=Safety(heartbeat_limit_s=1e9))
    loop = threading.Thread(target=car.vehicle.start, kwargs={"rate_hz": 15.0}, daemon=True)
    loop.start()
    relay: Any = None
    pipe.send("driving")
    while True:
        command = pipe.recv()
        if command[0] == "mark":
            pipe.send(len(car.vehicle.stats.jitter_ms))
        elif command[0] == "jitter":
            pipe.send(list(car.vehicle.stats.jitter_ms[command[1]:]))
        elif command[0] == "relay":
            relay = VideoRelay(command[1], command[2], car.camera_tap, VideoSettings(fps=15), demand_wait_s=5)
            relay.start()
            pipe.send(relay.process_id)
        elif command[0] == "sent":
            pipe.send((relay.sent, relay.skipped) if relay else (0, 0))
        elif command[0] == "stop":
            if relay is not None:
                relay.stop()
            car.vehicle.stop()
            loop.join(5)
            pipe.send("stopped")
            return
