"""`drem car`: activate this device, run the car agent (simulator or hardware), show its state."""
from __future__ import annotations

import argparse
import json
import logging
import os
import socket
import sys

from drem_cars.deployment_record import STAGE_HELP, NoDeploymentRecord, api_from_arguments

HELP = "car agent: activate this car, run it (--sim, --pwm camera + PWM, --deepracer), show its status"
EXIT_REVOKED = 3  # the same code as drem_cars.runner.EXIT_REVOKED (kept here so --help stays light)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config-dir", default=os.environ.get("DREM_CAR_CONFIG"),
                        help="where the credential, outbox and models live (default ~/.config/drem-car/)")
    sub = parser.add_subparsers(dest="car_command", metavar="ACTION", required=True)
    activate = sub.add_parser("activate", help="exchange a one-time activation code for this device's credential")
    activate.add_argument("--code", required=True, help="the code staff created for this car")
    where = activate.add_mutually_exclusive_group(required=True)
    where.add_argument("--api", help="drem API base URL, e.g. http://127.0.0.1:8000")
    where.add_argument("--aws", action="store_true",
                       help="the public URL of the AWS deployment, from .drem-aws/STAGE.json (`make deploy` writes it)")
    activate.add_argument("--stage", default=None, help=STAGE_HELP)
    activate.add_argument("--hostname", default=socket.gethostname().split(".")[0],
                          help="this car's hostname as staff entered it (default: this machine's)")
    activate.add_argument("--kind", choices=("car", "timer"), default="car")
    run = sub.add_parser("run", help="run the agent and the drive loop")
    run.add_argument("--sim", action="store_true", help="drive the simulator instead of hardware")
    run.add_argument("--track", default=None, help="simulator track (default reinvent_base when its DeepRacer route "
                                                   "file is found, else drem_oval, which ships with drem)")
    run.add_argument("--event", help="event id: the sim's timing line posts strip events to it")
    run.add_argument("--race-track", default="1", help="the event's track id for strip events (default 1)")
    run.add_argument("--rate-hz", type=float, default=15.0, help="drive loop rate (sim: >15 runs faster than life)")
    run.add_argument("--seconds", type=float, help="stop after this many seconds (default: run until Ctrl-C)")
    run.add_argument("--heartbeat-limit", type=float, default=60.0,
                     help="stop the car after this many seconds without reaching the server (default 60)")
    run.add_argument("--deepracer", metavar="URL", help="drive an AWS DeepRacer through its device console at URL")
    run.add_argument("--deepracer-password", default=os.environ.get("DEEPRACER_PASSWORD"),
                     help="device console password (or $DEEPRACER_PASSWORD)")
    run.add_argument("--deepracer-cert", metavar="FILE",
                     help="--deepracer: the car's certificate (PEM, or its SHA-256 fingerprint) to trust; by default "
                          "drem trusts the one the car shows at first contact and refuses any other later")
    run.add_argument("--live-url", default=os.environ.get("DREM_LIVE_URL"),
                     help="the live server the camera goes to (default $DREM_LIVE_URL, else the API's address, "
                          "where a proxy routes /live/ to it)")
    run.add_argument("--no-video", action="store_true",
                     help="never send the camera (by default it goes only while the car races or staff preview it)")
    run.add_argument("--video-fps", type=float, default=15.0, help="camera frames a second sent (default 15)")
    run.add_argument("--video-size", default="480x360", help="camera picture size WIDTHxHEIGHT (default 480x360)")
    run.add_argument("--video-view", choices=("camera", "model"), default="camera",
                     help="camera: the picture in colour; model: what the model sees (160x120 grey)")
    run.add_argument("--pwm", action="store_true",
                     help="drive a DIY car: OpenCV camera + steering servo and motor on Linux sysfs PWM")
    run.add_argument("--camera", default="0", help="--pwm: camera index (0 = /dev/video0), video file or URL")
    run.add_argument("--pwm-root", default="/sys/class/pwm", help="--pwm: sysfs PWM root (default /sys/class/pwm)")
    run.add_argument("--pwm-chip", type=int, default=None,
                     help="--pwm: pwmchipN of the servo and motor (default: the DeepRacer board's chip, found by "
                          "its 0000:00:17.0 device link)")
    run.add_argument("--servo-channel", type=int, default=1, help="--pwm: steering servo channel (DeepRacer: 1)")
    run.add_argument("--motor-channel", type=int, default=0, help="--pwm: drive motor (ESC) channel (DeepRacer: 0)")
    run.add_argument("--servo-enable-gpio", default="436",
                     help="--pwm: GPIO that powers the servos, active low (DeepRacer: 436); 'none' if there is none")
    run.add_argument("--gpio-root", default="/sys/class/gpio", help="--pwm: sysfs GPIO root (default /sys/class/gpio)")
    run.add_argument("--calibration", metavar="FILE",
                     help="--pwm: DeepRacer calibration.json (default: the car's /opt/aws/deepracer/calibration.json "
                          "if present, else DeepRacer's factory values)")
    sub.add_parser("status", help="show this device's activation and local state")


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    if args.car_command == "activate":
        return _activate(args)
    if args.car_command == "status":
        return _status(args)
    return _run(args)


def _activate(args: argparse.Namespace) -> int:
    from drem_cars.client import DeviceApiError, activate
    from drem_cars.credentials import CredentialStore

    try:
        api = api_from_arguments(args.api, args.aws, args.stage)
    except NoDeploymentRecord as exc:
        print(f"drem car activate: {exc}", file=sys.stderr)
        return 1
    assert api is not None  # argparse requires --api or --aws
    store = CredentialStore(args.config_dir)
    try:
        credential = activate(api, args.code, args.hostname, args.kind,
                              attempt_id=store.attempt_id_for(args.code))
    except DeviceApiError as exc:
        print(f"activation failed: {exc}", file=sys.stderr)
        return 1
    store.save(credential)
    print(f"activated {credential.device_kind} {credential.hostname} at {credential.api} as {credential.device_id} "
          f"(fleet {credential.fleet_id}); credential saved to {store.path} (mode 0600)")
    return 0


def _status(args: argparse.Namespace) -> int:
    from drem_cars.client import DeviceApiError
    from drem_cars.credentials import NotActivated
    from drem_cars.startup import start_device

    try:
        device = start_device(args.config_dir)
    except NotActivated as exc:
        print(exc, file=sys.stderr)
        return 1
    client, outbox, models = device.client, device.outbox, device.models
    assert models is not None  # a car runs models
    local = {"device_id": client.device_id, "api": client.api, "hostname": client.credential.hostname,
             "fleet_id": client.credential.fleet_id, "outbox_pending": outbox.count("pending"),
             "outbox_rejected": outbox.count("rejected"),
             "models": sorted(m.folder for m in models.installed().values())}
    try:
        local["server"] = client.request("GET", "/api/devices/self", what="status")
    except DeviceApiError as exc:
        local["server"] = f"unavailable: {exc}"
    print(json.dumps(local, indent=2))
    return 0


def _run(args: argparse.Namespace) -> int:
    from drem_cars.runner import run_agent

    return run_agent(args)
