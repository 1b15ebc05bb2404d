"""Build one league submission from a model export in any of the real layouts (pure: no AWS, no disk writes).

Five inputs, found by where each layout puts them (deepracer-formats.md §5):

| input               | old/new console export (DROA)           | DeepRacer-for-Cloud prefix        | drem sim run            |
|---------------------|-----------------------------------------|-----------------------------------|-------------------------|
| model metadata      | model/model_metadata.json               | model/model_metadata.json         | model_metadata.json     |
| hyperparameters     | ip/hyperparameters.json                 | ip/hyperparameters.json           | lineage.json            |
| training params     | training_params.yaml, else the training log's WORLD_NAME, else none (shown only) | training_params.yaml, else none | lineage.json (dataset) |
| training metrics    | metrics/training/**.json                | metrics/TrainingMetrics.json      | lineage.json (losses)   |
| evaluation metrics  | metrics/evaluation/**.json (newest)     | metrics/EvaluationMetrics-*.json (newest) | metrics.json   |

Every problem raises `ExportProblem` naming the file and the field ("ip/hyperparameters.json: missing"), so the racer
knows what to fix; nothing is built from a half-read export.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import re
from typing import Any

import yaml

from chalicelib.core.errors import InvalidInput
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
_SIMTRACE = re.compile(r"(^|/)evaluation-simtrace/[^/]+\.csv$")
# A lap's time in the metrics and the span of its episode in the sim-trace are the same clock (simapp
# metrics/s3_metrics.py: elapsed = metric_time - start_time, both sim time; the sim-trace's tstamp is sim time too):
# they differ by a step or two (15 Hz) and the reset, never by more than this.
SIMTRACE_TIME_SLACK_S = 0.5
TRACK_LENGTH_TOLERANCE = 0.01  # sim-trace track_len vs drem's length of the track: 1 %

# Where each tool writes the file that is missing, so a racer knows what to add (deepracer-formats.md §1.2, §5.1).
MISSING_METADATA = ("missing: the export has no model metadata. The console's model download (“Download model”, a "
                    ".tar.gz) holds model_metadata.json at its root; DeepRacer-for-Cloud writes it to the model "
                    "prefix as model/model_metadata.json; DROA's car archives hold it at their root. Push it with the "
                    "logs: drem league push LOGS MODEL.tar.gz")
MISSING_HYPERPARAMETERS = ("missing: the export has no hyperparameters. The console's logs download holds "
                           "ip/hyperparameters.json; DeepRacer-for-Cloud writes it to the model prefix as "
                           "ip/hyperparameters.json")
MISSING_TRAINING_METRICS = ("missing: the export has no training metrics. The console's logs download holds "
                            "metrics/training/*.json; DeepRacer-for-Cloud writes metrics/TrainingMetrics.json "
                            "(TrainingMetrics_1.json, … for more workers) in the model prefix")
MISSING_EVALUATION_METRICS = ("missing: the export has no evaluation. The console's logs download of an evaluated "
                              "model holds metrics/evaluation/*.json; DeepRacer-for-Cloud's dr-start-evaluation "
                              "writes metrics/EvaluationMetrics-<time>.json in the model prefix; drem writes "
                              "metrics.json with `drem sim eval --out DIR`")
MISSING_TRACK_EVIDENCE = ("nothing in the export says which track the evaluation ran on. Push the evaluation's log "
                          "(console: logs/evaluation/*-robomaker.log or logs/leaderboard/*; DROA: "
                          "logs/evaluation/*-simulation.log) or DeepRacer-for-Cloud's evaluation sim-trace "
                          "(evaluation-<time>/evaluation-simtrace/0-iteration.csv) or evaluation_params.yaml")
MISSING_LINEAGE = "missing: drem writes training/lineage.json into every model archive it trains (drem sim train)"


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


def assemble(files: ExportFiles, *, racer: str, track: str, track_length_m: float,
             model_name: str | None = None) -> SubmissionInput:
    """One submission from the export; `track_length_m` is the centre-line length drem knows for `track`, which the
    export's own evidence (sim-trace `track_len`) must agree with."""
    layout = detect_layout(files)
    metadata_file = _first(files, ["model/model_metadata.json", "model_metadata.json", "agent/model_metadata.json"],
                           suffix="/model_metadata.json", missing=MISSING_METADATA)
    metadata = _metadata(files, metadata_file)
    if layout == LAYOUT_DREM:
        parts = _drem_parts(files, track)
    else:
        parts = _deepracer_parts(files, track, track_length_m)
    name = model_name or _MODEL_NAME_UNSAFE.sub("-", files.source_name).strip("-.") or "model"
    try:
        return SubmissionInput(racer=racer, track=track, model_name=name[:80], layout=layout,
                               sensor=list(metadata.sensor), algorithm=metadata.training_origin,
                               action_space_type=metadata.action_space_type.value,
                               action_space=action_space_summary(metadata), top_speed_m_s=top_speed(metadata),
                               **parts)
    except ValueError as error:  # pydantic: a value out of range (e.g. a negative lap time)
        raise InvalidInput(f"the export gives a value the league cannot accept: {error}") from None


def top_speed(metadata: ModelMetadata) -> float:
    """The fastest the action space lets the car go (m/s): no lap is quicker than the track at this speed."""
    space = metadata.action_space
    if isinstance(space, list):
        return max(action.speed for action in space)
    return space.speed.high


def evidence_digest(entries: list[dict[str, Any]]) -> str:
    """The fingerprint of an evaluation's laps: the same log content pushed again (by another racer, or with its
    file renamed or re-indented) has the same digest."""
    canonical = json.dumps(entries, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    return hashlib.sha256(canonical.encode()).hexdigest()


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

def _deepracer_parts(files: ExportFiles, track: str, track_length_m: float) -> dict[str, Any]:
    hyper_file = _first(files, ["ip/hyperparameters.json", "hyperparameters.json"], suffix="/hyperparameters.json",
                        missing=MISSING_HYPERPARAMETERS)
    hyperparameters = _hyperparameters(files, hyper_file)
    training_track = _training_world(files)
    training: list[tuple[str, dict[str, Any]]] = []
    for training_file in _training_metric_files(files):
        episodes = _metric_entries(files, training_file, ("completion_percentage",))
        in_training = [e for e in episodes if e.get("phase", "training") == "training"] or episodes
        training += [(training_file, e) for e in in_training]
    evaluation_file = _newest(files, r"(^|/)metrics/EvaluationMetrics[^/]*\.json$|(^|/)metrics/evaluation/.+\.json$",
                              "metrics/evaluation/*.json", MISSING_EVALUATION_METRICS)
    entries = _metric_entries(files, evaluation_file, ("completion_percentage", "elapsed_time_in_milliseconds"))
    named = _check_evaluation_world(files, track, evaluation_file)
    traced = _check_simtraces(files, track, track_length_m, evaluation_file, entries)
    if not (named or traced):
        raise ExportProblem(evaluation_file, MISSING_TRACK_EVIDENCE)
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
                training_best_completion_pct=min(best, 100.0), trials=trials, evidence_digest=evidence_digest(entries))


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
    return [_newest(files, r"(^|/)metrics/training/.+\.json$", "metrics/training/*.json", MISSING_TRAINING_METRICS)]


def _training_world(files: ExportFiles) -> str | None:
    """The track the model trained on, from the training params or the training log (console and DROA exports have
    no params file: their simulation logs print the world name); None when the export has neither (DRfC's model
    prefix holds no params file): it is shown, never ranked."""
    yaml_name = _matching(files, r"(^|/)training[-_]params\.ya?ml$")
    if yaml_name:
        return _world_name(files, yaml_name)
    log_name = _matching(files, r"(^|/)logs/training/[^/]*-(robomaker|simulation)\.log$")
    if log_name:
        world = _world_in_log(files, log_name)
        if world is None:
            raise ExportProblem(log_name, "the training log does not say which track (no WORLD_NAME)")
        return world
    return None


def _world_in_log(files: ExportFiles, name: str) -> str | None:
    found = _WORLD_IN_LOG.search(files.read(name).decode("utf-8", "replace"))
    return found.group(1) if found else None


def _check_evaluation_world(files: ExportFiles, track: str, evaluation_file: str) -> bool:
    """Every place the export names the track of the evaluation whose laps are submitted must say `track`: the
    evaluation params YAML (DRfC) and the evaluation's own simulation log (console: logs/evaluation or
    logs/leaderboard; DROA: logs/evaluation/*-simulation.log). Real console/DROA exports have no params YAML, so the
    log is what tells. The log of that evaluation is the one that mentions its metrics file's job name; when no log
    does, every evaluation log in the export must name `track` (an export cannot hide a foreign evaluation)."""
    named = False
    yaml_name = _matching(files, r"(^|/)eval(uation)?[-_]params\.ya?ml$")
    if yaml_name:
        world = _world_name(files, yaml_name)
        if world != track:
            raise ExportProblem(yaml_name, f"the evaluation ran on {world!r}, not on {track!r}", field="WORLD_NAME")
        named = True
    logs = sorted(n for n in files.files if _EVALUATION_LOG.search(n))
    job = _ISO_PREFIX.sub("", evaluation_file.rsplit("/", 1)[-1].removesuffix(".json"))
    texts = {name: files.read(name).decode("utf-8", "replace") for name in logs}
    own = [name for name, text in texts.items() if len(job) >= 8 and job in text]
    for name in own or logs:
        found = _WORLD_IN_LOG.search(texts[name])
        if found and found.group(1) != track:
            raise ExportProblem(name, f"the evaluation ran on {found.group(1)!r}, not on {track!r}",
                                field="WORLD_NAME")
        named = named or found is not None
    return named


def _evaluation_job(evaluation_file: str) -> str:
    """What ties a metrics file to its sim-trace folder: DRfC `EvaluationMetrics-20220709200242.json` ↔
    `evaluation-20220709200242/`; console `evaluation-20201021101010-Xy….json` ↔ `sim-trace/evaluation/
    20201021101010-Xy…/`; a generically named file (`evaluation-metrics.json`) ↔ the name of its own folder."""
    folder, _, stem = evaluation_file.rpartition("/")
    stem = stem.removesuffix(".json").removeprefix("EvaluationMetrics-").removeprefix("evaluation-")
    return folder.rsplit("/", 1)[-1] if stem in ("metrics", "evaluation") else stem


def _check_simtraces(files: ExportFiles, track: str, track_length_m: float, evaluation_file: str,
                     entries: list[dict[str, Any]]) -> bool:
    """DeepRacer writes every step of an evaluation to its sim-trace, with the track's centre-line length
    (`track_len`, simapp markov/metrics/s3_metrics.py). Every evaluation sim-trace must be of a track that long; the
    submitted evaluation's own sim-trace (its folder named after the metrics file's job) also bounds each lap: a lap
    claimed faster than its episode lasted in the sim-trace is an edited metrics file. When the export holds the
    submitted evaluation's own sim-trace, that one decides (older evaluations on other tracks are left alone); when it
    does not, every evaluation sim-trace must be of the track."""
    traces = sorted(n for n in files.files if _SIMTRACE.search(n))
    job = _evaluation_job(evaluation_file)
    own = [name for name in traces if len(job) >= 8 and _simtrace_job(name) in (job, f"evaluation-{job}")]
    for name in own or traces:  # a console export keeps every evaluation: the submitted one's own trace decides
        episodes = _simtrace_episodes(files, name)
        for episode in episodes.values():
            for length in episode.lengths:
                if abs(length - track_length_m) > TRACK_LENGTH_TOLERANCE * track_length_m:
                    raise ExportProblem(name, f"the evaluation ran on a track {length:.2f} m long; {track} is "
                                              f"{track_length_m:.2f} m", field="track_len")
        if name in own:
            _check_lap_times(name, episodes, evaluation_file, entries)
    return bool(traces)


def _simtrace_job(name: str) -> str:
    """The folder an evaluation sim-trace sits in: `evaluation-20220709200242` (DRfC), `20201021101010-Xy…`."""
    return name.split("/evaluation-simtrace/")[0].rsplit("/", 1)[-1]


class _Episode:
    def __init__(self) -> None:
        self.first_s = float("inf")
        self.last_s = float("-inf")
        self.lengths: set[float] = set()

    @property
    def span_s(self) -> float:
        return max(0.0, self.last_s - self.first_s)


def _simtrace_episodes(files: ExportFiles, name: str) -> dict[int, _Episode]:
    text = files.read(name).decode("utf-8", "replace")
    reader = csv.DictReader(io.StringIO(text))
    if not reader.fieldnames or not {"episode", "tstamp", "track_len"} <= set(reader.fieldnames):
        raise ExportProblem(name, "is not a DeepRacer sim-trace (no episode, tstamp and track_len columns)")
    episodes: dict[int, _Episode] = {}
    for line, row in enumerate(reader, start=2):
        try:
            episode = episodes.setdefault(int(float(row["episode"])), _Episode())
            stamp, length = float(row["tstamp"]), float(row["track_len"])
        except (TypeError, ValueError):
            raise ExportProblem(name, f"line {line} is not a sim-trace row (episode, tstamp, track_len must be "
                                      "numbers)") from None
        episode.first_s, episode.last_s = min(episode.first_s, stamp), max(episode.last_s, stamp)
        episode.lengths.add(round(length, 3))
    return episodes


def _check_lap_times(trace: str, episodes: dict[int, _Episode], evaluation_file: str,
                     entries: list[dict[str, Any]]) -> None:
    ordered = [episodes[key] for key in sorted(episodes)]
    for index, (entry, episode) in enumerate(zip(entries, ordered, strict=False)):
        claimed = _number(evaluation_file, entry, "elapsed_time_in_milliseconds", index) / 1000.0
        if claimed + SIMTRACE_TIME_SLACK_S < episode.span_s:
            raise ExportProblem(evaluation_file, f"claims {claimed:.3f} s, but its sim-trace ({trace}) shows the "
                                                 f"trial lasted {episode.span_s:.3f} s",
                                field=f"metrics[{index}].elapsed_time_in_milliseconds")


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
    if lineage_name not in files:
        raise ExportProblem(lineage_name, MISSING_LINEAGE)
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
                trials=trials, evidence_digest=evidence_digest([metrics]))


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


def _first(files: ExportFiles, exact: list[str], *, suffix: str, missing: str) -> str:
    for name in exact:
        if name in files:
            return name
    candidates = sorted((n for n in files.files if n.endswith(suffix)), key=lambda n: (n.count("/"), n))
    if candidates:
        return candidates[0]
    raise ExportProblem(exact[0], missing)


def _matching(files: ExportFiles, pattern: str) -> str | None:
    found = sorted(n for n in files.files if re.search(pattern, n))
    return found[-1] if found else None


def _newest(files: ExportFiles, pattern: str, shown: str, missing: str) -> str:
    found = _matching(files, pattern)
    if found is None:
        raise ExportProblem(shown, missing)
    return found


def _num(value: float) -> str:
    return f"{value:g}"
