"""`drem export EVENT_ID --out DIR`: write a whole event (with its racers, races, boards and models) to a folder.

Locally the state dir's stack.json says where the storage server is and what everything is called; with --aws the
default credential chain and the environment contract (DREM_STAGE, DREM_TABLE_*, DREM_BUCKET_*, DREM_USER_POOL_ID)
or the flags do. `drem import` reads the folder back into another stack.
"""
from __future__ import annotations

import argparse
import os
import sys
from datetime import UTC, datetime
from pathlib import Path

HELP = "export a whole event (races, boards, racers, models) to a folder that `drem import` reads"


def add_location_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("which stack")
    group.add_argument("--state-dir", type=Path, default=Path(os.environ.get("DREM_STATE_DIR", ".drem")),
                       help="the local stack's state dir (default .drem, or $DREM_STATE_DIR)")
    group.add_argument("--aws", action="store_true",
                       help="use real AWS (default credential chain; names from .drem-aws/STAGE.json, which "
                            "`make deploy` writes, or $DREM_TABLE_*, $DREM_BUCKET_*, $DREM_USER_POOL_ID)")
    group.add_argument("--stage", default=None, help="with --aws: the stage (default $DREM_STAGE)")
    group.add_argument("--user-pool-id", default=None, help="with --aws: the user pool (default $DREM_USER_POOL_ID)")


def open_stack(args: argparse.Namespace):
    from chalicelib.storage.event_archive import StackLocation, connect

    if args.aws:
        from drem_local.deployment import DEFAULT_DIR, Deployment

        env = {k: v for k, v in os.environ.items() if k != "AWS_ENDPOINT_URL"}
        stage = args.stage or env.get("DREM_STAGE")
        if stage and (DEFAULT_DIR / f"{stage}.json").is_file():  # what `make deploy` recorded
            env.update(Deployment.load(stage).environment())
        return connect(StackLocation.from_environment(env, stage, args.user_pool_id))
    return connect(StackLocation.from_state_dir(args.state_dir))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("event_id", metavar="EVENT_ID", help="the event to export")
    parser.add_argument("--out", type=Path, required=True, help="a new (or empty) folder to write")
    add_location_arguments(parser)


def run(args: argparse.Namespace) -> int:
    from chalicelib.core.errors import DremError
    from chalicelib.domain.event_transfer.export import collect_event
    from chalicelib.formats.event_export.writer import write_export

    try:
        bundle = collect_event(open_stack(args), args.event_id)
        manifest = write_export(bundle, args.out, datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"))
    except DremError as exc:
        print(f"drem export: {exc.message}", file=sys.stderr)
        return 1
    counts = manifest["counts"]
    print(f"Exported event {args.event_id} to {args.out}: {counts['races']} races, {counts['leaderboards']} "
          f"board/overlay items, {counts['accounts']} accounts, {counts['profiles']} profile items, "
          f"{counts['fleet']} fleets, {counts['archives']} model archives"
          f"{', the logo (' + manifest['logo'] + ')' if 'logo' in manifest else ''} ({len(manifest['files'])} files, "
          "checksums in manifest.json).")
    print("Not exported: devices and their credentials (cars and timers re-activate on the target), passwords.")
    return 0
