"""`drem events`: list, create, show and delete events through the drem HTTP API."""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any
from urllib.parse import quote

from drem_web.labels import label

HELP = "list, create, show or delete events (via the drem API)"
EVENT_TYPES = ("PRIVATE_WORKSHOP", "PRIVATE_TRACK_RACE", "OFFICIAL_WORKSHOP", "OFFICIAL_TRACK_RACE", "AWS_SUMMIT",
               "TEST_EVENT", "OTHER")
RANKINGS = ("BEST_LAP_TIME", "BEST_AVERAGE_LAP_TIME_X_LAP", "LAP_COUNT")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_connection_arguments

    add_connection_arguments(parser)
    parser.add_argument("--json", action="store_true", help="print the API's JSON answer")
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    actions.add_parser("list", help="all events, newest first")
    show = actions.add_parser("show", help="one event with its tracks and race rules")
    show.add_argument("event_id")
    delete = actions.add_parser("delete", help="delete an event (refused while one of its tracks has a live race)")
    delete.add_argument("event_id")
    create = actions.add_parser("create", help="create an event")
    create.add_argument("name")
    create.add_argument("--type", dest="event_type", choices=EVENT_TYPES, default="OTHER")
    create.add_argument("--date", required=True, help="YYYY-MM-DD")
    create.add_argument("--country", required=True, help="ISO 3166-1 alpha-2 code, e.g. GB")
    create.add_argument("--sponsor", default="")
    create.add_argument("--race-time", type=int, default=2, help="minutes per race (1-10)")
    create.add_argument("--resets", type=int, default=None, help="resets allowed per lap (0-10; default unlimited)")
    create.add_argument("--ranking", choices=RANKINGS, default="BEST_LAP_TIME")
    create.add_argument("--lap-target", type=int, default=None, help="LAP_COUNT: laps to finish")
    create.add_argument("--max-runs", type=int, default=3, help="races per racer (1-5; 0 = unlimited)")
    create.add_argument("--average-window", type=int, default=3, help="laps in the rolling average (3-7)")
    create.add_argument("--track-type", default="REINVENT_2018")
    create.add_argument("--track", action="append", default=None, metavar="TITLE[@FLEET_ID]",
                        help="a track's leaderboard title, optionally with its fleet; repeat for more tracks")
    create.add_argument("--from-json", type=argparse.FileType("r"), default=None,
                        help="create from a JSON body instead (the other options are ignored)")


def run(args: argparse.Namespace) -> int:
    from drem_local.api_client import ApiClient, ApiError

    try:
        answer = _perform(ApiClient.from_args(args), args)
    except ApiError as exc:
        print(f"drem events {args.action}: {exc}", file=sys.stderr)
        return 1
    if answer is not None:
        print(json.dumps(answer, indent=2) if args.json else describe(args.action, answer))
    return 0


def _perform(api: Any, args: argparse.Namespace) -> Any:
    if args.action == "list":
        return api.get("/api/events")
    if args.action == "show":
        return api.get(f"/api/events/{quote(args.event_id, safe='')}")
    if args.action == "delete":
        api.delete(f"/api/events/{quote(args.event_id, safe='')}")
        return {"deleted": args.event_id}
    return api.post("/api/events", json=json.load(args.from_json) if args.from_json else event_body(args))


def event_body(args: argparse.Namespace) -> dict[str, Any]:
    race_config: dict[str, Any] = {
        "race_time_min": args.race_time, "resets_per_lap": args.resets, "ranking_method": args.ranking,
        "max_runs_per_racer": args.max_runs or None, "average_window": args.average_window,
        "track_type": args.track_type}
    if args.lap_target is not None:
        race_config["lap_count_target"] = args.lap_target
    tracks = []
    for spec in args.track or ["Track 1"]:
        title, _, fleet = spec.partition("@")
        tracks.append({"leaderboard_title": title, "fleet_id": fleet or None})
    return {"name": args.name, "event_type": args.event_type, "date": args.date, "country_code": args.country,
            "sponsor": args.sponsor, "race_config": race_config, "tracks": tracks}


def describe(action: str, answer: dict[str, Any]) -> str:
    if action == "delete":
        return f"Deleted event {answer['deleted']}."
    if action == "list":
        if not answer["events"]:
            return "No events yet."
        return "\n".join(f"{e['event_id']:<14} {e['date']}  {e['country_code']}  "
                         f"{label(e['event_type']):<20} {e['name']}"
                         for e in answer["events"])
    rules = answer["race_config"]
    lines = [f"{answer['name']} ({answer['event_id']}), {label(answer['event_type'])}, {answer['date']}, "
             f"{answer['country_code']}" + (f", sponsor {answer['sponsor']}" if answer["sponsor"] else ""),
             f"  race: {rules['race_time_min']} min, resets/lap {_limit(rules['resets_per_lap'])}, "
             f"ranking: {label(rules['ranking_method']).lower()}, runs/racer {_limit(rules['max_runs_per_racer'])}, "
             f"average of {rules['average_window']}, track {label(rules['track_type'])}"]
    for track in answer["tracks"]:
        lines.append(f"  track {track['track_id']}: {track['leaderboard_title'] or '(untitled)'}, "
                     f"fleet {track['fleet_id'] or '-'}")
    if answer["combined_board"]:
        lines.append("  combined leaderboard over all tracks")
    return "\n".join(lines)


def _limit(value: int | None) -> str:
    return "unlimited" if value is None else str(value)
