"""The model registry: every model version (uploaded, or trained here), its lineage, its evaluations per track over
time and its scrutineering verdict, with plots people would rather look at than read.

Evaluations are what `drem sim eval --out DIR` writes (`metrics.json`), posted as-is by the owner or model staff;
best and mean lap are recomputed from the lap times. Lineage is read from the archive's `training/lineage.json`
(written by drem's packager) when the model has one; uploaded console models simply have none.
"""
from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import DremError, InvalidInput
from chalicelib.core.principals import Principal
from chalicelib.domain.league import TRACK_PATTERN
from chalicelib.domain.racer_models import ModelRecord, ModelService, ModelStatus, utc_now
from chalicelib.formats.league_export import ExportLimits, read_tar_gz

LINEAGE_MEMBER = "training/lineage.json"
_LINEAGE_LIMITS = ExportLimits(max_file_bytes=2 * 1024 * 1024, max_total_read_bytes=2 * 1024 * 1024)
_LISTED = 100


class EvaluationInput(BaseModel):
    """A `metrics.json` from `drem sim eval` (other keys it holds are ignored)."""
    model_config = ConfigDict(extra="ignore")
    track: str = Field(pattern=TRACK_PATTERN)
    attempts: int = Field(ge=1, le=10_000)
    laps_completed: int = Field(ge=0, le=10_000)
    completion_pct: float = Field(ge=0, le=100, allow_inf_nan=False)
    offtrack_count: int = Field(ge=0, le=100_000)
    lap_times_s: list[float] = Field(default_factory=list, max_length=10_000)
    steering_jitter_deg: float | None = Field(default=None, ge=0, le=360, allow_inf_nan=False,
                                              description="stability: mean steering change per step")
    source: str = Field(default="sim", max_length=20, pattern=r"^[a-z0-9_-]+$")


class Evaluation(BaseModel):
    model_config = ConfigDict(frozen=True)
    model_id: str
    track: str
    recorded_at: str
    recorded_by: str
    source: str
    attempts: int
    laps_completed: int
    completion_pct: float
    offtrack_count: int
    best_lap_s: float | None
    mean_lap_s: float | None
    steering_jitter_deg: float | None


class EvaluationStore(Protocol):
    def add(self, owner_sub: str, evaluation: Evaluation) -> None: ...
    def for_owner(self, owner_sub: str) -> list[Evaluation]: ...


@dataclass(frozen=True)
class RegistryRow:
    model: ModelRecord
    latest: list[Evaluation]  # newest evaluation per track
    verdict: str


@dataclass(frozen=True)
class Curve:
    """One line of a chart: (x index into the chart's x labels, value) per point."""
    label: str
    points: list[tuple[int, float]]


@dataclass(frozen=True)
class RegistryView:
    """The registry's rows and the figures its charts show (chalicelib.views.registry_views draws them)."""
    everyone: bool
    rows: list[RegistryRow]
    detail_base: str
    version_labels: list[str] = field(default_factory=list)  # the x axis: model versions in upload order
    lap_curves: list[Curve] = field(default_factory=list)  # best lap (s) per track over versions
    completion_curves: list[Curve] = field(default_factory=list)  # completion (%) per track over versions
    track_bests: list[tuple[str, float]] = field(default_factory=list)  # best lap (s) per track, all versions


@dataclass(frozen=True)
class ModelDetail:
    model: ModelRecord
    verdict: str
    evaluations: list[Evaluation]
    lineage: list[tuple[str, str]]
    dataset_runs: list[str]
    loss_curves: list[Curve]  # train and validation loss per epoch (empty without a lineage)
    lineage_note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


LineageReader = Callable[[ModelRecord], dict[str, Any] | None]


class RegistryService:
    def __init__(self, models: ModelService, evaluations: EvaluationStore, lineage: LineageReader, *,
                 clock: Callable[[], str] = utc_now) -> None:
        self.models = models
        self.evaluations = evaluations
        self.lineage = lineage
        self._clock = clock

    def record(self, principal: Principal, model_id: str, body: EvaluationInput) -> Evaluation:
        model = self.models.get(principal, model_id)  # 404 unknown/deleted, 403 another racer's model
        if body.laps_completed > body.attempts or len(body.lap_times_s) != body.laps_completed:
            raise InvalidInput("lap_times_s must hold one time per completed lap (laps_completed ≤ attempts).",
                               field="lap_times_s")
        laps = body.lap_times_s
        if any(t <= 0 or t != t for t in laps):
            raise InvalidInput("lap times must be positive numbers of seconds.", field="lap_times_s")
        evaluation = Evaluation(
            model_id=model.model_id, track=body.track, recorded_at=self._clock(),
            recorded_by=getattr(principal, "username", "") or "", source=body.source, attempts=body.attempts,
            laps_completed=body.laps_completed, completion_pct=round(body.completion_pct, 2),
            offtrack_count=body.offtrack_count, best_lap_s=round(min(laps), 3) if laps else None,
            mean_lap_s=round(sum(laps) / len(laps), 3) if laps else None,
            steering_jitter_deg=body.steering_jitter_deg)
        self.evaluations.add(model.owner_sub, evaluation)
        return evaluation

    def for_model(self, principal: Principal, model_id: str) -> list[Evaluation]:
        model = self.models.get(principal, model_id)
        return [e for e in self.evaluations.for_owner(model.owner_sub) if e.model_id == model.model_id]

    def registry(self, principal: Principal, *, everyone: bool) -> RegistryView:
        if everyone:
            models = self.models.store.list_all(limit=_LISTED, next_token=None).models
        else:
            models = self.models.store.list_owner(_sub(principal), limit=_LISTED, next_token=None).models
        models = sorted((m for m in models if m.status is not ModelStatus.DELETED), key=lambda m: m.uploaded_at)
        evaluations: list[Evaluation] = []
        for owner in sorted({m.owner_sub for m in models}):
            evaluations.extend(self.evaluations.for_owner(owner))
        known = {m.model_id for m in models}
        evaluations = [e for e in evaluations if e.model_id in known]
        rows = [RegistryRow(m, _latest_per_track([e for e in evaluations if e.model_id == m.model_id]), verdict(m))
                for m in reversed(models)]
        return RegistryView(everyone=everyone, rows=rows, detail_base="/models/registry",
                            **_figures(models, evaluations))

    def detail(self, principal: Principal, model_id: str) -> ModelDetail:
        model = self.models.get(principal, model_id)
        evaluations = sorted(self.for_model(principal, model_id), key=lambda e: e.recorded_at, reverse=True)
        note = ""
        try:
            lineage = self.lineage(model) if model.status is ModelStatus.AVAILABLE else None
        except DremError as error:  # a damaged lineage file must not hide the rest of the dashboard
            lineage, note = None, f"training/lineage.json could not be read: {error.message}"
        if lineage is None:
            return ModelDetail(model, verdict(model), evaluations, [], [], [],
                               note or "No training lineage: this model was not trained by drem.")
        shown: list[tuple[str, str]] = [
            (key, str(lineage[key])) for key in ("network", "parameters", "seed", "epochs_run", "batch_size",
                                                 "learning_rate", "augment", "train_frames", "validation_frames",
                                                 "train_seconds") if key in lineage]
        shown += _training_recipe(lineage)
        dataset: Any = lineage.get("dataset") if isinstance(lineage.get("dataset"), dict) else {}
        runs = [str(r.get("run_id") or r.get("run")) + (f" ({r.get('track_id') or r.get('track')})"
                                                        if r.get("track_id") or r.get("track") else "")
                for r in (dataset.get("runs") or []) if isinstance(r, dict)][:50]
        curves = [Curve(label, list(enumerate(_floats(lineage.get(key)))))
                  for label, key in (("train", "train_losses"), ("validation", "validation_losses"))]
        return ModelDetail(model, verdict(model), evaluations, shown, runs, curves)


def _training_recipe(lineage: dict[str, Any]) -> list[tuple[str, str]]:
    """Augmentation and the DAgger block of a drem-trained model's lineage (archive content: shapes checked,
    lengths bounded; the template escapes)."""
    rows: list[tuple[str, str]] = []
    augmentation = lineage.get("augmentation")
    if isinstance(augmentation, dict) and isinstance(augmentation.get("names"), list):
        rows.append(("augmentation", ", ".join(str(n) for n in augmentation["names"][:10]) or "none"))
    dagger = lineage.get("dagger")
    if not isinstance(dagger, dict):
        return rows
    rows.append(("DAgger round", f"{dagger.get('round')} of {dagger.get('rounds')}"))
    for label, key in (("trained on", "train_tracks"), ("held out", "held_out_tracks")):
        tracks = dagger.get(key)
        if isinstance(tracks, list):
            rows.append((label, ", ".join(str(t) for t in tracks[:40])[:600] or "-"))
    for earlier in (dagger.get("previous_rounds") or [])[:20]:
        if not isinstance(earlier, dict):
            continue
        results = [f"{e.get('track')} {e.get('laps_completed')}/{e.get('attempts')}"
                   for e in (earlier.get("evaluation") or [])[:20] if isinstance(e, dict)]
        rows.append((f"round {earlier.get('round')} held-out laps", ", ".join(results)[:600] or "-"))
    return rows


def verdict(model: ModelRecord) -> str:
    """The scrutineering result in words."""
    if model.status is ModelStatus.AVAILABLE:
        text = f"passed ({model.model_kind or 'model'})"
        if model.scrutineer_result is not None:
            return f"{text}; simulator drive: {model.scrutineer_result.verdict}, {model.scrutineer_result.message}"
        if model.scrutiny == "cannot_scrutineer":
            return f"{text}; {model.scrutiny_text}"
        return text
    if model.status is ModelStatus.UPLOADED:
        return "waiting for the upload"
    detail = f" ({model.scrutiny_detail})" if model.scrutiny_detail else ""  # staff see the converter's own words
    return f"{model.status.value.lower().replace('_', ' ')}: {model.reason or 'no reason given'}{detail}"


def lineage_from_archive(models: ModelService, limit: int) -> LineageReader:
    """Read `training/lineage.json` from a validated archive, in memory and bounded (never extracted)."""
    def read(model: ModelRecord) -> dict[str, Any] | None:
        if model.s3_key is None:
            return None
        download = models.files.download_bounded(model.s3_key, limit=limit)
        if download is None or download.too_large:
            return None
        with download.body:
            files, _ = read_tar_gz(download.body, limits=_LINEAGE_LIMITS, wanted=lambda n: n == LINEAGE_MEMBER)
        if LINEAGE_MEMBER not in files:
            return None
        try:
            document = json.loads(files[LINEAGE_MEMBER])
        except ValueError:
            raise InvalidInput("it is not valid JSON", field=LINEAGE_MEMBER) from None
        except RecursionError:  # json recurses once per nesting level: `[[[[...` thousands deep blows the stack
            raise InvalidInput("it is nested too deeply", field=LINEAGE_MEMBER) from None
        return document if isinstance(document, dict) else None
    return read


def _latest_per_track(evaluations: list[Evaluation]) -> list[Evaluation]:
    latest: dict[str, Evaluation] = {}
    for evaluation in sorted(evaluations, key=lambda e: e.recorded_at):
        latest[evaluation.track] = evaluation
    return [latest[track] for track in sorted(latest)]


def _figures(models: list[ModelRecord], evaluations: list[Evaluation]) -> dict[str, Any]:
    """Lap time and completion over model versions (one curve per track), and the best lap per track."""
    versions = [m for m in models if any(e.model_id == m.model_id for e in evaluations)]
    tracks = sorted({e.track for e in evaluations})
    lap_curves, completion_curves = [], []
    for track in tracks:
        laps, completion = [], []
        for index, model in enumerate(versions):
            mine = _latest_per_track([e for e in evaluations if e.model_id == model.model_id and e.track == track])
            if mine:
                completion.append((index, mine[0].completion_pct))
                if mine[0].best_lap_s is not None:
                    laps.append((index, mine[0].best_lap_s))
        lap_curves.append(Curve(track, laps))
        completion_curves.append(Curve(track, completion))
    bests: list[tuple[str, float]] = []
    for track in tracks:
        on_track = [e for e in evaluations if e.track == track and e.best_lap_s is not None]
        if on_track:
            bests.append((track, min(e.best_lap_s for e in on_track)))  # type: ignore[type-var, arg-type]  # none is None
    return {"version_labels": [m.name for m in versions], "lap_curves": lap_curves,
            "completion_curves": completion_curves, "track_bests": bests}


def _floats(values: Any) -> list[float]:
    if not isinstance(values, list):
        return []
    return [float(v) for v in values[:2000] if isinstance(v, int | float) and not isinstance(v, bool) and v == v]


def _sub(principal: Principal) -> str:
    if not principal.is_user or not principal.sub:
        raise InvalidInput("Only signed-in users own models.")
    return principal.sub
