"""The check of an arrived upload handed to the background worker (chalicelib.domain.model_checks): the racer's
`/complete` still answers the verdict, the check itself runs in the worker, and nothing is lost when no worker is
there or the racer stops waiting. Over moto: the queue is the real DynamoDB adapter, the archive a real upload."""
from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import pytest

from chalicelib import services
from chalicelib.core.errors import Conflict, NotFound
from chalicelib.core.principals import User
from chalicelib.domain.model_checks import WorkerChecks
from chalicelib.domain.racer_models import ModelRecord, ModelService, ModelStatus, UploadRequest
from chalicelib.domain.scrutineer_queue import ScrutineerQueue
from chalicelib.storage import clients
from chalicelib.storage.scrutineer_queue import CHECK_QUEUE_PK, DynamoJobStore
from tests.unit.models_helpers import onnx_archive
from tests.waiting import wait_until

pytestmark = pytest.mark.unit

ALICE = User(sub="sub-alice", username="alice", groups=frozenset({"racer"}))


def check_queue(stack: Any) -> ScrutineerQueue:
    return ScrutineerQueue(DynamoJobStore(clients.dynamodb(), stack.tables["models"], queue_pk=CHECK_QUEUE_PK),
                           services.now_ms)


def app_and_worker(stack: Any, **waiting: Any) -> tuple[ModelService, ModelService, WorkerChecks, list[str]]:
    """The app's model service (hands checks over) and the worker's (checks them), as two processes would hold them;
    `checked_by` lists which of the two ran each check."""
    checks = WorkerChecks(check_queue(stack), poll_s=0.02, **waiting)
    app, worker = services.model_service(checks=checks), services.model_service()
    checked_by: list[str] = []
    for name, service in (("app", app), ("worker", worker)):
        original = service.finish_check
        service.finish_check = (lambda record, name=name, original=original:  # type: ignore[method-assign]
                                checked_by.append(name) or original(record))
    return app, worker, checks, checked_by


def uploaded(service: ModelService, aws_clients: Any, stack: Any, name: str = "fast.tar.gz") -> ModelRecord:
    ticket = service.request_upload(ALICE, UploadRequest(filename=name))
    aws_clients.s3.put_object(Bucket=stack.buckets["models"], Key=ticket.model.upload_key, Body=onnx_archive())
    return ticket.model


@pytest.fixture
def worker_running(stack: Any) -> Iterator[Any]:
    """Starts the worker's loop over `checks` for `service` (as drem_local.workers.scrutineer does) until the test
    ends."""
    stop = threading.Event()
    threads: list[threading.Thread] = []

    def start(checks: WorkerChecks, service: ModelService) -> None:
        def loop() -> None:
            while not stop.is_set():
                if checks.run_one(service) is False:
                    stop.wait(0.02)
        threads.append(threading.Thread(target=loop, daemon=True))
        threads[-1].start()

    yield start
    stop.set()
    for thread in threads:
        thread.join(10)


def test_complete_answers_the_verdict_of_a_check_the_worker_ran(stack: Any, aws_clients: Any,
                                                                worker_running: Any) -> None:
    app, worker, checks, checked_by = app_and_worker(stack, takeover_s=60)
    model = uploaded(app, aws_clients, stack)
    worker_running(checks, worker)

    verdict = app.complete(ALICE, model.model_id)

    assert verdict.status is ModelStatus.AVAILABLE and verdict.model_kind == "onnx"
    assert checked_by == ["worker"], "the app's process must not run the check itself"
    # the worker removes its job just after storing the verdict the app answered
    wait_until(lambda: checks.queue.state_of(model.model_id) is None, 10, "a finished check left its job behind")
    assert app.complete(ALICE, model.model_id).status is ModelStatus.AVAILABLE  # completing again: same verdict


def test_without_a_worker_the_app_checks_the_upload_itself(stack: Any, aws_clients: Any) -> None:
    app, _, checks, checked_by = app_and_worker(stack, takeover_s=0.1)
    model = uploaded(app, aws_clients, stack)

    verdict = app.complete(ALICE, model.model_id)

    assert verdict.status is ModelStatus.AVAILABLE
    assert checked_by == ["app"]
    assert checks.queue.state_of(model.model_id) is None


def test_a_racer_who_stops_waiting_sees_checking_and_the_worker_still_finishes(stack: Any, aws_clients: Any,
                                                                               worker_running: Any) -> None:
    # The app dies (or the racer's request times out) while waiting: the job is stored, the worker checks it.
    app, worker, checks, checked_by = app_and_worker(stack, wait_s=0.0, takeover_s=60)
    model = uploaded(app, aws_clients, stack)

    answer = app.complete(ALICE, model.model_id)
    assert answer.status is ModelStatus.UPLOADED and answer.check_text == "Waiting to be checked…"

    worker_running(checks, worker)
    judged = wait_until(lambda: (m := app.get(ALICE, model.model_id)).status is not ModelStatus.UPLOADED and m, 30,
                        "the worker never checked the upload")
    assert judged.status is ModelStatus.AVAILABLE and checked_by == ["worker"]


def test_an_upload_whose_file_never_arrived_is_refused_and_queues_nothing(stack: Any) -> None:
    app, _, checks, checked_by = app_and_worker(stack, takeover_s=60)
    ticket = app.request_upload(ALICE, UploadRequest(filename="never-sent.tar.gz"))

    with pytest.raises(Conflict, match="has not arrived yet"):
        app.complete(ALICE, ticket.model.model_id)
    assert checks.queue.state_of(ticket.model.model_id) is None and checked_by == []


def test_a_check_of_a_model_deleted_before_the_worker_came_is_dropped(stack: Any, aws_clients: Any) -> None:
    app, worker, checks, _ = app_and_worker(stack, wait_s=0.0, takeover_s=60)
    model = uploaded(app, aws_clients, stack)
    app.complete(ALICE, model.model_id)
    app.delete(ALICE, model.model_id)

    taken = checks.run_one(worker)
    assert taken is not False and (taken is None or taken.status is ModelStatus.DELETED)
    assert checks.queue.state_of(model.model_id) is None
    with pytest.raises(NotFound):  # still gone: the check did not bring it back
        app.get(ALICE, model.model_id)
