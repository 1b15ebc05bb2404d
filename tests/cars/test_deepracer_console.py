"""The device-console driver against a console that behaves like a stock DeepRacer's
(tests/cars/fake_deepracer_console.py: real Flask-WTF CSRF, asynchronous loading, one login at a time, LED only in
calibration mode)."""
from __future__ import annotations

import gzip
import io
import json
import tarfile
from collections.abc import Iterator
from pathlib import Path

import pytest
import requests

from chalicelib.domain.devices import Telemetry
from drem_cars.drivers.deepracer_console import ConsoleError, DeepRacerConsole, DeepRacerConsoleDriver, csrf_meta_token
from drem_cars.model_files import ModelError
from drem_cars.model_store import ARCHIVE_COPY, InstalledModel
from tests import user_processes
from tests.cars.fake_deepracer_console import AUTONOMOUS, CALIBRATION, MANUAL, FakeConsole
from tests.waiting import wait_until

pytestmark = pytest.mark.unit

METADATA = {"action_space": [{"steering_angle": -30, "speed": 0.6}, {"steering_angle": 30, "speed": 0.6}],
            "sensor": ["FRONT_FACING_CAMERA"], "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
            "training_algorithm": "clipped_ppo", "action_space_type": "discrete", "version": "5"}


def car_archive(members: dict[str, bytes]) -> bytes:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return gzip.compress(buffer.getvalue())


def console_model(tmp_path: Path, *, metadata: dict | None = None, archive_members: dict[str, bytes] | None = None,
                  local_member: str = "agent/model.pb") -> InstalledModel:
    """An installed model as the agent's store leaves it: unpacked files plus the archive copy it uploads."""
    metadata_bytes = json.dumps(METADATA if metadata is None else metadata).encode()
    folder = tmp_path / "racer-fast"
    (folder / "agent").mkdir(parents=True)
    (folder / local_member).write_bytes(b"frozen graph")
    (folder / "model_metadata.json").write_bytes(metadata_bytes)
    members = archive_members if archive_members is not None else {
        "agent/model.pb": b"frozen graph", "model_metadata.json": metadata_bytes}
    (folder / ARCHIVE_COPY).write_bytes(car_archive(members))
    return InstalledModel(model_id="m1", name="fast", folder="racer-fast", archive_md5="0" * 32, path=folder)


@pytest.fixture
def fake() -> Iterator[FakeConsole]:
    with FakeConsole(load_seconds=0.3) as console:
        yield console


def make_driver(fake: FakeConsole, **console_options: float) -> DeepRacerConsoleDriver:
    return DeepRacerConsoleDriver(DeepRacerConsole(fake.url, "car-password", **console_options),
                                  poll_s=0.05, settle_s=1.0, load_timeout_s=10.0)


def paths(fake: FakeConsole) -> list[str]:
    return [f"{method} {path}" for method, path, _ in fake.state.calls]


def test_a_model_is_uploaded_loaded_and_reported_only_once_the_car_says_loaded(fake: FakeConsole,
                                                                                 tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    state = fake.state
    assert state.auto_loading_status == "loaded" and state.loaded_model == "racer-fast"
    assert state.artifacts["racer-fast"]["model.pb"] == b"frozen graph"
    assert paths(fake) == ["POST /login", "PUT /api/uploadModels", "PUT /api/start_stop", "PUT /api/drive_mode",
                           "PUT /api/models/racer-fast/model", "PUT /api/max_nav_throttle"]
    assert state.mode == AUTONOMOUS and state.throttle_scale == 1.0  # the car boots with 0
    assert not state.driving, "a loaded car waits for staff to start it"


def test_staff_start_and_stop_drive_the_car_at_the_throttle_cap(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    driver.set_throttle_cap(40)
    driver.start_car()
    assert fake.state.driving and fake.state.throttle_scale == 0.4
    driver.emergency_stop()
    assert not fake.state.driving and fake.state.auto_loading_status == "loaded"


def test_a_cap_set_before_any_model_is_applied_once_the_car_is_autonomous(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.set_throttle_cap(55)
    assert fake.state.throttle_scale == 0.0, "in manual mode (boot) the car ignores max_nav_throttle"
    driver.load_model(console_model(tmp_path))
    assert fake.state.throttle_scale == 0.55


def test_bad_metadata_is_refused_at_once_with_the_cars_reason(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    with pytest.raises(ModelError, match="The training algorithm value is incorrect"):
        driver.load_model(console_model(tmp_path, metadata={**METADATA, "training_algorithm": "behaviour_cloning"}))
    assert fake.state.load_requests == 0


def test_an_archive_without_a_pb_uploads_fine_then_cannot_be_loaded(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    model = console_model(tmp_path, archive_members={"model_metadata.json": json.dumps(METADATA).encode()})
    with pytest.raises(ModelError, match="Model optimization failed!"):
        driver.load_model(model)
    assert "PUT /api/uploadModels" in paths(fake)


def test_a_load_that_fails_on_the_car_is_reported_failed_with_its_status(fake: FakeConsole, tmp_path: Path) -> None:
    fake.state.optimizer_fails = True
    with pytest.raises(ModelError, match='isModelLoading says "error"'):
        make_driver(fake).load_model(console_model(tmp_path))


def test_an_onnx_model_is_refused_for_the_console_without_calling_it(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    with pytest.raises(ModelError, match="TensorFlow models only"):
        driver.load_model(console_model(tmp_path, local_member="model.onnx"))
    assert fake.state.calls == []


def test_wrong_password_is_a_clear_error(fake: FakeConsole) -> None:
    with pytest.raises(ConsoleError, match="refused the password"):
        DeepRacerConsole(fake.url, "nope").login()


def test_an_emergency_stop_works_after_the_login_and_csrf_token_expired(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    driver.start_car()
    fake.advance_clock(3601)
    driver.emergency_stop()
    assert not fake.state.driving
    assert paths(fake).count("POST /login") == 2


def test_an_upload_retried_after_logging_in_again_sends_the_whole_archive(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.battery_pct()  # logged in
    fake.advance_clock(3601)  # the upload's first attempt is refused (expired CSRF token), the second must be whole
    model = console_model(tmp_path)
    driver.load_model(model)
    assert fake.state.artifacts["racer-fast"]["model.pb"] == b"frozen graph"
    assert paths(fake).count("POST /login") == 2


def test_another_client_logging_in_is_survived_and_shown_to_staff(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    driver.start_car()
    fake.log_in_elsewhere()
    assert driver.battery_pct() is None
    assert any("someone else logged in" in fault for fault in driver.faults())
    Telemetry(faults=driver.faults())  # the heartbeat accepts them (at most 120 characters each)
    assert paths(fake).count("POST /login") == 2, "ours, theirs: a poll does not take the car's login back"
    driver.emergency_stop()  # staff commands always do
    assert not fake.state.driving and paths(fake).count("POST /login") == 3
    assert driver.battery_pct() == 70.0 and driver.faults() == []


def test_polls_take_the_login_back_after_the_yield_time(fake: FakeConsole) -> None:
    clock = [0.0]
    console = DeepRacerConsole(fake.url, "car-password", yield_login_s=120, clock=lambda: clock[0])
    driver = DeepRacerConsoleDriver(console)
    assert driver.battery_pct() == 70.0
    fake.log_in_elsewhere()
    assert driver.battery_pct() is None
    clock[0] = 121.0
    assert driver.battery_pct() == 70.0 and driver.faults() == []


def test_the_tail_light_is_set_in_calibration_mode_while_stopped_and_the_model_stays_loaded(
        fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    assert driver.set_tail_light("#FFA500") == "tail light #FFA500"
    state = fake.state
    assert state.tail_light == (255, 165, 0)
    assert "GET /api/set_calibration_mode" in paths(fake)
    assert state.mode == AUTONOMOUS and state.auto_loading_status == "loaded" and state.throttle_scale == 1.0
    driver.start_car()
    assert state.driving


def test_a_tail_light_asked_for_while_the_car_drives_waits_for_the_next_stop(fake: FakeConsole,
                                                                             tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    driver.start_car()
    assert "next stops" in driver.set_tail_light("#00FF00")
    assert fake.state.driving and fake.state.tail_light == (0, 0, 0)
    driver.battery_pct()
    assert any("waits for the car to stop" in fault for fault in driver.faults())
    Telemetry(faults=driver.faults())
    driver.emergency_stop()
    assert fake.state.tail_light == (0, 255, 0) and not fake.state.driving


def test_battery_is_reported_as_the_car_reports_it(fake: FakeConsole) -> None:
    driver = make_driver(fake)
    fake.state.battery_level = 11  # above full
    assert driver.battery_pct() == 100.0
    fake.state.battery_level = -1
    assert driver.battery_pct() is None
    assert driver.faults() == ["the car cannot read its battery level (the console reports -1)"]


def test_delete_all_models_stops_the_car_and_deletes_every_model_on_it(fake: FakeConsole, tmp_path: Path) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    fake.state.artifacts["someone-elses"] = {"model.pb": b"x", "checksum.txt": b"1\n"}
    driver.start_car()
    assert driver.delete_all_models() == 2
    assert fake.state.artifacts == {} and not fake.state.driving
    assert ("PUT", "/api/deleteModels", {"filenames": ["racer-fast", "someone-elses"]}) in fake.state.calls


# --- the fake console itself behaves like the car (what the driver above relies on) ---

def logged_in_session(fake: FakeConsole) -> tuple[requests.Session, dict[str, str]]:
    session = requests.Session()
    token = session.get(f"{fake.url}/", timeout=5).text.split('name="csrf-token" content="')[1].split('"')[0]
    for cookie in session.cookies:
        cookie.secure = False  # the car's session cookie is Secure (HTTPS); this fake speaks plain http
    headers = {"X-CSRFToken": token, "Referer": f"{fake.url}/"}
    assert session.post(f"{fake.url}/login", data={"password": "car-password"}, headers=headers,
                        timeout=5).text == "success"
    return session, headers


def wait_for_status(session: requests.Session, fake: FakeConsole, wanted: str) -> None:
    wait_until(lambda: session.get(f"{fake.url}/api/isModelLoading", timeout=5).json()["isModelLoading"] == wanted,
               10, f"isModelLoading says {wanted!r}", poll_s=0.02)


def test_fake_login_and_api_need_the_csrf_token(fake: FakeConsole) -> None:
    session = requests.Session()
    assert session.post(f"{fake.url}/login", data={"password": "car-password"}, timeout=5).status_code == 400
    session, headers = logged_in_session(fake)
    no_token = session.put(f"{fake.url}/api/start_stop", json={"start_stop": "stop"}, timeout=5)
    assert no_token.status_code == 400 and "CSRF token is missing" in no_token.text
    fake.advance_clock(3601)
    expired = session.put(f"{fake.url}/api/start_stop", json={"start_stop": "stop"}, headers=headers, timeout=5)
    assert expired.status_code == 400 and "CSRF token has expired" in expired.text


def test_fake_keeps_one_login_at_a_time(fake: FakeConsole) -> None:
    first, _ = logged_in_session(fake)
    assert first.get(f"{fake.url}/api/get_battery_level", timeout=5).status_code == 200
    logged_in_session(fake)
    assert first.get(f"{fake.url}/api/get_battery_level", timeout=5).status_code == 401


def test_fake_loads_asynchronously_and_hides_manual_mode_and_pb_name_failures(fake: FakeConsole) -> None:
    session, headers = logged_in_session(fake)
    archive = car_archive({"agent/model.pb": b"g", "model_metadata.json": json.dumps(METADATA).encode()})
    upload = session.put(f"{fake.url}/api/uploadModels", headers=headers, timeout=5,
                         files={"file": ("m.tar.gz", archive)})
    assert upload.json() == {"success": True, "message": "Model uploaded successfully to your vehicle"}
    assert fake.state.mode == MANUAL
    manual = session.put(f"{fake.url}/api/models/m/model", headers=headers, timeout=5)
    assert manual.json() == {"success": True}
    wait_for_status(session, fake, "error")
    session.put(f"{fake.url}/api/drive_mode", json={"drive_mode": "auto"}, headers=headers, timeout=5)
    assert session.put(f"{fake.url}/api/models/m/model.pb", headers=headers, timeout=5).json() == {"success": True}
    wait_for_status(session, fake, "loading")
    wait_for_status(session, fake, "error")
    assert session.put(f"{fake.url}/api/models/m/model", headers=headers, timeout=5).json() == {"success": True}
    wait_for_status(session, fake, "loaded")


def test_fake_changes_the_tail_light_only_in_calibration_mode(fake: FakeConsole) -> None:
    session, headers = logged_in_session(fake)
    colour = {"red": 10, "green": 20, "blue": 30}
    assert session.post(f"{fake.url}/api/set_led_color", json=colour, headers=headers, timeout=5).json() == {
        "success": True}
    assert fake.state.tail_light == (0, 0, 0)
    session.get(f"{fake.url}/api/set_calibration_mode", timeout=5)
    session.post(f"{fake.url}/api/set_led_color", json=colour, headers=headers, timeout=5)
    assert fake.state.mode == CALIBRATION and fake.state.tail_light == (10, 20, 30)
    refused = session.post(f"{fake.url}/api/set_led_color", json={**colour, "red": 300}, headers=headers, timeout=5)
    assert refused.json() == {"success": False, "reason": "Input is not valid"}


class AckRecorder:
    """The part of the device API client a command needs: acknowledgements, recorded."""

    def __init__(self) -> None:
        self.acks: dict[str, tuple[bool, str]] = {}

    def acknowledge(self, command_id: str, ok: bool, message: str) -> None:
        self.acks[command_id] = (ok, message)


def test_staff_commands_reach_the_car_through_the_agent(fake: FakeConsole, tmp_path: Path) -> None:
    from drem_cars.agent import CarAgent

    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    client = AckRecorder()
    agent = CarAgent(client, driver, outbox=None, store=None)  # type: ignore[arg-type]
    agent.run_command({"command_id": "c1", "type": "SET_THROTTLE_CAP", "parameters": {"throttle_cap_pct": 30}})
    agent.run_command({"command_id": "c2", "type": "START_CAR"})
    assert fake.state.driving and fake.state.throttle_scale == 0.3
    agent.run_command({"command_id": "c3", "type": "SET_TAIL_LIGHT", "parameters": {"colour": "#0000FF"}})
    assert client.acks["c3"] == (True, "tail light #0000FF when the car next stops (it changes only in "
                                       "calibration mode)")
    agent.run_command({"command_id": "c4", "type": "EMERGENCY_STOP"})
    assert not fake.state.driving and fake.state.tail_light == (0, 0, 255)
    agent.run_command({"command_id": "c5", "type": "DELETE_ALL_MODELS"})
    assert fake.state.artifacts == {}
    assert all(ok for ok, _ in client.acks.values()), client.acks
    assert "someone else" not in " ".join(agent.telemetry()["faults"])


def test_an_unreachable_car_is_retried_later_not_reported_as_a_broken_model(tmp_path: Path) -> None:
    from drem_cars.drivers.deepracer_console import ConsoleUnreachable

    driver = DeepRacerConsoleDriver(DeepRacerConsole("http://127.0.0.1:9", "pw", timeout_s=2))
    with pytest.raises(ConsoleUnreachable, match="cannot reach the DeepRacer console"):
        driver.load_model(console_model(tmp_path))
    assert driver.battery_pct() is None and driver.faults()[0].startswith("console: cannot reach")
    Telemetry(faults=driver.faults())


def test_the_csrf_token_is_read_from_the_meta_tag_whatever_the_attribute_order() -> None:
    assert csrf_meta_token('<head><meta charset="utf-8"><meta name="csrf-token" content="abc.def"></head>') == "abc.def"
    assert csrf_meta_token("<meta content='x-1' name='csrf-token' />") == "x-1"
    assert csrf_meta_token('<meta name="viewport" content="width=device-width">') is None


def test_the_installed_cli_drives_a_deepracer_console_or_says_why_it_cannot(fake: FakeConsole, tmp_path: Path) -> None:
    """`drem car run --deepracer` as a user runs it: the installed entry point, from outside the repository, stopped
    with Ctrl-C once its heartbeat has read the car (`--seconds` only bounds a hang)."""
    import signal
    import subprocess
    import sys

    from drem_cars.credentials import CredentialStore, StoredCredential

    config = tmp_path / "config"
    CredentialStore(config).save(StoredCredential(api="http://127.0.0.1:9", device_id="car-1", device_kind="car",
                                                  hostname="deepracer-07", fleet_id="f", credential="car-1.secret"))
    drem = str(Path(sys.executable).with_name("drem"))

    def start(password: str) -> subprocess.Popen[str]:
        return subprocess.Popen([drem, "car", "--config-dir", str(config), "run", "--deepracer", fake.url,
                                 "--seconds", "60"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env={"PATH": "/usr/bin:/bin", "DEEPRACER_PASSWORD": password,
                                                "DREM_CAR_NO_REEXEC": "1"}, preexec_fn=user_processes.from_a_shell)

    refused = start("wrong")
    _out, err = refused.communicate(timeout=60)
    assert refused.returncode == 1 and "refused the password" in err, err
    running = start("car-password")
    try:
        wait_until(lambda: "GET /api/get_battery_level" in paths(fake) or running.poll() is not None, 30,
                   "the heartbeat reads the car's battery (API unreachable)")
        assert running.poll() is None, running.communicate()[1]
        running.send_signal(signal.SIGINT)  # Ctrl-C, as a user stops it
        try:
            _out, err = running.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            pytest.fail(f"drem car run did not stop on Ctrl-C within 30 s: {user_processes.state(running.pid)}")
    finally:
        if running.poll() is None:
            running.kill()
            running.communicate()
    assert running.returncode == 0, err
    assert "Traceback" not in err, err


def test_the_agents_two_threads_sharing_the_console_do_not_take_each_other_for_someone_else(
        fake: FakeConsole, tmp_path: Path) -> None:
    import threading

    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    fake.advance_clock(3601)  # both threads' next calls are refused and log in again, at the same moment
    errors: list[BaseException] = []

    def hammer(action) -> None:  # type: ignore[no-untyped-def]
        try:
            for _ in range(15):
                action()
        except BaseException as exc:  # noqa: BLE001 - reported below
            errors.append(exc)

    threads = [threading.Thread(target=hammer, args=(driver.battery_pct,)),
               threading.Thread(target=hammer, args=(lambda: driver.set_throttle_cap(50),))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(60)
    assert errors == []
    assert driver.console.held_by_other_since is None and driver.faults() == []
    assert fake.state.throttle_scale == 0.5


def test_a_strange_battery_answer_is_a_fault_not_a_broken_heartbeat(fake: FakeConsole) -> None:
    driver = make_driver(fake)
    fake.state.battery_level = "unknown"  # type: ignore[assignment]
    assert driver.battery_pct() is None
    assert driver.faults() == ["console: /api/get_battery_level: battery_level 'unknown' is not a number"]


# --- a restarted car (every battery swap) ---

@pytest.mark.parametrize("forget_logins", [False, True], ids=["login kept (token.txt)", "login lost"])
def test_fake_restart_loses_the_loaded_model_and_keeps_the_folders(fake: FakeConsole, tmp_path: Path,
                                                                   forget_logins: bool) -> None:
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    session, _headers = logged_in_session(fake)  # the car's one login is now this session's
    fake.restart(forget_logins=forget_logins)
    answer = session.get(f"{fake.url}/api/isModelLoading", timeout=5)
    if forget_logins:
        assert answer.status_code == 401, "the login is gone"
        session, _headers = logged_in_session(fake)
        answer = session.get(f"{fake.url}/api/isModelLoading", timeout=5)
    assert answer.json()["isModelLoading"] == "error"
    listed = session.get(f"{fake.url}/api/uploaded_model_list", timeout=5).json()
    assert [entry["name"] for entry in listed] == ["racer-fast"], "the model folders stay on the car's disk"
    assert fake.state.mode == MANUAL and fake.state.loaded_model is None and fake.state.throttle_scale == 0.0


@pytest.mark.parametrize("forget_logins", [False, True], ids=["login kept (token.txt)", "login lost"])
def test_a_restarted_car_is_told_apart_from_another_login_and_refuses_to_start_without_a_model(
        fake: FakeConsole, tmp_path: Path, forget_logins: bool) -> None:
    driver = make_driver(fake)
    model = console_model(tmp_path)
    driver.load_model(model)
    fake.power_off()  # the battery swap: the car is off for a while, and the heartbeat notices
    assert driver.battery_pct() is None
    fake.power_on(forget_logins=forget_logins)
    assert driver.battery_pct() == 70.0, "nobody else holds a restarted car: drem logs in again at once if it must"
    assert not any("someone else" in fault for fault in driver.faults())
    assert driver.console.restarts == 1
    with pytest.raises(ConsoleError, match="not started: the car has no model loaded"):
        driver.start_car()
    assert not fake.state.driving
    lost = driver.model_lost(model)
    assert lost is not None and "car restarted" in lost and "loading it again" in lost
    uploads_before = paths(fake).count("PUT /api/uploadModels")
    driver.load_model(model)
    driver.reloaded(model)
    assert paths(fake).count("PUT /api/uploadModels") == uploads_before, "the car kept the folder: load it only"
    assert fake.state.loaded_model == "racer-fast" and driver.model_lost(model) is None
    assert driver.battery_pct() == 70.0 and any("loaded again" in fault for fault in driver.faults())
    Telemetry(faults=driver.faults())
    driver.start_car()
    assert fake.state.driving


def test_a_young_login_refused_without_the_car_going_away_is_another_clients_even_with_a_fresh_session_key(
        fake: FakeConsole, tmp_path: Path) -> None:
    """The car's session cookie is no evidence of a restart (its key may be the same at every start): only the car
    going away and coming back is."""
    driver = make_driver(fake)
    driver.load_model(console_model(tmp_path))
    fake.log_in_elsewhere()
    assert driver.battery_pct() is None, "a poll leaves the car to whoever logged in"
    assert any("someone else logged in" in fault for fault in driver.faults()) and driver.console.restarts == 0
    assert fake.state.loaded_model == "racer-fast"


class AssignmentClient(AckRecorder):
    """The device API as the agent sees it: one assigned console model, downloads served from bytes."""

    def __init__(self, archive: bytes) -> None:
        super().__init__()
        import hashlib

        self.archive = archive
        self.md5 = hashlib.md5(archive).hexdigest()
        self.reports: list[dict] = []

    def assignment(self) -> dict:
        return {"models": [{"model_id": "m1", "name": "fast", "folder": "racer-fast", "md5": self.md5,
                            "url": "https://api.example/m1"}]}

    def download(self, url: str, handle) -> None:  # type: ignore[no-untyped-def]
        handle.write(self.archive)

    def report_model_status(self, body: dict) -> dict:
        self.reports.append(body)
        return {}


def test_the_agent_reloads_the_model_a_restarted_car_lost_and_says_so(fake: FakeConsole, tmp_path: Path) -> None:
    from drem_cars.agent import CarAgent
    from drem_cars.model_store import ModelStore
    from drem_cars.outbox import Outbox

    client = AssignmentClient(car_archive({"agent/model.pb": b"frozen graph",
                                           "model_metadata.json": json.dumps(METADATA).encode()}))
    driver = make_driver(fake)
    agent = CarAgent(client, driver, Outbox(tmp_path / "outbox.sqlite3"), ModelStore(tmp_path / "models"))  # type: ignore[arg-type]
    agent.sync_models()
    assert [r["status"] for r in client.reports][-1] == "loaded" and fake.state.loaded_model == "racer-fast"
    fake.power_off()  # a battery swap: the heartbeat finds the car gone, then back
    assert "battery_pct" not in agent.telemetry()
    fake.power_on()
    agent.run_command({"command_id": "c1", "type": "START_CAR"})
    ok, message = client.acks["c1"]
    assert not ok and "no model loaded" in message and not fake.state.driving
    agent.sync_models()  # the next check asks the car, finds the model gone, loads it again
    statuses = [(r["status"], r.get("reason", "")) for r in client.reports]
    assert statuses[-2][0] == "verified" and "car restarted" in statuses[-2][1]
    assert statuses[-1] == ("loaded", "")
    assert fake.state.loaded_model == "racer-fast" and fake.state.auto_loading_status == "loaded"
    assert agent.telemetry()["model"]["name"] == "fast"
    assert any("loaded again" in fault for fault in agent.telemetry()["faults"])
    agent.run_command({"command_id": "c2", "type": "START_CAR"})
    assert client.acks["c2"] == (True, "started") and fake.state.driving


class QueueClient(AckRecorder):
    """The device API for a car whose assignment staff change: two racers' console models; a waiting assignment
    request is answered the moment the version changes, as the server's long poll does."""

    def __init__(self, archives: dict[str, bytes]) -> None:
        import hashlib
        import threading

        super().__init__()
        self.archives = archives
        self.md5 = {model_id: hashlib.md5(data).hexdigest() for model_id, data in archives.items()}
        self.order: list[str] = []
        self.version = 0
        self.changed = threading.Condition()
        self.reports: list[dict] = []
        self.plain_polls = 0

    def assign(self, order: list[str]) -> None:
        with self.changed:
            self.order, self.version = order, self.version + 1
            self.changed.notify_all()

    def assignment(self, *, wait_for_version: int | None = None, wait_s: float = 0.0) -> dict:
        with self.changed:
            if wait_for_version is None:
                self.plain_polls += 1
            else:
                self.changed.wait_for(lambda: self.version != wait_for_version, timeout=wait_s)
            return {"version": self.version, "models": [
                {"model_id": model_id, "name": model_id, "folder": f"racer-{model_id}", "md5": self.md5[model_id],
                 "url": f"https://api.example/{model_id}"} for model_id in self.order]}

    def download(self, url: str, handle) -> None:  # type: ignore[no-untyped-def]
        handle.write(self.archives[url.rsplit("/", 1)[1]])

    def report_model_status(self, body: dict) -> dict:
        self.reports.append(body)
        return {}

    def heartbeat(self, telemetry: dict) -> dict:
        return {}

    def commands(self) -> list:
        return []


def test_the_next_racers_model_waits_on_the_car_so_the_swap_is_the_load_alone(fake: FakeConsole,
                                                                              tmp_path: Path) -> None:
    from drem_cars.agent import AgentTiming, CarAgent
    from drem_cars.model_store import ModelStore
    from drem_cars.outbox import Outbox

    archive = {name: car_archive({"agent/model.pb": f"graph of {name}".encode(),
                                  "model_metadata.json": json.dumps(METADATA).encode()}) for name in ("ann", "bob")}
    client = QueueClient(archive)
    # The car check runs every 60 s here: only the long poll can bring a new assignment within the waits below.
    agent = CarAgent(client, make_driver(fake), Outbox(tmp_path / "outbox.sqlite3"), ModelStore(tmp_path / "models"),
                     AgentTiming(tick_s=0.1, assignment_poll_s=60.0, assignment_wait_s=20.0))  # type: ignore[arg-type]
    agent.start()
    try:
        wait_until(lambda: client.plain_polls >= 1, 20, "the agent asks for its assignment")
        client.assign(["ann", "bob"])  # ann races, bob is next in the queue
        wait_until(lambda: fake.state.loaded_model == "racer-ann" and "racer-bob" in fake.state.artifacts, 20,
                   "ann's model loaded and bob's already on the car")
        assert fake.state.artifacts["racer-bob"]["model.pb"] == b"graph of bob"
        uploads = paths(fake).count("PUT /api/uploadModels")
        assert uploads == 2
        client.assign(["bob", "ann"])  # the next race
        wait_until(lambda: fake.state.loaded_model == "racer-bob" and fake.state.auto_loading_status == "loaded", 20,
                   "bob's model loaded")
        wait_until(lambda: any(r == {"model_id": "bob", "status": "loaded", "md5": client.md5["bob"]}
                               for r in client.reports), 20, "staff see bob's model loaded")
        assert paths(fake).count("PUT /api/uploadModels") == uploads, "the swap was the load call alone"
        ann = [r for r in client.reports if r["model_id"] == "ann"]
        assert ann[-1]["status"] == "verified" and "waiting for its turn" in ann[-1]["reason"], \
            "staff no longer see ann's model as the loaded one"
        assert client.plain_polls == 1, "the assignment came by the long poll, not by polling"
    finally:
        agent.stop()


def test_a_model_folder_deleted_on_the_car_is_uploaded_again_when_its_load_is_refused(fake: FakeConsole,
                                                                                      tmp_path: Path) -> None:
    driver = make_driver(fake)
    model = console_model(tmp_path)
    driver.preload(model)
    assert "racer-fast" in fake.state.artifacts and fake.state.loaded_model is None, "on the car, not loaded"
    with fake.state.lock:
        del fake.state.artifacts["racer-fast"]  # someone deleted it on the car's own web page
    driver.load_model(model)
    assert fake.state.loaded_model == "racer-fast"
    assert paths(fake).count("PUT /api/uploadModels") == 2


def test_a_car_restarted_in_the_middle_of_a_load_is_loaded_again_not_blamed_on_the_model(fake: FakeConsole,
                                                                                        tmp_path: Path) -> None:
    from drem_cars.drivers import CarUnreachable

    armed = [False]

    def switch_off_once_while_waiting(seconds: float) -> None:  # the battery is swapped during the load
        if armed[0]:
            armed[0] = False
            fake.power_off()

    driver = DeepRacerConsoleDriver(DeepRacerConsole(fake.url, "car-password"), poll_s=0.05, settle_s=1.0,
                                    load_timeout_s=10.0, sleep=switch_off_once_while_waiting)
    model = console_model(tmp_path)
    driver.console.login()
    armed[0] = True
    with pytest.raises(CarUnreachable, match="stopped answering while loading racer-fast/model"):
        driver.load_model(model)
    fake.power_on()
    driver.load_model(model)  # the agent's next check: the folder is on the car, the load is all it takes
    assert fake.state.loaded_model == "racer-fast" and fake.state.auto_loading_status == "loaded"
    assert paths(fake).count("PUT /api/uploadModels") == 1


def test_the_check_puts_back_a_folder_deleted_on_the_car_without_stopping_it(fake: FakeConsole,
                                                                             tmp_path: Path) -> None:
    driver = make_driver(fake)
    model = console_model(tmp_path)
    driver.load_model(model)
    driver.start_car()
    with fake.state.lock:
        del fake.state.artifacts["racer-fast"]  # deleted on the car's own page; the loaded model drives on
    assert driver.model_lost(model) is None, "still loaded and driving: not a reason to stop the car"
    assert fake.state.driving
    assert fake.state.artifacts["racer-fast"]["model.pb"] == b"frozen graph", "put back for the next restart"
