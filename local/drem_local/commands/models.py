"""`drem models`: list, upload, delete and assign model archives through the drem HTTP API."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from drem_web.labels import label

# A scrutineering drive is synchronous: up to 3 laps with a per-lap time limit in the simulator.
SCRUTINEER_TIMEOUT_S = 600.0
HELP = "list, upload, delete, scrutineer model archives and assign them to cars (via the drem API)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_api_arguments

    add_api_arguments(parser)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    listing = actions.add_parser("list", help="your models (operators/admins: everyone's), newest first")
    listing.add_argument("--limit", type=int, default=25, help="models per page (1-100)")
    listing.add_argument("--all", action="store_true", help="follow the pages to the end")
    upload = actions.add_parser("upload", help="upload a .tar.gz model archive and wait for its verdict")
    upload.add_argument("file", type=Path, help="the archive, named like my-model.tar.gz")
    delete = actions.add_parser("delete", help="delete one of your models")
    delete.add_argument("model_id")
    scrutineer = actions.add_parser("scrutineer", help="test-drive a model in the simulator on an event's track")
    scrutineer.add_argument("model_id")
    scrutineer.add_argument("--event", dest="event_id", help="drive on this event's track type")
    scrutineer.add_argument("--track-type", help="or name the track type, e.g. ATOZ_SPEEDWAY (default REINVENT_2018)")
    scrutineer.add_argument("--laps", type=int, default=1, help="lap attempts (1-3)")
    assign = actions.add_parser("assign", help="give models to a car (no model ids: clear the car)")
    assign.add_argument("car", help="the car's device id")
    assign.add_argument("model_ids", nargs="*", metavar="MODEL")


def run(args: argparse.Namespace) -> int:
    from drem_local.api_client import ApiClient, ApiError

    try:
        api = ApiClient.from_args(args)
        return {"list": _list, "upload": _upload, "delete": _delete, "assign": _assign,
                "scrutineer": _scrutineer}[args.action](api, args)
    except ApiError as exc:
        print(f"drem models {args.action}: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"drem models {args.action}: {exc}", file=sys.stderr)
        return 1


def _list(api: Any, args: argparse.Namespace) -> int:
    from urllib.parse import urlencode

    params: dict[str, Any] = {"limit": args.limit}
    rows: list[dict[str, Any]] = []
    while True:
        page = api.get(f"/api/models?{urlencode(params)}")
        rows.extend(page["models"])
        if not args.all or not page.get("next"):
            break
        params["next"] = page["next"]
    print(f"{'MODEL ID':<26} {'NAME':<24} {'OWNER':<16} {'STATUS':<12} UPLOADED")
    for model in rows:
        print(f"{model['model_id']:<26} {model['name']:<24} {model['owner_username']:<16} "
              f"{label(model['status']):<14} {model['uploaded_at']}")
        if model.get("reason"):
            print(f"{'':<26} reason: {model['reason']}")
    return 0


def _upload(api: Any, args: argparse.Namespace) -> int:
    import requests

    path: Path = args.file
    if not path.is_file():
        print(f"drem models upload: {path} is not a file", file=sys.stderr)
        return 1
    ticket = api.post("/api/models", {"filename": path.name})
    if path.stat().st_size > ticket["max_bytes"]:
        print(f"drem models upload: {path.name} is larger than the {ticket['max_bytes']} byte limit",
              file=sys.stderr)
        return 1
    model_id = ticket["model"]["model_id"]
    with path.open("rb") as handle:
        posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                               files={"file": (path.name, handle)}, timeout=600)
    if posted.status_code not in (200, 201, 204):
        print(f"drem models upload: storage refused the file (HTTP {posted.status_code})", file=sys.stderr)
        return 1
    model = api.post(f"/api/models/{model_id}/complete")["model"]
    print(f"{model['name']} ({model['model_id']}): {label(model['status'])}")
    if model.get("reason"):
        print(f"reason: {model['reason']}")
    if model.get("scrutiny") == "cannot_scrutineer":
        print(f"cannot be scrutineered: {model.get('scrutiny_reason')}")
    return 0 if model["status"] == "AVAILABLE" else 3


def _scrutineer(api: Any, args: argparse.Namespace) -> int:
    body = {"laps": args.laps, **({"event_id": args.event_id} if args.event_id else {}),
            **({"track_type": args.track_type} if args.track_type else {})}
    api.timeout_s = max(api.timeout_s, SCRUTINEER_TIMEOUT_S)  # the drive runs inside the request
    model = api.post(f"/api/models/{args.model_id}/scrutineer", body)["model"]
    result = model["scrutineer_result"]
    best = f"{result['best_lap_time_s']:.2f}s" if result.get("best_lap_time_s") is not None else "-"
    print(f"{model['name']} ({model['model_id']}) on {result['track_type'] or result['track']}: {result['verdict']}")
    print(f"laps completed {result['laps_completed']}/{result['laps']}, best lap {best}, "
          f"off-tracks {result['offtrack_count']}")
    return 0 if result["verdict"] == "passed" else 3


def _delete(api: Any, args: argparse.Namespace) -> int:
    model = api.delete(f"/api/models/{args.model_id}")["model"]
    print(f"{model['name']} ({model['model_id']}): {label(model['status'])}")
    return 0


def _assign(api: Any, args: argparse.Namespace) -> int:
    assignment = api.put(f"/api/cars/{args.car}/models", {"model_ids": args.model_ids})["assignment"]
    names = ", ".join(f"{m['owner_username']}/{m['name']}" for m in assignment["models"]) or "nothing (cleared)"
    print(f"{assignment['device_id']}: {names}")
    return 0
