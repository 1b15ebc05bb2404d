"""Manual drive server: a real HTTP server on a free port, the simulator stepping in real time in its thread."""
from __future__ import annotations

import io
import json
import tarfile
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import boto3
import cv2
import numpy as np
import pytest
from moto import mock_aws

from drem_sim import drive_server
from drem_sim.learn.dataset import load_snapshot
from drem_sim.runs import upload_run
from drem_sim.tracks import load_track
from tests.waiting import wait_until

pytestmark = pytest.mark.sim


@pytest.fixture
def server(tmp_path: Path) -> Iterator[drive_server.DriveServer]:
    running, threads = drive_server.start(load_track("drem_oval"), tmp_path / "runs", port=0)
    yield running
    drive_server.stop(running, threads)


def _get(server: drive_server.DriveServer, path: str) -> tuple[int, str, bytes]:
    with urllib.request.urlopen(server.url.rstrip("/") + path, timeout=5) as response:
        return response.status, response.headers.get_content_type(), response.read()


def _post(server: drive_server.DriveServer, path: str, body: Any, content_type: str = "application/json") -> tuple[int,
                                                                                                                   Any]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    request = urllib.request.Request(server.url.rstrip("/") + path, data=data, method="POST",
                                     headers={"Content-Type": content_type})
    try:
        with urllib.request.urlopen(request, timeout=5) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as error:
        return error.code, json.loads(error.read())


def _state(server: drive_server.DriveServer) -> dict[str, Any]:
    return json.loads(_get(server, "/state")[2])


def _drive_until(server: drive_server.DriveServer, condition, control: dict[str, float], seconds: float = 5.0) -> dict:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        _post(server, "/control", control)
        state = _state(server)
        if condition(state):
            return state
        time.sleep(0.05)
    raise AssertionError(f"condition not reached in {seconds}s: {state}")


def test_page_and_camera_frame_are_served(server: drive_server.DriveServer) -> None:
    status, kind, page = _get(server, "/")
    assert status == 200 and kind == "text/html"
    assert b'src="/frame.png"' in page and b'"/control"' in page
    status, kind, png = _get(server, "/frame.png")
    frame = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    assert kind == "image/png" and frame.shape == (120, 160)


def test_throttle_moves_the_car_and_the_camera_view_changes(server: drive_server.DriveServer) -> None:
    first_frame = _get(server, "/frame.png")[2]
    start = _state(server)
    assert start["speed"] == 0 and start["progress"] == 0

    moving = _drive_until(server, lambda s: s["progress"] > 2.0, {"steering": 0.0, "throttle": 1.0})

    assert moving["speed"] == pytest.approx(drive_server.FULL_THROTTLE_SPEED)
    assert moving["steps"] > start["steps"]
    assert _get(server, "/frame.png")[2] != first_frame


def test_steering_is_scaled_to_degrees_left_positive(server: drive_server.DriveServer) -> None:
    state = _drive_until(server, lambda s: s["steering_angle"] == 15.0, {"steering": 0.5, "throttle": 0.0})
    assert state["speed"] == 0


def test_the_car_stops_when_controls_stop_arriving(tmp_path: Path) -> None:
    session = drive_server.DriveSession(load_track("drem_oval"), tmp_path, control_timeout_s=0.2)
    session.set_control(drive_server.Control(steering=0.3, throttle=1.0))
    assert session.action()["speed"] == pytest.approx(drive_server.FULL_THROTTLE_SPEED)
    wait_until(lambda: session.action() == {"steering_angle": 0.0, "speed": 0.0}, 30,
               "the car to stop once no control arrived for 0.2 s")


@pytest.mark.parametrize(("body", "message"), [
    ({"steering": "left"}, "steering must be a number"),
    (b'{"throttle": NaN}', "throttle must be a number"),
    (b'{"steering": ', "body is not JSON"),
    ({"steering": 0, "boost": 1}, "a control is"),
    ([1, 2], "a control is"),
])
def test_bad_controls_are_refused_with_a_reason(server: drive_server.DriveServer, body: Any, message: str) -> None:
    status, reply = _post(server, "/control", body)
    assert status == 400 and message in reply["error"]


def test_form_posts_are_refused(server: drive_server.DriveServer) -> None:
    status, reply = _post(server, "/control", b"steering=1", content_type="application/x-www-form-urlencoded")
    assert status == 415 and "application/json" in reply["error"]


def test_a_recording_is_a_run_folder_the_trainer_reads(server: drive_server.DriveServer) -> None:
    status, state = _post(server, "/record", {"on": True})
    assert status == 200 and state["recording"]
    _drive_until(server, lambda s: s["recorded_frames"] >= 12, {"steering": 0.2, "throttle": 0.8})
    status, state = _post(server, "/record", {"on": False})

    assert status == 200 and not state["recording"]
    run_dir = Path(state["last_run"]["run_dir"])
    meta = json.loads((run_dir / "metadata.json").read_text())
    assert meta["driver"] == "human" and meta["track_id"] == "drem_oval" and meta["frames"] >= 12
    rows = [json.loads(line) for line in (run_dir / "controls.jsonl").read_text().splitlines()]
    assert rows[0]["t_ms"] == 0
    assert max(row["speed"] for row in rows) == pytest.approx(0.8 * drive_server.FULL_THROTTLE_SPEED, abs=1e-3)
    assert all(0.0 <= row["car_speed"] <= row["speed"] + 1e-6 for row in rows)  # the car picks up speed, no jump
    snapshot = load_snapshot([run_dir])  # the car's real speeds are what the frames teach; off-track left out
    moving = [index for index, row in enumerate(rows) if row["car_speed"] > 0]
    driven = rows[moving[0]:moving[-1] + 1]
    assert len(snapshot) == sum(1 for row in driven if not row["offtrack"]) > 0
    assert snapshot.speed.tolist() == pytest.approx([row["car_speed"] for row in driven if not row["offtrack"]])


def test_a_stopped_recording_is_uploaded_to_the_runs_bucket(tmp_path: Path) -> None:
    with mock_aws():
        s3 = boto3.client("s3", region_name="us-east-1")
        s3.create_bucket(Bucket="drem-test-runs")
        session = drive_server.DriveSession(load_track("drem_oval"), tmp_path,
                                            uploader=lambda run_dir: upload_run(s3, "drem-test-runs", run_dir))
        session.set_recording(True)
        session.set_control(drive_server.Control(throttle=1.0))
        for _ in range(5):
            session.step()
        state = session.set_recording(False)

        uri = state["last_run"]["uploaded"]
        assert uri.startswith("s3://drem-test-runs/runs/drem_oval/")
        stored = s3.list_objects_v2(Bucket="drem-test-runs", Prefix=uri.removeprefix("s3://drem-test-runs/"))
        keys = {item["Key"] for item in stored["Contents"]}
        bundle = next(key for key in keys if key.endswith("/frames.tar"))  # all frames travel as one object
        body = s3.get_object(Bucket="drem-test-runs", Key=bundle)["Body"].read()
        with tarfile.open(fileobj=io.BytesIO(body)) as frames:
            assert len([name for name in frames.getnames() if name.startswith("frames/")]) == 5
        assert any(key.endswith("/metadata.json") for key in keys)


def test_a_failed_upload_is_reported_and_the_run_stays_on_disk(tmp_path: Path) -> None:
    def unreachable(_run_dir: Path) -> str:
        raise ConnectionError("local stack is not running")

    session = drive_server.DriveSession(load_track("drem_oval"), tmp_path, uploader=unreachable)
    session.set_recording(True)
    session.set_control(drive_server.Control(throttle=1.0))
    session.step()
    state = session.set_recording(False)

    assert state["last_run"]["uploaded"] is None
    assert state["last_run"]["upload_error"] == "ConnectionError: local stack is not running"
    assert (Path(state["last_run"]["run_dir"]) / "metadata.json").is_file()


def test_the_drive_page_counts_no_lap_finished_from_where_the_car_was_put_back(tmp_path: Path) -> None:
    """A person leaves the track at 80 % of their first lap and finishes it from where the car was put back: the
    page's Laps stays 0 (that was no whole lap); the next lap, driven whole from the line, is lap 1, and the recorded
    run says the same."""
    from drem_sim.demonstrator import Demonstrator

    session = drive_server.DriveSession(load_track("reinvent_base"), tmp_path / "runs")
    teacher = Demonstrator(session.env.track)
    max_steering = session.env.physics.spec.max_steering_deg
    session.set_recording(True)

    def drive_one_lap(leave_at: float | None = None) -> None:
        laps_before, resets_before = session.env.laps, session.env.resets
        for _ in range(15 * 60):
            params = session.env.params
            if leave_at is not None and session.env.resets == resets_before and params["progress"] > leave_at:
                action = {"steering_angle": -30.0, "speed": 2.0}  # hard right, off the track
            else:
                action = teacher.act(params)
            session.set_control(drive_server.Control(
                steering=max(-1.0, min(1.0, action["steering_angle"] / max_steering)),
                throttle=min(1.0, action["speed"] / drive_server.FULL_THROTTLE_SPEED)))
            session.step()
            if session.env.laps > laps_before:
                return
        raise AssertionError("the car did not come round in a minute")

    drive_one_lap(leave_at=80.0)
    state = session.state()
    assert state["resets"] >= 1 and (state["laps"], state["lap_times_s"]) == (0, [])
    drive_one_lap()
    state = session.state()
    assert state["laps"] == 1 and len(state["lap_times_s"]) == 1 and state["lap_times_s"][0] > 5.0
    session.set_recording(False)
    assert session.last_run is not None
    meta = json.loads((Path(session.last_run["run_dir"]) / "metadata.json").read_text())
    assert (meta["laps"], len(meta["lap_times_ms"]), meta["resets"]) == (1, 1, state["resets"])
