"""`drem league`: push a model export to the virtual league, pull a track's board.

    drem league push PATH --track TRACK [--racer NAME] [--model-name NAME] [--dry-run]
    drem league pull --track TRACK [--sort best|avg] [--algorithm A] [--sensor S] [--since DAY] [--until DAY]
                     [--csv FILE | --json]

PATH is a model export folder or .tar.gz in any real layout (old/new console export, DeepRacer-for-Cloud model
prefix, a drem sim run); the assembler reads it locally, in memory, and sends one JSON submission.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path
from typing import Any

HELP = "push a model export to the virtual league; pull a track's board (table, CSV or JSON)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_api_arguments

    add_api_arguments(parser)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    push = actions.add_parser("push", help="assemble a submission from a model export and push it")
    push.add_argument("path", type=Path, help="export folder or .tar.gz")
    push.add_argument("--track", required=True, help="the track the model was evaluated on, e.g. reinvent_base")
    push.add_argument("--racer", help="racer name (default: the signed-in username; admins may name another)")
    push.add_argument("--model-name", help="default: the export's folder or archive name")
    push.add_argument("--dry-run", action="store_true", help="print the submission, send nothing")
    pull = actions.add_parser("pull", help="a track's board")
    pull.add_argument("--track", required=True)
    pull.add_argument("--sort", choices=("best", "avg"), default="best", help="best lap (default) or average lap")
    pull.add_argument("--algorithm", help="only this training algorithm (clipped_ppo, sac, behaviour_cloning)")
    pull.add_argument("--sensor", help="only models with this sensor")
    pull.add_argument("--since", help="only submissions on or after YYYY-MM-DD")
    pull.add_argument("--until", help="only submissions on or before YYYY-MM-DD")
    output = pull.add_mutually_exclusive_group()
    output.add_argument("--csv", type=Path, metavar="FILE", help="save the board as CSV")
    output.add_argument("--json", action="store_true", help="print the board as JSON")


def run(args: argparse.Namespace) -> int:
    from chalicelib.domain.errors import DremError
    from drem_local.api_client import ApiError

    try:
        return _push(args) if args.action == "push" else _pull(args)
    except (ApiError, DremError) as exc:
        print(f"drem league {args.action}: {getattr(exc, 'message', None) or exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"drem league {args.action}: {exc}", file=sys.stderr)
        return 1


def _push(args: argparse.Namespace) -> int:
    from chalicelib.formats.league_assembler import assemble
    from chalicelib.formats.league_export import read_export
    from drem_local.api_client import ApiClient

    export = with_sim_evaluation(read_export(args.path), args.path, args.track)
    if args.dry_run:
        racer = args.racer or args.username or "racer"
        print(assemble(export, racer=racer, track=args.track, model_name=args.model_name).model_dump_json(indent=2))
        return 0
    api = ApiClient.from_args(args)
    racer = args.racer or api.get("/api/me")["username"]
    submission = assemble(export, racer=racer, track=args.track, model_name=args.model_name)
    reply = api.post(f"/api/league/{args.track}/submissions", json=submission.model_dump(mode="json"))
    entry = reply["entry"]
    best = f"{entry['best_lap_s']:.3f} s" if entry["best_lap_s"] is not None else "no completed lap"
    print(f"pushed {entry['model_name']} for {entry['racer']} on {args.track} ({submission.layout} export): "
          f"{entry['laps_completed']}/{entry['trials']} laps, best {best}")
    return 0


def with_sim_evaluation(export: Any, path: Any, track: str) -> Any:
    """A drem model (its training/lineage.json) without an evaluation on `track`: run `drem sim eval` on it here,
    so drem's own models (the samples included) can be pushed as they are, like a console export with its metrics."""
    names = set(export.names)
    if not names & {"lineage.json", "training/lineage.json"} or "metrics.json" in names:
        return export
    try:
        from drem_sim.learn.evaluate import evaluate_model
    except ImportError as exc:
        raise OSError(f"this export has no metrics.json, and the simulator that would make one is not installed "
                      f"({exc}); run `drem sim eval --model {path} --track {track} --out DIR` where it is") from None
    print(f"no evaluation in {path}: evaluating it on {track} in the simulator (3 laps) ...", file=sys.stderr)
    try:
        metrics = evaluate_model(path, track, laps=3)
    except ValueError as exc:  # an unknown track or a model the simulator cannot run
        raise OSError(f"could not evaluate {path} on {track}: {exc}") from None
    export.files["metrics.json"] = metrics.model_dump_json().encode()
    export.names.append("metrics.json")
    return export


def _pull(args: argparse.Namespace) -> int:
    from chalicelib.domain.league import BOARD_COLUMNS
    from drem_local.api_client import ApiClient, api_url

    api = ApiClient(api_url(args), args.token)  # the board is public: no sign-in needed
    params = {key: value for key in ("sort", "algorithm", "sensor", "since", "until")
              if (value := getattr(args, key))}
    board = api.get(f"/api/league/{args.track}", params=params)
    rows = rows_of(board)
    if args.json:
        print(json.dumps({"track": board["track"], "sort": board["sort"], "rows": rows}, indent=2))
    elif args.csv:
        args.csv.write_text(to_csv(rows, BOARD_COLUMNS), encoding="utf-8")
        print(f"saved {len(rows)} rows to {args.csv}")
    else:
        print(table(rows, BOARD_COLUMNS) if rows else f"no submissions on {args.track} yet")
    return 0


def rows_of(board: dict[str, Any]) -> list[dict[str, Any]]:
    from chalicelib.domain.league import Board

    return Board.model_validate(board).rows()


def to_csv(rows: list[dict[str, Any]], columns: tuple[str, ...]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), lineterminator="\n")
    writer.writeheader()
    writer.writerows({key: "" if row[key] is None else row[key] for key in columns} for row in rows)
    return buffer.getvalue()


def table(rows: list[dict[str, Any]], columns: tuple[str, ...]) -> str:
    """An aligned terminal table: numbers right-aligned, text left-aligned, '-' for no value."""
    def cell(value: Any) -> str:
        if value is None:
            return "-"
        return f"{value:.3f}" if isinstance(value, float) else str(value)
    cells = [[cell(row[key]) for key in columns] for row in rows]
    widths = [max(len(column), *(len(line[i]) for line in cells)) for i, column in enumerate(columns)]
    numeric = [all(isinstance(row[key], int | float) or row[key] is None for row in rows) for key in columns]
    def line(values: list[str]) -> str:
        return "  ".join(v.rjust(w) if num else v.ljust(w) for v, w, num in zip(values, widths, numeric,
                                                                                strict=True)).rstrip()
    return "\n".join([line(list(columns)), line(["-" * w for w in widths]), *(line(values) for values in cells)])
