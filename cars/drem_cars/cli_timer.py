"""`drem timer`: a Raspberry Pi with two timing strips posts lap crossings to drem (durably, in order)."""
from __future__ import annotations

import argparse
import logging
import os
import sys
import time

from drem_cars.deployment_record import STAGE_HELP, NoDeploymentRecord, api_from_arguments

HELP = ("timing-strip agent for a Raspberry Pi: GPIO17/27 crossings → strip events "
        "(activate with `drem car activate --kind timer`)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--config-dir", default=os.environ.get("DREM_CAR_CONFIG"),
                        help="credential + outbox directory (default ~/.config/drem-car/)")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--api", help="override the API URL saved at activation")
    where.add_argument("--aws", action="store_true",
                       help="use the AWS deployment's public URL from .drem-aws/STAGE.json (`make deploy` writes it)")
    parser.add_argument("--stage", default=None, help=STAGE_HELP)
    parser.add_argument("--event", required=True, help="event id")
    parser.add_argument("--track", default="1", help="the event's track id (default 1)")
    parser.add_argument("--pins", default="17,27", help="BCM pins of the strips (default 17,27)")
    parser.add_argument("--seconds", type=float, help="stop after this many seconds (default: until Ctrl-C)")


def run(args: argparse.Namespace) -> int:
    from drem_cars.agent import CarAgent
    from drem_cars.credentials import NotActivated
    from drem_cars.drivers.timer_device import TimerDriver
    from drem_cars.parts.timing_strips import TimingStrips
    from drem_cars.runner import run_until_stopped
    from drem_cars.startup import start_device

    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        device = start_device(args.config_dir, api=api_from_arguments(args.api, args.aws, args.stage),
                              runs_models=False)
    except (NotActivated, NoDeploymentRecord) as exc:
        print(f"drem timer: {exc}", file=sys.stderr)
        return 1
    client, outbox = device.client, device.outbox
    print(f"timer {client.credential.hostname}: event {args.event}, track {args.track}, strips on GPIO "
          f"{args.pins}, posting to {client.api}", flush=True)
    pins = tuple(int(p) for p in args.pins.split(","))
    strips = TimingStrips(outbox, args.event, args.track, client.device_id, pins)
    agent = CarAgent(client, TimerDriver(), outbox, store=None)
    run_until_stopped(agent, time.monotonic() + args.seconds if args.seconds else None)
    agent.flush_outbox()
    strips.close()
    print(f"crossings queued {strips.queued}, ignored {strips.ignored}, outbox pending {outbox.count()}")
    if agent.revoked:
        print(f"stopped: {agent.revoked}", file=sys.stderr)
        return 3
    return 0
