"""`drem car run`: wire the agent to a driver and run until stopped, revoked or asked to restart."""
from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from drem_cars.agent import CarAgent
from drem_cars.car_tls import CarTrust, CertificateProblem
from drem_cars.client import DeviceClient
from drem_cars.credentials import NotActivated
from drem_cars.drivers.deepracer_console import ConsoleError, ConsoleUnreachable, DeepRacerConsole
from drem_cars.model_store import ModelStore
from drem_cars.outbox import Outbox
from drem_cars.startup import start_device
from drem_cars.video_relay import VideoRelay, VideoSettings, parse_size
from drem_cars.video_sources import ConsoleCamera, FrameSource

EXIT_REVOKED = 3


def run_until_stopped(agent: CarAgent, deadline: float | None) -> None:
    """Run the agent's background work until it stops itself (revoked, restart), the deadline, or Ctrl-C."""
    try:
        agent.start()  # inside: its first thread may already be at work (and Ctrl-C pressed) while it starts the next
        while not agent.wait(0.5):
            if deadline is not None and time.monotonic() >= deadline:
                break
    except KeyboardInterrupt:
        pass
    agent.stop()


@contextmanager
def video_relay(args: argparse.Namespace, client: DeviceClient, source: FrameSource) -> Iterator[VideoRelay | None]:
    """The camera relay next to the drive loop, for as long as it runs (`--no-video`: none)."""
    if getattr(args, "no_video", True):
        yield None
        return
    width, height = parse_size(args.video_size)
    relay = VideoRelay(args.live_url or client.api, client.credential.credential, source,
                       VideoSettings(args.video_fps, width, height, args.video_view))
    relay.start()
    try:
        yield relay
    finally:
        relay.stop()


def run_agent(args: argparse.Namespace) -> int:
    try:
        device = start_device(args.config_dir)
    except NotActivated as exc:
        print(exc, file=sys.stderr)
        return 1
    client, outbox, models = device.client, device.outbox, device.models
    assert models is not None  # a car runs models
    deadline = time.monotonic() + args.seconds if args.seconds else None
    try:
        parse_size(getattr(args, "video_size", "480x360"))
        if not 1 <= getattr(args, "video_fps", 15.0) <= 30:
            raise ValueError(f"--video-fps {args.video_fps:g}: give 1 to 30 frames a second")
    except ValueError as exc:
        print(f"drem car run: {exc}", file=sys.stderr)
        return 2
    driving = (f"the DeepRacer at {args.deepracer}" if args.deepracer else "camera + PWM" if args.pwm
               else "the simulator" if args.sim else None)
    if driving:  # the operator at the car sees at once that it started, and where it reports to
        credential = client.credential
        print(f"drem car run: {credential.hostname} ({credential.device_kind} {credential.device_id}) driving "
              f"{driving}, reporting to {client.api}; {outbox.count()} crossing(s) waiting to be sent. "
              "Ctrl-C stops.", flush=True)
    if args.deepracer:
        return _run_deepracer(args, client, outbox, models, deadline, device.config_dir)
    if args.pwm:
        return _run_pwm(args, client, outbox, models, deadline)
    if not args.sim:
        print("drem car run: say what to drive: --sim, --pwm (camera + PWM) or --deepracer URL "
              "(see docs/cars.md)", file=sys.stderr)
        return 2
    from drem_sim.tracks import TrackError, default_track_name

    try:
        car = _sim_car(args, client, outbox, args.track or default_track_name())
    except TrackError as exc:
        print(f"drem car run --sim: {exc}", file=sys.stderr)
        return 2
    agent = CarAgent(client, car.driver, outbox, models)
    agent.times_laps = car.strips is not None
    with video_relay(args, client, car.camera_tap):
        stats = _drive(agent, car.vehicle, args.rate_hz, deadline)
    print(f"drive loop: {stats.summary()}; sim laps crossed: {car.strips.queued if car.strips else 0}; "
          f"outbox pending {outbox.count()}")
    return _finish(agent)


def _sim_car(args: argparse.Namespace, client: DeviceClient, outbox: Outbox, track: str):
    from drem_cars.parts.safety import Safety
    from drem_cars.sim_car import build_sim_car

    return build_sim_car(track, safety=Safety(heartbeat_limit_s=args.heartbeat_limit), outbox=outbox,
                         event_id=args.event, track_id=args.race_track, device_id=client.device_id)


def _run_pwm(args: argparse.Namespace, client: DeviceClient, outbox: Outbox, models: ModelStore,
             deadline: float | None) -> int:
    from drem_cars.parts.camera_cv import camera_source
    from drem_cars.parts.pwm import DEEPRACER_CALIBRATION
    from drem_cars.parts.safety import Safety
    from drem_cars.pwm_car import HardwareUnavailable, PwmWiring, build_pwm_car

    calibration = (Path(args.calibration) if args.calibration
                   else DEEPRACER_CALIBRATION if DEEPRACER_CALIBRATION.is_file() else None)
    gpio = str(args.servo_enable_gpio).strip().lower()
    if gpio != "none" and not gpio.isdigit():
        print(f"--servo-enable-gpio takes a GPIO number or 'none', not {args.servo_enable_gpio!r}", file=sys.stderr)
        return 2
    enable_gpio = None if gpio == "none" else int(gpio)
    wiring = PwmWiring(Path(args.pwm_root), args.pwm_chip, args.servo_channel, args.motor_channel, calibration,
                       enable_gpio, Path(args.gpio_root))
    try:
        car = build_pwm_car(camera_source(args.camera), wiring, safety=Safety(heartbeat_limit_s=args.heartbeat_limit))
    except HardwareUnavailable as exc:
        print(f"drem car run --pwm: {exc}", file=sys.stderr)
        return 1
    agent = CarAgent(client, car.driver, outbox, models)
    with video_relay(args, client, car.camera_tap):
        stats = _drive(agent, car.vehicle, args.rate_hz, deadline)  # the loop's shutdown: motor neutral, PWM off
    print(f"drive loop: {stats.summary()}; camera frames read: {car.camera.frames_read}; "
          f"outbox pending {outbox.count()}")
    return _finish(agent)


def _drive(agent: CarAgent, vehicle, rate_hz: float, deadline: float | None):
    """Run the agent next to the drive loop until stopped (Ctrl-C, deadline, revocation, restart)."""
    agent.start()
    watcher = threading.Thread(target=_stop_vehicle_when, args=(agent, vehicle, deadline), daemon=True)
    watcher.start()
    try:
        stats = vehicle.start(rate_hz=rate_hz)
    except KeyboardInterrupt:
        stats = vehicle.stats
    agent.stop()
    agent.flush_outbox()
    return stats


def _stop_vehicle_when(agent: CarAgent, vehicle, deadline: float | None) -> None:
    while not agent.wait(0.2):
        if deadline is not None and time.monotonic() >= deadline:
            break
    vehicle.stop()


def _run_deepracer(args: argparse.Namespace, client: DeviceClient, outbox: Outbox, models: ModelStore,
                   deadline: float | None, config_dir: Path) -> int:
    from drem_cars.drivers.deepracer_console import DeepRacerConsoleDriver

    if not args.deepracer_password:
        print("--deepracer needs --deepracer-password (or $DEEPRACER_PASSWORD)", file=sys.stderr)
        return 2
    try:
        console = wait_for_car(args.deepracer, args.deepracer_password, CarTrust(config_dir),
                               Path(args.deepracer_cert) if args.deepracer_cert else None, deadline)
    except (ConsoleError, CertificateProblem) as exc:
        print(f"DeepRacer console: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 0
    if console is None:  # the deadline passed while waiting
        return 0
    agent = CarAgent(client, DeepRacerConsoleDriver(console), outbox, models)
    with video_relay(args, client, ConsoleCamera(console)):
        run_until_stopped(agent, deadline)
    return _finish(agent)


def wait_for_car(url: str, password: str, trust: CarTrust, given_cert: Path | None, deadline: float | None,
                 *, first_wait_s: float = 1.0, longest_wait_s: float = 10.0,
                 sleep: Callable[[float], None] = time.sleep) -> DeepRacerConsole | None:
    """Log in to the car's console, waiting (1, 2, 4 ... 10 s apart) while it is not up: at an event the laptop is
    up before the cars. A refusal (password, certificate) is not waited out: the caller says why and stops."""
    wait_s, said = first_wait_s, False
    while True:
        try:
            fingerprint, trusted = trust.pin_for(url, given_cert)
            console = DeepRacerConsole(url, password, fingerprint=fingerprint)
            console.login()
        except (ConsoleUnreachable, OSError) as exc:
            if not said:
                print(f"waiting for the DeepRacer console at {url} (not answering yet: {exc}); trying again until "
                      "it does", file=sys.stderr, flush=True)
                said = True
        else:
            if trusted:
                print(trusted, file=sys.stderr, flush=True)
            if said:
                print(f"the DeepRacer console at {url} answers: driving it", file=sys.stderr, flush=True)
            return console
        if deadline is not None and time.monotonic() + wait_s >= deadline:
            return None
        sleep(wait_s)
        wait_s = min(longest_wait_s, wait_s * 2)


def _finish(agent: CarAgent) -> int:
    if agent.revoked:
        print(f"stopped: {agent.revoked}. Ask staff for a new activation code and run `drem car activate`.",
              file=sys.stderr)
        return EXIT_REVOKED
    if agent.restart_requested:
        print("restart requested by staff: restarting the agent", file=sys.stderr)
        if os.environ.get("DREM_CAR_NO_REEXEC") != "1":
            os.execv(sys.executable, [sys.executable, *sys.argv])
    return 0
