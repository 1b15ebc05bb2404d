"""What the learning booth's pages show: the racer's runs, jobs, model versions and the tracks to drive."""
from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from markupsafe import Markup

from chalicelib.core.errors import DremError
from chalicelib.core.principals import Principal
from chalicelib.domain.booth_runs import ListRunsQuery, RunRecord, RunService
from chalicelib.domain.booth_tracks import TrackInfo, TrackService
from chalicelib.domain.booth_training import DEFAULT_EPOCHS, MAX_EPOCHS, VERSION_NAME, JobView, TrainingService
from chalicelib.domain.devices import DeviceKind, DeviceService, DeviceView
from chalicelib.domain.racer_models import MODEL_STAFF, ModelRecord, ModelStatus
from chalicelib.views import svg_plots
from chalicelib.views.racer_names import ProfilesBySub, shown_racer_names
from chalicelib.views.track_map import track_map

PLOT_POINTS = 60  # a run's controls, thinned: the shape of the drive, not every decision
EPOCHS_RANGE = f"Epochs are a whole number from 1 to {MAX_EPOCHS}."


@dataclass(frozen=True)
class TrainAction:
    """The Train button for the epochs in the field, and why it is off (shown beside it); None: it is on."""
    drives: int  # the finished manual runs a job would learn from (the newest 50)
    epochs: str  # as the field holds it
    why_not: str | None


def train_action(principal: Principal, training: TrainingService, epochs: str = str(DEFAULT_EPOCHS)) -> TrainAction:
    """Asked again as the epochs change and as a job ends, so the button says what pressing it would do now."""
    drives = training.drives_to_train(principal)
    number = int(epochs) if re.fullmatch(r"[0-9]{1,3}", epochs.strip()) else 0
    why_not = training.why_not_train(principal, epochs=number, drives=drives) if 1 <= number <= MAX_EPOCHS else \
        EPOCHS_RANGE
    return TrainAction(drives=len(drives), epochs=epochs.strip()[:3], why_not=why_not)


@dataclass(frozen=True)
class BoothView:
    everyone: bool
    tracks: list[TrackInfo]
    runs: list[RunRecord]
    jobs: list[JobView]
    versions: list[ModelRecord]
    active_model_id: str | None
    aggregates: list[dict[str, Any]]
    train: TrainAction  # the Train button, off with its reason when pressing it could only fail
    active_versions: list[tuple[str, ModelRecord]]  # staff: each driver's active version, to send to a car
    cars: list[DeviceView]  # staff: the cars an active version can be sent to
    racer_names: dict[str, str]  # staff: {sub: display name, told apart among the racers the page lists}
    job_names: dict[str, str]  # staff: the same for the racers of the jobs list (which its poll renders alone)


def booth_view(principal: Principal, runs: RunService, training: TrainingService, tracks: TrackService,
               devices: DeviceService, profiles: ProfilesBySub, *, everyone: bool) -> BoothView:
    everyone = everyone and bool(principal.roles & MODEL_STAFF)
    query = ListRunsQuery(everyone=everyone)
    mine = runs.list_runs(principal, query)
    owner = principal.sub or ""
    jobs = jobs_view(principal, training, everyone=everyone)
    return BoothView(everyone=everyone, tracks=tracks.all_tracks(), runs=mine, jobs=jobs,
                     versions=my_versions(principal, training),
                     active_model_id=training.active_of(owner), aggregates=runs.aggregates(principal, query),
                     train=train_action(principal, training),
                     active_versions=_active_versions(training, mine) if everyone else [],
                     cars=[d for d in devices.list_devices() if d.kind is DeviceKind.CAR] if everyone else [],
                     racer_names=shown_racer_names({(r.owner_sub, r.owner_username) for r in mine}, profiles)
                     if everyone else {},
                     job_names=job_racer_names(jobs, profiles) if everyone else {})


def my_versions(principal: Principal, training: TrainingService) -> list[ModelRecord]:
    """The caller's trained versions (v0001 …), newest first."""
    models = training.models.store.list_owner(principal.sub or "", limit=100, next_token=None).models
    return sorted((m for m in models if VERSION_NAME.match(m.name) and m.status is not ModelStatus.DELETED),
                  key=lambda m: m.name, reverse=True)


def versions_when_idle(principal: Principal, training: TrainingService, jobs: list[JobView]) -> dict[str, Any]:
    """For the jobs answer: the versions once no listed job waits or runs (the answer that sees the last one end,
    after which the list stops polling), so a new version shows without a reload; nothing while one is busy."""
    if any(view.job.status.value in ("QUEUED", "RUNNING") for view in jobs):
        return {}
    return {"versions": my_versions(principal, training), "active_model_id": training.active_of(principal.sub or "")}


def _active_versions(training: TrainingService, runs: list[RunRecord]) -> list[tuple[str, ModelRecord]]:
    found = []
    for sub, username in sorted({(r.owner_sub, r.owner_username) for r in runs}, key=lambda o: o[1]):
        model_id = training.active_of(sub)
        model = training.models.store.get(sub, model_id) if model_id else None
        if model is not None and model.status is ModelStatus.AVAILABLE:
            found.append((username, model))
    return found


def jobs_view(principal: Principal, training: TrainingService, *, everyone: bool = False) -> list[JobView]:
    return training.list_jobs(principal, everyone=everyone)[:20]


def job_racer_names(jobs: list[JobView], profiles: ProfilesBySub) -> dict[str, str]:
    """Staff's jobs list names each job's racer by display name, told apart among the jobs listed: the same on the
    booth page and in the fragment it polls every second, as both list the same jobs."""
    return shown_racer_names({(v.job.owner_sub, v.job.owner_username) for v in jobs}, profiles)


def racer_name(owner_sub: str, owner_username: str, profiles: ProfilesBySub) -> str:
    """How a page about one racer's run or model names that racer: the display name (no one to tell apart from)."""
    return shown_racer_names([(owner_sub, owner_username)], profiles)[owner_sub]


@dataclass(frozen=True)
class RunInspection:
    run: RunRecord
    steering_plot: Markup
    speed_plot: Markup
    speed_measured: bool  # the rows carry the car's own speed (a person's drive); else only the speed commanded


def run_inspection(run: RunRecord, rows: list[dict[str, Any]]) -> RunInspection:
    """The run with its controls over time: steering (+ = left) and the car's speed (the speed commanded, and named
    so, where the run did not record the car's own), off-track moments marked. A long
    run is drawn in buckets of frames, each by its lowest and highest value in the order they came, so a burst of
    full-lock frames between two samples still shows."""
    size = max(1, -(-len(rows) // PLOT_POINTS))
    buckets = [rows[start:start + size] for start in range(0, len(rows), size)]
    decimals = 0 if rows and rows[-1]["t_ms"] - rows[0]["t_ms"] > 20_000 else 1  # a short run's labels must differ too
    labels = [f"{bucket[0]['t_ms'] / 1000:.{decimals}f}s" if index % 10 == 0 else ""
              for index, bucket in enumerate(buckets)]
    steering = svg_plots.Series("steering °", _extremes(buckets, lambda r: r["steering_angle"]))
    measured = bool(rows) and all("car_speed" in row for row in rows)
    speed_name = "car's speed" if measured else "speed commanded"
    speed = svg_plots.Series(f"{speed_name} m/s", _extremes(buckets, _car_speed))
    off = svg_plots.Series("off track", [(i, max(_car_speed(r) for r in bucket)) for i, bucket in enumerate(buckets)
                                         if any(r["offtrack"] for r in bucket)])
    return RunInspection(
        run=run, speed_measured=measured,
        steering_plot=svg_plots.line_chart([steering], labels, title="Steering over the run", y_label="degrees",
                                           testid="plot-steering"),
        speed_plot=svg_plots.line_chart([s for s in (speed, off) if s.points], labels,
                                        title=f"The {speed_name} over the run", y_label="m/s", testid="plot-speed"))


def _car_speed(row: dict[str, Any]) -> float:
    """What the car really did (a person's drive records it), else the speed commanded."""
    return float(row.get("car_speed", row["speed"]))


def _extremes(buckets: list[list[dict[str, Any]]], value: Callable[[dict[str, Any]], float]) -> list[tuple[int, float]]:
    points: list[tuple[int, float]] = []
    for index, bucket in enumerate(buckets):
        values = [value(row) for row in bucket]
        low, high = values.index(min(values)), values.index(max(values))
        points += [(index, values[i]) for i in sorted({low, high})]
    return points


def run_map(tracks: TrackService, run: RunRecord, rows: list[dict[str, Any]]) -> Markup | None:
    """The saved run on its track, seen from above (None where the simulator's tracks are not installed)."""
    try:
        track = tracks.get(run.track_id)
    except DremError:
        return None
    return track_map(track, rows, testid="run-map")
