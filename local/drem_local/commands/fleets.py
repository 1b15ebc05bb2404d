"""`drem fleets`: list, create and delete fleets through the drem HTTP API."""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any
from urllib.parse import quote

HELP = "list, create or delete fleets of cars and timers (via the drem API)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_connection_arguments

    add_connection_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the API's JSON answer")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions.add_parser("list", help="fleets and their devices")
    create = actions.add_parser("create", help="create a fleet, optionally moving devices into it")
    create.add_argument("name")
    create.add_argument("device_ids", nargs="*", metavar="DEVICE_ID")
    delete = actions.add_parser("delete", help="delete a fleet (its devices stay registered, in no fleet)")
    delete.add_argument("fleet_id")


def run(args: argparse.Namespace) -> int:
    from drem_local.api_client import ApiClient, ApiError

    try:
        api = ApiClient.from_args(args)
        if args.action == "list":
            answer = api.get("/api/fleets")
        elif args.action == "create":
            answer = api.post("/api/fleets", json={"name": args.name, "device_ids": args.device_ids})
        else:
            api.delete(f"/api/fleets/{quote(args.fleet_id, safe='')}")
            answer = {"deleted": args.fleet_id}
    except ApiError as exc:
        print(f"drem fleets {args.action}: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(answer, indent=2) if args.json else describe(args.action, answer))
    return 0


def describe(action: str, answer: dict[str, Any]) -> str:
    if action == "delete":
        return f"Deleted fleet {answer['deleted']}."
    fleets = answer["fleets"] if action == "list" else [answer]
    if not fleets:
        return "No fleets yet."
    return "\n".join(f"{f['fleet_id']:<14} {f['name']:<24} {len(f['device_ids'])} device(s)"
                     + (f": {', '.join(f['device_ids'])}" if f["device_ids"] else "") for f in fleets)
