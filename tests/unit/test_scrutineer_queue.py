"""Background scrutineering below the HTTP layer: the durable queue (idempotent enqueue, leases that expire when a
worker dies, a job that keeps killing its worker given up), and one worker step storing figures and the clip."""
from __future__ import annotations

from datetime import date
from pathlib import Path
from typing import Any

import pytest

from chalicelib import services
from chalicelib.core.errors import Forbidden, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.events import EventInput
from chalicelib.domain.model_scrutiny import BackgroundScrutineer, DriveOutcome, upcoming_track_types
from chalicelib.domain.racer_models import ModelRecord, ModelStatus, ScrutineerResult, UploadRequest
from chalicelib.domain.scrutineer_queue import MAX_ATTEMPTS
from tests.unit.models_helpers import onnx_archive
from tests.unit.race_helpers import FakeClock

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))
BOB = User(sub="sub-bob", username="bob", groups=frozenset({"racer"}))
OPERATOR = User(sub="sub-op", username="op", groups=frozenset({"operator"}))
GIF = b"GIF89a-a-clip"


def upload(stack: Any, aws_clients: Any, name: str = "queued.tar.gz", bias: float = 0.0) -> ModelRecord:
    service = services.model_service()
    ticket = service.request_upload(ALICE, UploadRequest(filename=name))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive(bias))
    return service.complete(ALICE, ticket.model.model_id)


def passed(track_type: str = "REINVENT_2018") -> ScrutineerResult:
    return ScrutineerResult(verdict="passed", message="2/2 laps completed on reinvent_base", track="reinvent_base",
                            track_type=track_type, laps=2, laps_completed=2, best_lap_time_s=9.13, offtrack_count=0)


class FakeDrive:
    """Stands in for the bounded simulator child (tested for real in the integration test): records its calls."""

    def __init__(self, outcome: DriveOutcome) -> None:
        self.outcome = outcome
        self.calls: list[tuple[list[str], set[str]]] = []

    def __call__(self, folder: Path, track_types: list[str], laps: int) -> DriveOutcome:
        self.calls.append((track_types, {p.name for p in folder.iterdir()}))
        return self.outcome


def worker(drive: Any) -> BackgroundScrutineer:
    return BackgroundScrutineer(services.scrutineer_service(), services.scrutineer_queue(), drive)


def test_an_uploaded_model_is_queued_once_on_the_upcoming_events_track(stack: Any, aws_clients: Any,
                                                                       clock: FakeClock) -> None:
    today = date.fromtimestamp(clock.now / 1000)
    services.event_service().create_event(OPERATOR, EventInput(
        name="Summit", event_type="AWS_SUMMIT", date=today, country_code="GB",
        race_config={"track_type": "SUMMIT_SPEEDWAY"}))
    model = upload(stack, aws_clients)

    assert model.status is ModelStatus.AVAILABLE and model.scrutineer_status == "queued"
    assert services.model_service().get(ALICE, model.model_id).public()["scrutineer_status"] == "queued"
    queue = services.scrutineer_queue()
    job = queue.state_of(model.model_id)
    assert job is not None and job.track_types == ["SUMMIT_SPEEDWAY"] and job.state == "queued"
    assert queue.enqueue(model.model_id, model.owner_sub, ["REINVENT_2018"]) is False  # idempotent
    assert len(queue.store.waiting(10)) == 1


def test_without_upcoming_events_the_default_track_is_driven() -> None:
    assert upcoming_track_types([], date(2026, 11, 24)) == ["REINVENT_2018"]


def test_a_lease_held_by_a_dead_worker_expires_and_the_job_is_driven_again(stack: Any, aws_clients: Any,
                                                                          clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    queue = services.scrutineer_queue()
    first = queue.take()
    assert first is not None and first.model_id == model.model_id and first.attempts == 1
    assert queue.take() is None, "a job being driven is not handed to a second worker"

    clock.advance(queue.lease_ms + 1)  # the first worker was kill -9'd: its lease runs out
    second = queue.take()
    assert second is not None and second.model_id == model.model_id and second.attempts == 2
    assert queue.finish(first) is False, "the dead worker's late finish must not remove the re-taken job"
    assert queue.finish(second) is True and queue.state_of(model.model_id) is None


def test_a_job_given_back_on_sigterm_is_taken_again_at_once(stack: Any, aws_clients: Any, clock: FakeClock) -> None:
    upload(stack, aws_clients)
    queue = services.scrutineer_queue()
    job = queue.take()
    assert job is not None and queue.give_back(job)
    again = queue.take()
    assert again is not None and again.model_id == job.model_id


def test_a_worker_step_stores_the_figures_and_the_clip_for_the_owner_only(stack: Any, aws_clients: Any,
                                                                         clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    drive = FakeDrive(DriveOutcome(reports=[passed()], clip=GIF))

    assert worker(drive).run_one() is not None
    assert drive.calls == [(["REINVENT_2018"], {"model.onnx", "model_metadata.json"})]
    stored = services.model_service().get(ALICE, model.model_id)
    assert stored.scrutineer_status == "passed" and stored.scrutineer_state is None
    assert stored.scrutineer_result is not None and stored.scrutineer_result.best_lap_time_s == 9.13
    shown = stored.public()
    assert shown["scrutineer_clip"] == f"/api/models/{model.model_id}/scrutineer/clip.gif"
    assert "scrutineer_clip_key" not in shown
    assert services.scrutineer_service().clip(ALICE, model.model_id) == GIF
    assert services.scrutineer_service().clip(OPERATOR, model.model_id) == GIF
    with pytest.raises(Forbidden):
        services.scrutineer_service().clip(BOB, model.model_id)
    assert services.scrutineer_queue().state_of(model.model_id) is None
    assert worker(drive).run_one() is None, "an empty queue drives nothing"


def test_a_drive_stopped_by_its_bounds_says_could_not_scrutineer_with_the_reason(stack: Any, aws_clients: Any,
                                                                                clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    worker(FakeDrive(DriveOutcome(failure="The test drive took longer than 90 s and was stopped.",
                                  failure_detail="wall-clock limit of 90 s reached"))).run_one()

    stored = services.model_service().get(ALICE, model.model_id)
    assert stored.scrutineer_status == "cannot_scrutineer"
    assert stored.scrutineer_status_reason == "The test drive took longer than 90 s and was stopped."
    assert "detail" not in stored.public()["scrutineer_result"], "the racer's API answer has no technical detail"
    assert stored.public(staff=True)["scrutineer_result"]["detail"] == "wall-clock limit of 90 s reached"
    with pytest.raises(NotFound):
        services.scrutineer_service().clip(ALICE, model.model_id)


def test_a_job_that_keeps_killing_its_worker_is_given_up(stack: Any, aws_clients: Any, clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    queue = services.scrutineer_queue()
    for _ in range(MAX_ATTEMPTS):  # each worker dies mid-drive
        assert queue.take() is not None
        clock.advance(queue.lease_ms + 1)
    drive = FakeDrive(DriveOutcome(reports=[passed()]))

    worker(drive).run_one()
    assert drive.calls == [], "not driven a fourth time"
    stored = services.model_service().get(ALICE, model.model_id)
    assert stored.scrutineer_status == "cannot_scrutineer"
    assert "stopped 3 times without finishing" in (stored.scrutineer_status_reason or "")
    assert queue.state_of(model.model_id) is None


def test_a_model_deleted_while_queued_is_dropped_not_driven(stack: Any, aws_clients: Any, clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    services.model_service().delete(ALICE, model.model_id)
    drive = FakeDrive(DriveOutcome(reports=[passed()]))

    worker(drive).run_one()
    assert drive.calls == [] and services.scrutineer_queue().state_of(model.model_id) is None


def test_several_tracks_show_the_worst_verdict_and_name_every_drive(stack: Any, aws_clients: Any,
                                                                   clock: FakeClock) -> None:
    model = upload(stack, aws_clients)
    failed = passed("ATOZ_SPEEDWAY").model_copy(update={"verdict": "failed", "laps_completed": 1,
                                                        "message": "1/2 laps completed on reInvent2019_wide"})
    worker(FakeDrive(DriveOutcome(reports=[passed(), failed]))).run_one()

    result = services.model_service().get(ALICE, model.model_id).scrutineer_result
    assert result is not None and result.verdict == "failed" and result.track_type == "ATOZ_SPEEDWAY"
    assert "also driven: REINVENT_2018: passed" in result.message


class Interrupted(BaseException):
    """What SIGTERM raises in the worker (drem_local.workers.scrutineer._Stop) while a drive runs."""


def test_a_drive_interrupted_by_sigterm_goes_back_to_the_queue_at_once(stack: Any, aws_clients: Any,
                                                                       clock: FakeClock) -> None:
    model = upload(stack, aws_clients)

    def stopped_mid_drive(folder: Path, track_types: list[str], laps: int) -> DriveOutcome:
        assert services.model_service().get(ALICE, model.model_id).scrutineer_status == "driving"
        raise Interrupted()

    interrupted = worker(stopped_mid_drive)
    with pytest.raises(Interrupted):
        interrupted.run_one()
    interrupted.give_back()

    assert services.model_service().get(ALICE, model.model_id).scrutineer_status == "queued"
    drive = FakeDrive(DriveOutcome(reports=[passed()], clip=GIF))
    assert worker(drive).run_one() is not None, "taken again without waiting for the lease"
    assert services.model_service().get(ALICE, model.model_id).scrutineer_status == "passed"


def test_driving_it_by_hand_takes_its_place_in_the_queue(stack: Any, aws_clients: Any, clock: FakeClock) -> None:
    from types import SimpleNamespace

    from chalicelib.domain.model_scrutiny import ScrutineerRequest, ScrutineerService

    model = upload(stack, aws_clients)
    report = SimpleNamespace(verdict="failed", message="0/1 laps completed on reinvent_base", track="reinvent_base",
                             track_type="REINVENT_2018", laps=1, laps_completed=0, best_lap_time_s=None,
                             mean_lap_time_s=None, offtrack_count=1)
    by_hand = ScrutineerService(services.model_service(), tracks=None, drive=lambda folder, track, laps: report,
                                queue=services.scrutineer_queue())  # type: ignore[arg-type]

    driven = by_hand.scrutineer(ALICE, model.model_id, ScrutineerRequest(laps=1))
    assert driven.scrutineer_status == "failed" and driven.scrutineer_state is None
    assert services.scrutineer_queue().state_of(model.model_id) is None, "no second, background drive"


@pytest.mark.parametrize(("worker_elsewhere", "shown"), [(False, "not_scrutineered"), ("1", "queued")])
def test_without_a_simulator_a_model_is_queued_only_where_a_worker_runs_elsewhere(
        stack: Any, aws_clients: Any, monkeypatch: pytest.MonkeyPatch, worker_elsewhere: Any, shown: str) -> None:
    """The functions on AWS have no simulator: alone they queue nothing (a model "queued" for ever would mislead);
    with the learning booth's task, which runs the scrutineering worker, the stack tells them so and they queue."""
    import importlib.util

    from drem_infra.resources import SCRUTINEERING_WORKER_ENV

    find_spec = importlib.util.find_spec
    monkeypatch.setattr(services.importlib.util, "find_spec",
                        lambda name, *args: None if name == "drem_sim" else find_spec(name, *args))
    if worker_elsewhere:
        monkeypatch.setenv(SCRUTINEERING_WORKER_ENV, worker_elsewhere)
    model = upload(stack, aws_clients)
    assert services.model_service().get(ALICE, model.model_id).public()["scrutineer_status"] == shown
    assert (services.scrutineer_queue().state_of(model.model_id) is not None) is bool(worker_elsewhere)


def test_a_hand_drive_stored_just_before_the_background_drive_writes_is_kept(stack: Any, aws_clients: Any,
                                                                             clock: FakeClock) -> None:
    """What CI once met: staff drove the model on their event's track by hand, and its result landed between the
    background worker's last read of the model and its write. The model must show the hand drive, the newer word."""
    from types import SimpleNamespace

    from chalicelib.domain.model_scrutiny import ScrutineerRequest, ScrutineerService

    model = upload(stack, aws_clients)
    report = SimpleNamespace(verdict="failed", message="0/1 laps completed on reInvent2019_wide",
                             track="reInvent2019_wide", track_type="ATOZ_SPEEDWAY", laps=1, laps_completed=0,
                             best_lap_time_s=None, mean_lap_time_s=None, offtrack_count=1)
    by_hand = ScrutineerService(services.model_service(), tracks=None, drive=lambda folder, track, laps: report,
                                queue=services.scrutineer_queue())  # type: ignore[arg-type]
    drive = FakeDrive(DriveOutcome(reports=[passed("REINVENT_2018")], clip=GIF))
    background = worker(drive)
    store = background.models.store
    read = store.get
    hand_driven: list[ModelRecord] = []

    def read_then_a_hand_drive_lands(owner_sub: str, model_id: str) -> ModelRecord | None:
        record = read(owner_sub, model_id)
        if drive.calls and not hand_driven:  # the worker's read after its drive, before it writes
            hand_driven.append(by_hand.scrutineer(OPERATOR, model_id, ScrutineerRequest(
                laps=1, track_type="ATOZ_SPEEDWAY")))
        return record

    store.get = read_then_a_hand_drive_lands  # type: ignore[method-assign]
    assert background.run_one() is not None and hand_driven

    shown = services.model_service().get(ALICE, model.model_id)
    assert shown.scrutineer_result is not None
    assert shown.scrutineer_result.track_type == "ATOZ_SPEEDWAY", "the background drive overwrote the hand drive"
    assert shown.scrutineer_status == "failed" and shown.scrutineer_state is None
