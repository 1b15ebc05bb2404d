"""Giving models to cars: staff assign, the car downloads with a presigned GET and reports, staff watch the status."""
from __future__ import annotations

import datetime
import hashlib
import json
from typing import Any

import numpy as np
import pytest
import requests
from chalice.test import Client

from tests.unit.models_helpers import (
    ModelsApi,
    activate_device,
    bearer,
    device_headers,
    make_fleet,
    onnx_archive,
    traversal_archive,
)

pytestmark = pytest.mark.unit


@pytest.fixture
def app_client(client: Client, device_verifier: None) -> Client:
    return client


@pytest.fixture
def racer(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("alice", ("racer",))))


@pytest.fixture
def operator(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("olga", ("operator",))))


@pytest.fixture
def commentator(app_client: Client, users: Any) -> ModelsApi:
    return ModelsApi(app_client, bearer(users.access_token("chris", ("commentator",))))


@pytest.fixture
def fleet(app_client: Client) -> str:
    return make_fleet("fleet-1")


@pytest.fixture
def car_x(fleet: str, app_client: Client) -> tuple[str, ModelsApi]:
    issued = activate_device("car-x", fleet)
    return issued.device_id, ModelsApi(app_client, device_headers(issued.credential))


@pytest.fixture
def car_y(fleet: str, app_client: Client) -> tuple[str, ModelsApi]:
    issued = activate_device("car-y", fleet)
    return issued.device_id, ModelsApi(app_client, device_headers(issued.credential))


def assign(caller: ModelsApi, device_id: str, model_ids: list[str]) -> Any:
    return caller.call("PUT", f"/api/cars/{device_id}/models", {"model_ids": model_ids})


def report(car: ModelsApi, model_id: str, status: str, **extra: Any) -> Any:
    return car.call("POST", "/api/devices/self/assignment/status", {"model_id": model_id, "status": status, **extra})


def test_car_downloads_its_assigned_model_with_a_short_lived_url(racer: ModelsApi, operator: ModelsApi,
                                                                 car_x: tuple[str, ModelsApi]) -> None:
    archive = onnx_archive(0.25)
    model = racer.upload_and_complete("fast.tar.gz", archive)
    device_id, car = car_x

    assigned = assign(operator, device_id, [model["model_id"]])
    assert assigned.status_code == 200, assigned.json_body

    view = car.call("GET", "/api/devices/self/assignment").json_body
    assert view["device_id"] == device_id
    [entry] = view["models"]
    assert (entry["model_id"], entry["name"], entry["folder"]) == (model["model_id"], "fast", "alice-fast")
    assert entry["md5"] == hashlib.md5(archive).hexdigest() and entry["model_md5"] == model["model_md5"]
    assert entry["expires_in"] <= 300
    downloaded = requests.get(entry["url"], timeout=10)
    assert downloaded.status_code == 200 and downloaded.content == archive
    assert "X-Amz-Expires=300" in entry["url"]


def test_only_available_models_can_be_assigned(racer: ModelsApi, operator: ModelsApi,
                                               car_x: tuple[str, ModelsApi]) -> None:
    device_id, car = car_x
    quarantined = racer.upload_and_complete("evil.tar.gz", traversal_archive())
    pending = racer.upload("pending.tar.gz", onnx_archive())

    for model in (quarantined, pending):
        refused = assign(operator, device_id, [model["model_id"]])
        assert refused.status_code == 409 and refused.json_body["error"]["field"] == "model_ids"
    assert assign(operator, device_id, ["nope"]).status_code == 404
    assert car.call("GET", "/api/devices/self/assignment").json_body["models"] == []


def test_assignment_needs_a_real_car_and_staff(racer: ModelsApi, operator: ModelsApi, fleet: str,
                                               car_x: tuple[str, ModelsApi]) -> None:
    model = racer.upload_and_complete("m.tar.gz", onnx_archive())
    timer = activate_device("timer-1", fleet, kind="timer")
    device_id, car = car_x

    assert assign(operator, "car-unknown", [model["model_id"]]).status_code == 404
    assert assign(operator, timer.device_id, [model["model_id"]]).status_code == 404
    assert assign(racer, device_id, [model["model_id"]]).status_code == 403
    assert assign(car, device_id, [model["model_id"]]).status_code == 403
    assert assign(operator, device_id, [model["model_id"], model["model_id"]]).status_code == 400


def test_car_reports_are_visible_to_staff_per_car_and_per_event(
        racer: ModelsApi, operator: ModelsApi, commentator: ModelsApi, fleet: str,
        car_x: tuple[str, ModelsApi], car_y: tuple[str, ModelsApi]) -> None:
    archive = onnx_archive(0.75)
    model = racer.upload_and_complete("steady.tar.gz", archive)
    (x_id, car), (y_id, _) = car_x, car_y
    assign(operator, x_id, [model["model_id"]])

    assert report(car, model["model_id"], "downloading").status_code == 200
    verified = report(car, model["model_id"], "verified", md5=hashlib.md5(archive).hexdigest())
    assert verified.json_body["progress"]["status"] == "verified"
    assert report(car, model["model_id"], "loaded").status_code == 200

    staff_view = commentator.call("GET", f"/api/cars/{x_id}/models").json_body["assignment"]
    assert staff_view["models"][0]["progress"]["status"] == "loaded"

    event_id = create_event(fleet)  # through the events area's own service
    rows = commentator.call("GET", f"/api/events/{event_id}/model-status").json_body["rows"]
    by_car = {row["device_id"]: row for row in rows}
    assert set(by_car) == {x_id, y_id}
    assert (by_car[x_id]["model_name"], by_car[x_id]["owner_username"], by_car[x_id]["status"]) == \
        ("steady", "alice", "loaded")
    assert by_car[x_id]["updated_at"]
    assert by_car[y_id]["status"] == "unassigned"
    assert racer.call("GET", f"/api/events/{event_id}/model-status").status_code == 403


def test_a_wrong_checksum_is_recorded_as_failed(racer: ModelsApi, operator: ModelsApi,
                                                car_x: tuple[str, ModelsApi]) -> None:
    model = racer.upload_and_complete("m.tar.gz", onnx_archive())
    device_id, car = car_x
    assign(operator, device_id, [model["model_id"]])

    reply = report(car, model["model_id"], "verified", md5="0" * 32)
    assert reply.json_body["progress"]["status"] == "failed"
    assert "checksum mismatch" in reply.json_body["progress"]["reason"]
    assert report(car, model["model_id"], "failed").status_code == 400, "a failure needs a reason"


def test_a_car_reports_only_on_its_own_assignment(racer: ModelsApi, operator: ModelsApi,
                                                  car_x: tuple[str, ModelsApi], car_y: tuple[str, ModelsApi]) -> None:
    model = racer.upload_and_complete("m.tar.gz", onnx_archive())
    (x_id, _), (_, car_y_api) = car_x, car_y
    assign(operator, x_id, [model["model_id"]])

    assert report(car_y_api, model["model_id"], "loaded").status_code == 404
    assert car_y_api.call("GET", "/api/devices/self/assignment").json_body["models"] == []
    assert racer.call("GET", "/api/devices/self/assignment").status_code == 403
    x_view = operator.call("GET", f"/api/cars/{x_id}/models").json_body["assignment"]
    assert x_view["models"][0]["progress"]["status"] == "assigned"


def test_clearing_a_car_and_deleting_a_model_withdraw_it(racer: ModelsApi, operator: ModelsApi,
                                                         car_x: tuple[str, ModelsApi]) -> None:
    first = racer.upload_and_complete("one.tar.gz", onnx_archive(1))
    second = racer.upload_and_complete("two.tar.gz", onnx_archive(2))
    device_id, car = car_x
    assign(operator, device_id, [first["model_id"], second["model_id"]])

    racer.delete(second["model_id"])
    view = car.call("GET", "/api/devices/self/assignment").json_body
    assert [m["model_id"] for m in view["models"]] == [first["model_id"]]
    assert view["withdrawn"] == [second["model_id"]]

    assert assign(operator, device_id, []).status_code == 200
    assert car.call("GET", "/api/devices/self/assignment").json_body["models"] == []
    assert report(car, first["model_id"], "loaded").status_code == 404


def create_event(fleet_id: str) -> str:
    from chalicelib import services
    from chalicelib.core.principals import User
    from chalicelib.domain.events import EventInput

    operator = User(sub="operator-sub", username="olga", groups=frozenset({"operator"}))
    event = services.event_service().create_event(operator, EventInput.model_validate_json(json.dumps({
        "name": "Summit", "event_type": "AWS_SUMMIT", "date": datetime.date.today().isoformat(),
        "country_code": "GB", "tracks": [{"fleet_id": fleet_id}]})))
    return event.event_id


def test_a_console_model_reaches_a_drem_car_with_its_onnx_conversion(racer: ModelsApi, operator: ModelsApi,
                                                                     car_x: tuple[str, ModelsApi],
                                                                     tmp_path: Any) -> None:
    from drem_cars.model_store import ModelStore
    from drem_cars.parts.pilot_onnx import OnnxPilot
    from tests import console_fixture

    original = console_fixture.require_fixture().read_bytes()
    console_model = racer.upload_and_complete("console.tar.gz", original)
    drem_model = racer.upload_and_complete("drem.tar.gz", onnx_archive(0.5))
    assert console_model["scrutiny"] == "ready", console_model
    device_id, car = car_x
    assert assign(operator, device_id, [console_model["model_id"], drem_model["model_id"]]).status_code == 200

    entries = {e["name"]: e for e in car.call("GET", "/api/devices/self/assignment").json_body["models"]}
    assert "onnx" not in entries["drem"], "an ONNX archive needs no conversion"
    entry = entries["console"]
    assert entry["md5"] == hashlib.md5(original).hexdigest(), "the archive is still the upload, byte for byte"

    def fetch(url: str):  # noqa: ANN202
        return lambda handle: handle.write(requests.get(url, timeout=30).content)

    store = ModelStore(tmp_path / "models")
    installed = store.install(entry["model_id"], entry["name"], entry["folder"], entry["md5"],
                              download=fetch(entry["url"]),
                              converted=(fetch(entry["onnx"]["url"]), entry["onnx"]["md5"]))
    assert (installed.path / "agent" / "model.pb").is_file() and (installed.path / "model.onnx").is_file()
    steering, speed, _ = OnnxPilot(installed.path).run(np.zeros((120, 160), np.uint8))
    action_space = json.loads((installed.path / "model_metadata.json").read_text())["action_space"]
    assert (steering, speed) in {(a["steering_angle"], a["speed"]) for a in action_space}

    from drem_cars.model_store import ModelInstallError
    with pytest.raises(ModelInstallError, match="model.onnx md5"):
        store.install(entry["model_id"], entry["name"], "other", entry["md5"], download=fetch(entry["url"]),
                      converted=(fetch(entry["onnx"]["url"]), "0" * 32))


class MemoryAssignments:
    """The assignment store in memory; `first_read` is set once a car's poll has read its assignment."""

    def __init__(self) -> None:
        import threading

        from chalicelib.domain.assignments import Assignment

        self.items: dict[str, Assignment] = {}
        self.first_read = threading.Event()

    def get(self, device_id: str):  # type: ignore[no-untyped-def]
        self.first_read.set()
        return self.items.get(device_id)

    def put(self, assignment, *, expected_version: int) -> None:  # type: ignore[no-untyped-def]
        self.items[assignment.device_id] = assignment

    def written_elsewhere(self, device_id: str) -> None:
        """Another process (or on AWS another Lambda) changes the item: nothing in this process hears of it."""
        from chalicelib.domain.assignments import Assignment

        current = self.items.get(device_id) or Assignment(device_id=device_id)
        self.items[device_id] = current.model_copy(update={"version": current.version + 1})


class OneModel:
    """What assign and a car's read need of the model service: one AVAILABLE model."""

    def __init__(self) -> None:
        from types import SimpleNamespace

        from chalicelib.domain.racer_models import ModelStatus

        self.record = SimpleNamespace(model_id="m1", name="fast", owner_sub="sub-1", owner_username="ana",
                                      model_md5=None, archive_md5=None, status=ModelStatus.AVAILABLE,
                                      converted_md5=None)
        self.store = SimpleNamespace(get=lambda owner_sub, model_id: self.record)

    def available_model(self, model_id: str):  # type: ignore[no-untyped-def]
        return self.record

    def download_url(self, record) -> str:  # type: ignore[no-untyped-def]
        return "https://storage.example/m1"

    def converted_download_url(self, record) -> None:  # type: ignore[no-untyped-def]
        return None


def _waiting_car(recheck_s: float):  # type: ignore[no-untyped-def]
    """A service, its store, and a car's long poll (wait_for_version=0, 20 s) running on its own thread."""
    import threading
    from types import SimpleNamespace

    from chalicelib.core.principals import Device
    from chalicelib.domain.assignments import AssignmentQuery, AssignmentService

    store = MemoryAssignments()
    service = AssignmentService(store, OneModel(), SimpleNamespace(require_car=lambda device_id: None),  # type: ignore[arg-type]
                                recheck_s=recheck_s)
    answers: list[dict] = []
    poll = threading.Thread(target=lambda: answers.append(service.for_car(
        Device(device_id="car-1", device_kind="car"), AssignmentQuery(wait_for_version=0, wait_s=20))), daemon=True)
    poll.start()
    assert store.first_read.wait(30), "the car's poll reads its assignment"
    return service, store, poll, answers


def test_staff_assigning_wakes_the_waiting_car_before_any_storage_recheck() -> None:
    from chalicelib.core.principals import User

    # The storage re-read comes only after an hour: an answer before the 20 s wait ends was pushed by the write.
    service, _store, poll, answers = _waiting_car(recheck_s=3600)
    service.assign(User(sub="op", username="op", groups=frozenset({"operator"})), "car-1", ["m1"])
    poll.join(30)
    assert answers, "the car was answered"
    assert answers[0]["change_seen_by"] == "push", "woken by the write, not by a re-read or the end of the wait"
    assert answers[0]["version"] == 1 and [m["name"] for m in answers[0]["models"]] == ["fast"]


def test_a_change_made_in_another_process_reaches_the_car_by_the_storage_recheck() -> None:
    _service, store, poll, answers = _waiting_car(recheck_s=0.05)
    store.written_elsewhere("car-1")
    poll.join(30)
    assert answers and answers[0]["change_seen_by"] == "recheck" and answers[0]["version"] == 1


def test_a_car_behind_is_answered_at_once_and_an_unchanged_one_at_the_end_of_its_wait() -> None:
    from types import SimpleNamespace

    from chalicelib.core.principals import Device
    from chalicelib.domain.assignments import AssignmentQuery, AssignmentService

    store = MemoryAssignments()
    store.written_elsewhere("car-1")
    service = AssignmentService(store, OneModel(), SimpleNamespace(), recheck_s=0.05)  # type: ignore[arg-type]
    car = Device(device_id="car-1", device_kind="car")
    behind = service.for_car(car, AssignmentQuery(wait_for_version=0, wait_s=20))
    assert behind["version"] == 1 and behind["change_seen_by"] == "at once"
    unchanged = service.for_car(car, AssignmentQuery(wait_for_version=1, wait_s=0.2))
    assert unchanged["version"] == 1 and unchanged["change_seen_by"] == "deadline"


def test_the_car_route_takes_the_wait_and_refuses_a_wait_longer_than_the_gateway_allows(
        car_x: tuple[str, ModelsApi]) -> None:
    _device_id, car = car_x
    view = car.call("GET", "/api/devices/self/assignment?wait_for_version=5&wait_s=0").json_body
    assert view["version"] == 0 and view["models"] == []
    refused = car.call("GET", "/api/devices/self/assignment?wait_for_version=0&wait_s=600")
    assert refused.status_code == 400, refused.json_body
