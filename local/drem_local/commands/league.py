"""`drem league`: push a model export to the virtual league, pull a track's board.

    drem league push PATH [PATH ...] --track TRACK [--racer NAME] [--model-name NAME] [--dry-run]
    drem league pull --track TRACK [--sort best|avg] [--algorithm A] [--sensor S] [--since DAY] [--until DAY]
                     [--csv FILE | --json]

Each PATH is a folder or .tar.gz the racer has, as their tool wrote it: a console or DROA logs download, a
DeepRacer-for-Cloud model prefix, the console's model download (it holds model_metadata.json), a drem model. The CLI
only packs the files the server reads (metadata, hyperparameters, params, logs, metrics, evaluation sim-traces; never
the model graph, checkpoints or training sim-traces) into one .tar.gz and uploads it; the server assembles the
submission and checks it. A PATH that is a model archive (a console model download with agent/model.pb, a drem model
with model.onnx) is also uploaded as a model (as `drem models upload` does), so drem re-drives it on the track and
ranks what it measured ("verified by drem"); --self-reported leaves it at the logs.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import re
import sys
from pathlib import Path
from typing import Any

PACK_FILE_MIB = 32  # the CLI packs every file the server reads, each at most this big (a long robomaker log)

HELP = "push a model export to the virtual league; pull a track's board (table, CSV or JSON)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from drem_local.api_client import add_api_arguments

    add_api_arguments(parser)
    actions = parser.add_subparsers(dest="action", metavar="ACTION", required=True)
    push = actions.add_parser("push", help="upload a model export's files; the server assembles the submission")
    push.add_argument("path", type=Path, nargs="+",
                      help="export folders or .tar.gz files (e.g. the logs download and the model download)")
    push.add_argument("--track", required=True, help="the track the model was evaluated on, e.g. reinvent_base")
    push.add_argument("--racer", help="racer name (default: the signed-in username; admins may name another)")
    push.add_argument("--model-name", help="default: the export's folder or archive name")
    push.add_argument("--dry-run", action="store_true", help="list the files that would be uploaded, send nothing")
    push.add_argument("--self-reported", action="store_true",
                      help="do not upload the model archive for drem to re-drive; rank the logs alone")
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
    from chalicelib.core.errors import DremError
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
    from chalicelib.domain.league_intake import MAX_UPLOAD_BYTES
    from chalicelib.formats.league_export import ExportLimits, MiB, pack_exports, read_export
    from drem_local.api_client import ApiClient

    limits = ExportLimits(max_file_bytes=PACK_FILE_MIB * MiB, max_total_read_bytes=3 * PACK_FILE_MIB * MiB)
    exports = [with_sim_evaluation(read_export(path, limits=limits), path, args.track) for path in args.path]
    upload = pack_exports(exports)
    model_name = args.model_name or safe_model_name(exports[0].source_name)
    names = sorted({name for export in exports for name in export.files})
    if args.dry_run:
        print("\n".join(names))
        print(f"{len(names)} files, {len(upload)} bytes packed, for {model_name} on {args.track}")
        return 0
    if len(upload) > MAX_UPLOAD_BYTES:
        raise OSError(f"the packed files take {len(upload)} bytes, more than the {MAX_UPLOAD_BYTES} the server "
                      f"takes; leave out old evaluations' logs and sim-traces")
    api = ApiClient.from_args(args)
    params = {"model_name": model_name, **({"racer": args.racer} if args.racer else {})}
    archive = None if args.self_reported else model_archive(args.path, exports)
    if archive is not None:
        params["model_id"] = upload_model(api, archive)
    reply = api.post_bytes(f"/api/league/{args.track}/submissions", upload, "application/gzip", params=params)
    entry, layout = reply["entry"], reply["submission"]["layout"]
    best = f"{entry['best_lap_s']:.3f} s" if entry["best_lap_s"] is not None else "no completed lap"
    print(f"pushed {entry['model_name']} for {entry['racer']} on {args.track} ({layout} export): "
          f"{entry['laps_completed']}/{entry['trials']} laps, best {best}")
    if archive is not None:
        print(f"drem re-drives {archive.name} on {args.track} in the background; the board then ranks what it "
              "measured (verified by drem)")
    return 0


def model_archive(paths: list[Path], exports: list[Any]) -> Path | None:
    """The PATH that is a model archive drem can drive (.tar.gz with agent/model.pb or model.onnx)."""
    for path, export in zip(paths, exports, strict=True):
        if path.is_file() and {"agent/model.pb", "model.onnx"} & set(export.names):
            return path
    return None


def upload_model(api: Any, path: Path) -> str:
    """Upload the model archive as `drem models upload` does; its id once the server accepted it."""
    import requests

    from drem_local.api_client import ApiError

    ticket = api.post("/api/models", {"filename": path.name})
    if path.stat().st_size > ticket["max_bytes"]:
        raise ApiError(413, f"{path.name} is larger than the {ticket['max_bytes']} byte model limit")
    with path.open("rb") as handle:
        posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                               files={"file": (path.name, handle)}, timeout=600)
    if posted.status_code not in (200, 201, 204):
        raise ApiError(posted.status_code, f"storage refused {path.name} (HTTP {posted.status_code})")
    model = api.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]
    duplicate = model.get("duplicate_of") or {}
    if model["status"] != "AVAILABLE" and duplicate.get("model_id"):
        # The racer uploaded this very model before (to push it to another track, say): push with that one.
        print(f"{path.name} is your model '{duplicate.get('name')}', uploaded before: pushing with it")
        return str(duplicate["model_id"])
    if model["status"] != "AVAILABLE":
        raise ApiError(400, f"{path.name} was not accepted as a model ({model['status']}: {model.get('reason')}); "
                            "push with --self-reported to rank the logs alone")
    return str(model["model_id"])


def safe_model_name(source_name: str) -> str:
    """The export's folder or archive name as the board shows it (letters, digits, '_', '.', '-')."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", source_name).strip("-.")[:80] or "model"


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
