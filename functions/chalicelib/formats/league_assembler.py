"""Build one league submission from a model export in any of the real layouts (pure: no AWS, no disk writes).

Five inputs, found by where each layout puts them (deepracer-formats.md §5):

| input               | old/new console export (DROA)           | DeepRacer-for-Cloud prefix        | drem sim run            |
|---------------------|-----------------------------------------|-----------------------------------|-------------------------|
| model metadata      | model/model_metadata.json               | model/model_metadata.json         | model_metadata.json     |
| hyperparameters     | ip/hyperparameters.json                 | ip/hyperparameters.json           | lineage.json            |
| training params     | training_params.yaml, else the WORLD_NAME the training log prints | training_params.yaml | lineage.json (dataset) |
| training metrics    | metrics/training/**.json                | metrics/TrainingMetrics.json      | lineage.json (losses)   |
| evaluation metrics  | metrics/evaluation/**.json (newest)     | metrics/EvaluationMetrics-*.json (newest) | metrics.json   |

Every problem raises `ExportProblem` naming the file and the field ("ip/hyperparameters.json: missing"), so the racer
knows what to fix; nothing is built from a half-read export.
"""
from __future__ import annotations

import json
import re
from typing import Any

import yaml

from chalicelib.domain.errors import InvalidInput
from chalicelib.domain.league import EvaluationTrial, SubmissionInput
from chalicelib.formats.league_export import ExportFiles
from chalicelib.formats.model_metadata import ModelMetadata, ModelMetadataError, parse_model_metadata_json

LAYOUT_CONSOLE_OLD = "console-old"
LAYOUT_CONSOLE_NEW = "console-new"
LAYOUT_DRFC = "drfc"
LAYOUT_DREM = "drem-sim"

_ISO_FOLDER = re.compile(r"(^|/)\d{4}-\d{2}-\d{2}T\d{2}[:-]?\d{2}")
# How the simulation logs name the track: the console's robomaker log prints `WORLD_NAME=reinvent_base` (env) and
# `'WORLD_NAME': 'reinvent_base'` (params); DeepRacer-on-AWS (DROA) simulation logs print SageMaker's
# `"world_name": "Spain_track"` and `hyperparameter world_name value Spain_track`.
_WORLD_IN_LOG = re.compile(r"""world_name['"]?(?:\s*[:=]\s*|\s+value\s+)['"]?([A-Za-z0-9_-]{1,64})""", re.I)
_EVALUATION_LOG = re.compile(r"(^|/)logs/(evaluation|leaderboard)/[^/]+\.log$")
# A console/DROA metrics file is named after its job: "evaluation-20220703172413-wDhqXQC-SkGOinLUdZCQZQ.json",
# "2026-03-07T17:52:00.898Z-deepracerindy-evaluation-9oJ3QbS0SYm7Iag.json"; the job's log mentions that name.
_ISO_PREFIX = re.compile(r"^\d{4}-\d{2}-\d{2}T[\d:.-]+Z?-")
_DRFC_TRAINING_METRICS = re.compile(r"(^|/)metrics/TrainingMetrics(_\d+)?\.json$")
_MODEL_NAME_UNSAFE = re.compile(r"[^A-Za-z0-9_.-]+")
_MAX_YAML_BYTES = 256 * 1024


class ExportProblem(InvalidInput):
    """A file of the export is missing or wrong; `field` is "file: field"."""

    def __init__(self, file: str, problem: str, field: str | None = None) -> None:
        where = f"{file}: {field}" if field else file
        super().__init__(f"{where}: {problem}", field=where)


def detect_layout(files: ExportFiles) -> str:
    names = files.names
    if any(n in ("lineage.json", "training/lineage.json") for n in names) and "metrics.json" in names:
        return LAYOUT_DREM
    if any(n.split("/")[-1] == "TrainingMetrics.json" or "/EvaluationMetrics" in f"/{n}" for n in names):
        return LAYOUT_DRFC
    if any(n.endswith("-simulation.log") or _ISO_FOLDER.search(n) for n in names):
        return LAYOUT_CONSOLE_NEW
    return LAYOUT_CONSOLE_OLD


def assemble(files: ExportFiles, *, racer: str, track: str, model_name: str | None = None) -> SubmissionInput:
    layout = detect_layout(files)
    metadata_file = _first(files, ["model/model_metadata.json", "model_metadata.json", "agent/model_metadata.json"],
                           suffix="/model_metadata.json", what="model metadata (model_metadata.json)")
    metadata = _metadata(files, metadata_file)
    if layout == LAYOUT_DREM:
        parts = _drem_parts(files, track)
    else:
        parts = _deepracer_parts(files, track)
    name = model_name or _MODEL_NAME_UNSAFE.sub("-", files.source_name).strip("-.") or "model"
    try:
        return SubmissionInput(racer=racer, track=track, model_name=name[:80], layout=layout,
                               sensor=list(metadata.sensor), algorithm=metadata.training_origin,
                               action_space_type=metadata.action_space_type.value,
                               action_space=action_space_summary(metadata), **parts)
    except ValueError as error:  # pydantic: a value out of range (e.g. a negative lap time)
        raise InvalidInput(f"the export gives a value the league cannot accept: {error}") from None


def action_space_summary(metadata: ModelMetadata) -> str:
    space = metadata.action_space
    if isinstance(space, list):
        steering = [a.steering_angle for a in space]
        speeds = [a.speed for a in space]
        return (f"{len(space)} discrete actions, steering {_num(min(steering))}..{_num(max(steering))} deg, "
                f"speed {_num(min(speeds))}..{_num(max(speeds))} m/s")
    return (f"continuous, steering {_num(space.steering_angle.low)}..{_num(space.steering_angle.high)} deg, "
            f"speed {_num(space.speed.low)}..{_num(space.speed.high)} m/s")


# -- DeepRacer console / DRfC ------------------------------------------------------------------------------------------

def _deepracer_parts(files: ExportFiles, track: str) -> dict[str, Any]:
    hyper_file = _first(files, ["ip/hyperparameters.json", "hyperparameters.json"], suffix="/hyperparameters.json",
                        what="hyperparameters (ip/hyperparameters.json)")
    hyperparameters = _hyperparameters(files, hyper_file)
    training_track = _training_world(files)
    training: list[tuple[str, dict[str, Any]]] = []
    for training_file in _training_metric_files(files):
        episodes = _metric_entries(files, training_file, ("completion_percentage",))
        in_training = [e for e in episodes if e.get("phase", "training") == "training"] or episodes
        training += [(training_file, e) for e in in_training]
    evaluation_file = _newest(files, r"(^|/)metrics/EvaluationMetrics[^/]*\.json$|(^|/)metrics/evaluation/.+\.json$",
                              "evaluation metrics (metrics/EvaluationMetrics-*.json or metrics/evaluation/*.json)")
    _check_evaluation_world(files, track, evaluation_file)
    entries = _metric_entries(files, evaluation_file, ("completion_percentage", "elapsed_time_in_milliseconds"))
    trials = [EvaluationTrial(
        trial=_int(evaluation_file, entry, "trial", index, default=index + 1),
        time_s=round(_number(evaluation_file, entry, "elapsed_time_in_milliseconds", index) / 1000.0, 3),
        completion_pct=min(_number(evaluation_file, entry, "completion_percentage", index), 100.0),
        off_track_count=_int(evaluation_file, entry, "off_track_count", index, default=0),
        reset_count=_int(evaluation_file, entry, "reset_count", index, default=0),
        crash_count=_int(evaluation_file, entry, "crash_count", index, default=0),
        status=str(entry.get("episode_status", ""))[:40]) for index, entry in enumerate(entries)]
    best = max(_number(name, e, "completion_percentage", i) for i, (name, e) in enumerate(training))
    return dict(hyperparameters=hyperparameters, training_track=training_track, training_episodes=len(training),
                training_best_completion_pct=min(best, 100.0), trials=trials)


def _metadata(files: ExportFiles, name: str) -> ModelMetadata:
    try:
        return parse_model_metadata_json(files.read(name))
    except ModelMetadataError as error:
        detail = error.message.removeprefix("model_metadata.json: ").removeprefix("model_metadata.json ")
        raise ExportProblem(name, detail) from None


def _hyperparameters(files: ExportFiles, name: str) -> dict[str, Any]:
    document = _json(files, name)
    if not isinstance(document, dict) or not document:
        raise ExportProblem(name, "must hold a JSON object of hyperparameters")
    if len(document) > 60:
        raise ExportProblem(name, f"holds {len(document)} keys; at most 60 are accepted")
    for key, value in document.items():
        if not (value is None or isinstance(value, str | int | float | bool)) or len(str(key)) > 64:
            raise ExportProblem(name, "must be a number, text or true/false", field=str(key)[:64])
        if isinstance(value, str) and len(value) > 200:
            raise ExportProblem(name, "is longer than 200 characters", field=key)
    return document


def _training_metric_files(files: ExportFiles) -> list[str]:
    """DRfC with several workers writes metrics/TrainingMetrics.json, TrainingMetrics_1.json, … (one per worker):
    every worker's episodes count. Consoles write one file per training job under metrics/training/: the newest."""
    workers = sorted(n for n in files.files if _DRFC_TRAINING_METRICS.search(n))
    if workers:
        return workers
    return [_newest(files, r"(^|/)metrics/training/.+\.json$",
                    "training metrics (metrics/TrainingMetrics.json or metrics/training/*.json)")]


def _training_world(files: ExportFiles) -> str:
    """The track the model trained on, from the training params or the training log (console and DROA exports have
    no params file: their simulation logs print the world name)."""
    yaml_name = _matching(files, r"(^|/)training[-_]params\.ya?ml$")
    if yaml_name:
        return _world_name(files, yaml_name)
    log_name = _matching(files, r"(^|/)logs/training/[^/]*-(robomaker|simulation)\.log$")
    if log_name:
        world = _world_in_log(files, log_name)
        if world is None:
            raise ExportProblem(log_name, "the training log does not say which track (no WORLD_NAME)")
        return world
    raise ExportProblem("training_params.yaml", "missing (no training params YAML and no training log that names "
                        "the track)")


def _world_in_log(files: ExportFiles, name: str) -> str | None:
    found = _WORLD_IN_LOG.search(files.read(name).decode("utf-8", "replace"))
    return found.group(1) if found else None


def _check_evaluation_world(files: ExportFiles, track: str, evaluation_file: str) -> None:
    """Every place the export names the track of the evaluation whose laps are submitted must say `track`: the
    evaluation params YAML (DRfC) and the evaluation's own simulation log (console: logs/evaluation or
    logs/leaderboard; DROA: logs/evaluation/*-simulation.log). Real console/DROA exports have no params YAML, so the
    log is what tells. The log of that evaluation is the one that mentions its metrics file's job name; when no log
    does, every evaluation log in the export must name `track` (an export cannot hide a foreign evaluation)."""
    yaml_name = _matching(files, r"(^|/)eval(uation)?[-_]params\.ya?ml$")
    if yaml_name:
        world = _world_name(files, yaml_name)
        if world != track:
            raise ExportProblem(yaml_name, f"the evaluation ran on {world!r}, not on {track!r}", field="WORLD_NAME")
    logs = sorted(n for n in files.files if _EVALUATION_LOG.search(n))
    job = _ISO_PREFIX.sub("", evaluation_file.rsplit("/", 1)[-1].removesuffix(".json"))
    texts = {name: files.read(name).decode("utf-8", "replace") for name in logs}
    own = [name for name, text in texts.items() if len(job) >= 8 and job in text]
    for name in own or logs:
        found = _WORLD_IN_LOG.search(texts[name])
        if found and found.group(1) != track:
            raise ExportProblem(name, f"the evaluation ran on {found.group(1)!r}, not on {track!r}",
                                field="WORLD_NAME")


def _world_name(files: ExportFiles, name: str) -> str:
    raw = files.read(name)
    if len(raw) > _MAX_YAML_BYTES:
        raise ExportProblem(name, "is too large for a params file")
    try:
        document = yaml.safe_load(raw.decode("utf-8-sig"))
    except (yaml.YAMLError, UnicodeDecodeError) as error:
        raise ExportProblem(name, f"is not valid YAML ({str(error).splitlines()[0][:120]})") from None
    if not isinstance(document, dict):
        raise ExportProblem(name, "must be a YAML mapping of KEY: value")
    world = document.get("WORLD_NAME")
    if not isinstance(world, str) or not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", world):
        raise ExportProblem(name, "missing or not a track name", field="WORLD_NAME")
    return world


def _metric_entries(files: ExportFiles, name: str, required: tuple[str, ...]) -> list[dict[str, Any]]:
    document = _json(files, name)
    if not isinstance(document, dict):
        raise ExportProblem(name, 'must be a JSON object with a "metrics" list')
    entries = document.get("metrics")
    if not isinstance(entries, list) or not entries:
        raise ExportProblem(name, "missing or empty (no episodes recorded)", field="metrics")
    if len(entries) > 100_000:
        raise ExportProblem(name, "holds too many entries", field="metrics")
    for index, entry in enumerate(entries):
        if not isinstance(entry, dict):
            raise ExportProblem(name, "must be an object", field=f"metrics[{index}]")
        for key in required:
            _number(name, entry, key, index)
    return entries


# -- drem's own sim runs -----------------------------------------------------------------------------------------------

def _drem_parts(files: ExportFiles, track: str) -> dict[str, Any]:
    lineage_name = "training/lineage.json" if "training/lineage.json" in files else "lineage.json"
    lineage = _json(files, lineage_name)
    if not isinstance(lineage, dict):
        raise ExportProblem(lineage_name, "must hold a JSON object")
    hyper_keys = ("batch_size", "learning_rate", "epochs_requested", "epochs_run", "seed", "augment", "network",
                  "parameters", "train_frames", "validation_frames")
    hyperparameters = {k: lineage[k] for k in hyper_keys if isinstance(lineage.get(k), str | int | float | bool)}
    if "epochs_run" not in hyperparameters:
        raise ExportProblem(lineage_name, "missing (how many epochs were trained)", field="epochs_run")
    runs = ((lineage.get("dataset") or {}).get("runs") or []) if isinstance(lineage.get("dataset"), dict) else []
    tracks = sorted({str(r.get("track_id") or r.get("track")) for r in runs
                     if isinstance(r, dict) and (r.get("track_id") or r.get("track"))})
    metrics = _json(files, "metrics.json")
    if not isinstance(metrics, dict):
        raise ExportProblem("metrics.json", "must hold a JSON object (drem sim eval --out)")
    if metrics.get("track") != track:
        raise ExportProblem("metrics.json", f"the evaluation ran on {metrics.get('track')!r}, not on {track!r}",
                            field="track")
    progress = metrics.get("attempt_progress")
    laps = metrics.get("lap_times_s")
    if not isinstance(progress, list) or not progress:
        raise ExportProblem("metrics.json", "missing or empty", field="attempt_progress")
    if not isinstance(laps, list):
        raise ExportProblem("metrics.json", "missing", field="lap_times_s")
    lap_times = iter(laps)
    trials = []
    for index, value in enumerate(progress):
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise ExportProblem("metrics.json", "must be a number", field=f"attempt_progress[{index}]")
        completed = value >= 100.0
        time_s = next(lap_times, None) if completed else 0.0
        if not isinstance(time_s, int | float):
            raise ExportProblem("metrics.json", "has fewer lap times than completed attempts", field="lap_times_s")
        trials.append(EvaluationTrial(trial=index + 1, time_s=round(float(time_s), 3),
                                      completion_pct=min(float(value), 100.0), off_track_count=0 if completed else 1,
                                      status="Lap complete" if completed else "Off track"))
    return dict(hyperparameters=hyperparameters, training_track="+".join(tracks)[:64] or None,
                training_episodes=int(hyperparameters["epochs_run"]), training_best_completion_pct=None,
                trials=trials)


# -- small readers -----------------------------------------------------------------------------------------------------

def _json(files: ExportFiles, name: str) -> Any:
    if name not in files:
        raise ExportProblem(name, "missing")
    try:
        return json.loads(files.read(name).decode("utf-8-sig"), parse_constant=_no_constant)
    except UnicodeDecodeError:
        raise ExportProblem(name, "is not UTF-8 text") from None
    except json.JSONDecodeError as error:
        raise ExportProblem(name, f"is not valid JSON ({error.msg} at line {error.lineno} column {error.colno})") \
            from None
    except (ValueError, RecursionError) as error:
        raise ExportProblem(name, f"is not valid JSON ({error})") from None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a number JSON allows")


def _number(file: str, entry: dict[str, Any], key: str, index: int) -> float:
    value = entry.get(key)
    if not isinstance(value, int | float) or isinstance(value, bool) or value < 0:
        problem = "missing" if key not in entry else f"must be a number >= 0, got {str(value)[:30]!r}"
        raise ExportProblem(file, problem, field=f"metrics[{index}].{key}")
    return float(value)


def _int(file: str, entry: dict[str, Any], key: str, index: int, *, default: int) -> int:
    if key not in entry:
        return default
    return int(_number(file, entry, key, index))


def _first(files: ExportFiles, exact: list[str], *, suffix: str, what: str) -> str:
    for name in exact:
        if name in files:
            return name
    candidates = sorted((n for n in files.files if n.endswith(suffix)), key=lambda n: (n.count("/"), n))
    if candidates:
        return candidates[0]
    raise ExportProblem(exact[0], f"missing: the export has no {what}")


def _matching(files: ExportFiles, pattern: str) -> str | None:
    found = sorted(n for n in files.files if re.search(pattern, n))
    return found[-1] if found else None


def _newest(files: ExportFiles, pattern: str, what: str) -> str:
    found = _matching(files, pattern)
    if found is None:
        raise ExportProblem(what.split(" (")[1].rstrip(")").split(" or ")[0], f"missing: the export has no {what}")
    return found


def _num(value: float) -> str:
    return f"{value:g}"
