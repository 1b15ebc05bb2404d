"""The learning booth's API: tracks, runs (live drive and uploaded artifacts), metrics, training jobs, versions, and
who sees what (a racer only their own runs and jobs, admins and operators everyone's)."""
from __future__ import annotations

import json
from typing import Any

import cv2
import numpy as np
import pytest

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.booth_runs import compute_metrics, parse_controls
from tests.unit.booth_helpers import drive_lost_by_a_kill
from tests.unit.models_helpers import ModelsApi, activate_device, bearer, make_fleet, onnx_archive

pytestmark = pytest.mark.unit


@pytest.fixture
def bob(client: Any, users: Any) -> ModelsApi:
    return ModelsApi(client, bearer(users.access_token("bob", ("racer",))))


@pytest.fixture
def operator(client: Any, users: Any) -> ModelsApi:
    return ModelsApi(client, bearer(users.access_token("olga", ("operator",))))


def row(index: int, *, lap: int = 0, progress: float = 0.0, steering: float = 0.0, offtrack: bool = False) -> dict:
    return {"index": index, "t_ms": index * 1000 // 15, "steering_angle": steering, "speed": 1.5,
            "progress": progress, "x": 0.1 * index, "y": 0.0, "heading": 0.0, "lap": lap, "offtrack": offtrack}


def controls(rows: list[dict]) -> bytes:
    return "".join(json.dumps(r) + "\n" for r in rows).encode()


def png() -> bytes:
    return cv2.imencode(".png", np.full((120, 160), 38, np.uint8))[1].tobytes()


def frames_tar(name: str) -> bytes:
    import io
    import tarfile

    buffer, data = io.BytesIO(), png()
    with tarfile.open(fileobj=buffer, mode="w") as bundle:
        info = tarfile.TarInfo(name)
        info.size = len(data)
        bundle.addfile(info, io.BytesIO(data))
    return buffer.getvalue()


def drive(api: ModelsApi, track: str = "drem_oval", steps: int = 30) -> dict[str, Any]:
    started = api.call("POST", "/api/drive", {"track_id": track})
    assert started.status_code == 201, started.json_body
    run_id = started.json_body["run_id"]
    assert started.json_body["frame"].startswith("data:image/png;base64,")
    for _ in range(steps):
        step = api.call("POST", f"/api/runs/{run_id}/drive", {"steering": 0.0, "throttle": 0.6})
        assert step.status_code == 200, step.json_body
    finished = api.call("POST", f"/api/runs/{run_id}/drive/finish")
    assert finished.status_code == 200, finished.json_body
    return finished.json_body["run"]


def test_tracks_are_the_simulators_closed_loops(client: Any) -> None:
    tracks = client.http.get("/api/tracks").json_body["tracks"]
    assert "drem_oval" in {t["track_id"] for t in tracks}
    assert "Straight_track" not in {t["track_id"] for t in tracks}  # an open route cannot be raced
    oval = client.http.get("/api/tracks/drem_oval").json_body["track"]
    assert oval["length_m"] > 5 and len(oval["centerline"]) >= 3
    missing = client.http.get("/api/tracks/nowhere", headers={"Accept": "application/json"})
    assert missing.status_code == 404 and "GET /api/tracks" in missing.json_body["error"]["message"]


def test_a_live_drive_becomes_a_finalised_run_only_its_driver_and_staff_see(alice: ModelsApi, bob: ModelsApi,
                                                                            operator: ModelsApi, client: Any) -> None:
    run = drive(alice, steps=40)
    assert run["status"] == "FINALISED" and run["mode"] == "manual"
    assert run["metrics"]["frames"] == 40 and run["metrics"]["mean_speed"] > 0.5
    assert [r["run_id"] for r in alice.call("GET", "/api/runs").json_body["runs"]] == [run["run_id"]]
    assert bob.call("GET", "/api/runs").json_body["runs"] == []
    assert bob.call("GET", f"/api/runs/{run['run_id']}").status_code == 403
    assert bob.call("POST", f"/api/runs/{run['run_id']}/drive", {"throttle": 1}).status_code in (403, 404)
    assert [r["run_id"] for r in operator.call("GET", "/api/runs?everyone=true").json_body["runs"]] == [run["run_id"]]
    picture = alice.call("GET", f"/api/runs/{run['run_id']}/artifacts/topdown.png")
    assert picture.status_code == 302
    import requests

    fetched = requests.get(picture.headers["Location"], timeout=10)
    assert fetched.status_code == 200 and fetched.content.startswith(b"\x89PNG")
    controls_link = alice.call("GET", f"/api/runs/{run['run_id']}/artifacts/controls.jsonl").headers["Location"]
    lines = requests.get(controls_link, timeout=10).text.splitlines()
    assert len(lines) == 40 and json.loads(lines[0])["frame"] == "frames/000000.png"
    bundle_link = alice.call("GET", f"/api/runs/{run['run_id']}/artifacts/frames.tar").headers["Location"]
    from drem_sim.runs import read_frames

    frames = list(read_frames(requests.get(bundle_link, timeout=10).content))  # all 40 frames in one download
    assert [name for name, _ in frames] == [f"frames/{i:06d}.png" for i in range(40)]
    page = client.http.get(f"/booth/runs/{run['run_id']}", headers={"Authorization": alice.headers["Authorization"]})
    html = page.body.decode()
    assert 'data-testid="run-topdown"' in html and "40 (" in html
    steering = html[html.index('data-testid="plot-steering"'):]
    assert "<polyline" in steering[:steering.index("</svg>")]  # the controls over time, drawn


def test_uploaded_artifacts_are_checked_and_finalising_computes_the_metrics(alice: ModelsApi) -> None:
    created = alice.call("POST", "/api/runs", {"track_id": "drem_oval", "mode": "manual"})
    assert created.status_code == 201, created.json_body
    run_id = created.json_body["run"]["run_id"]
    put = alice.client.http.put
    headers = {**alice.headers, "Content-Type": "application/octet-stream"}
    bad = put(f"/api/runs/{run_id}/artifacts/controls.jsonl", headers=headers, body=b'{"t_ms": "soon"}\n')
    assert bad.status_code == 200  # stored as bytes; judged when finalised
    refused = alice.call("POST", f"/api/runs/{run_id}/finalise")
    assert refused.status_code == 400 and "line 1" in refused.json_body["error"]["message"]
    assert put(f"/api/runs/{run_id}/artifacts/frame-000000.png", headers=headers, body=b"GIF89a").status_code == 400
    assert put(f"/api/runs/{run_id}/artifacts/..%2Fescape", headers=headers, body=b"x").status_code == 400
    assert put(f"/api/runs/{run_id}/artifacts/frame-000000.png", headers=headers, body=png()).status_code == 200
    escaping = put(f"/api/runs/{run_id}/artifacts/frames.tar", headers=headers, body=frames_tar("../../x.png"))
    assert escaping.status_code == 400 and "is not a frames/NNNNNN.png file" in escaping.json_body["error"]["message"]
    assert put(f"/api/runs/{run_id}/artifacts/frames.tar", headers=headers,
               body=frames_tar("frames/000001.png")).status_code == 200
    rows = [row(i, progress=i * 2.0, steering=(5.0 if i % 2 else -5.0)) for i in range(50)]
    rows += [row(50, lap=1, progress=0.5), row(51, lap=1, progress=3.0, offtrack=True), row(52, lap=1, progress=1.0)]
    assert put(f"/api/runs/{run_id}/artifacts/controls.jsonl", headers=headers, body=controls(rows)).status_code == 200
    run = alice.call("POST", f"/api/runs/{run_id}/finalise").json_body["run"]
    metrics = run["metrics"]
    # the lap, then an attempt that left the track 3 % on; where the car was put back begins no attempt
    assert (metrics["laps_completed"], metrics["offtrack_count"], metrics["attempts"]) == (1, 1, 2)
    assert metrics["completion_pct"] == pytest.approx((100 + 3.0) / 2, abs=0.01)
    assert metrics["stability_deg"] == pytest.approx(10.0, abs=0.3)
    assert metrics["lap_times_s"] == pytest.approx([3.32], abs=0.005)  # the line lies 80 % into the 50th decision
    late = put(f"/api/runs/{run_id}/artifacts/controls.jsonl", headers=headers, body=controls(rows))
    assert late.status_code == 409  # a finalised run's artifacts no longer change


def test_metrics_count_only_clean_laps() -> None:
    rows = [row(i, progress=min(99.0, i * 5.0), offtrack=i == 10) for i in range(30)] + [row(30, lap=1)]
    metrics = compute_metrics(parse_controls(controls(rows)))
    # one attempt, off the track at 50 %; the stretch from where the car was put back to the line is no attempt
    assert metrics.laps_completed == 0 and metrics.offtrack_count == 1 and metrics.attempts == 1
    assert metrics.completion_pct == 55.0  # where the off-track decision (row 10) took the car: row 11's 55 %
    with pytest.raises(InvalidInput, match="no rows"):
        parse_controls(b"\n\n")
    with pytest.raises(InvalidInput, match="x must be a number"):
        parse_controls(controls([{**row(0), "x": float("nan")}]))


def test_training_jobs_queue_in_order_and_a_trained_archive_becomes_the_next_version(
        alice: ModelsApi, bob: ModelsApi, operator: ModelsApi, client: Any) -> None:
    from chalicelib import services

    alice_run, bob_run = drive(alice, steps=10), drive(bob, steps=10)
    stolen = alice.call("POST", "/api/training-jobs", {"run_ids": [bob_run["run_id"]]})
    assert stolen.status_code == 403  # another racer's run: not visible, never trained on
    job = alice.call("POST", "/api/training-jobs", {"run_ids": [alice_run["run_id"]], "epochs": 2})
    assert job.status_code == 201, job.json_body
    assert job.json_body["job"]["status"] == "QUEUED" and job.json_body["job"]["queue_position"] == 1
    assert alice.call("POST", "/api/training-jobs", {"run_ids": [alice_run["run_id"]]}).status_code == 409
    bob_job = bob.call("POST", "/api/training-jobs", {"run_ids": [bob_run["run_id"]]}).json_body["job"]
    assert bob_job["queue_position"] == 2
    assert bob.call("GET", f"/api/training-jobs/{job.json_body['job']['job_id']}").status_code == 403

    training = services.training_service()
    claimed = training.claim_next()
    assert claimed is not None and claimed.owner_username == "alice"
    assert bob.call("GET", f"/api/training-jobs/{bob_job['job_id']}").json_body["job"]["queue_position"] == 1
    claimed = training.report(claimed, progress=0.5, epoch=1, loss=0.25)
    shown = alice.call("GET", f"/api/training-jobs/{claimed.job_id}").json_body["job"]
    assert (shown["status"], shown["progress"], shown["loss"]) == ("RUNNING", 0.5, 0.25)
    assert training.next_version_name(claimed.owner_sub) == "v0001"
    model = services.model_service().submit_archive(claimed.owner_sub, "alice", "v0001", onnx_archive(0.3))
    assert model.status.value == "AVAILABLE" and model.name == "v0001"
    training.finish(claimed, model)
    assert training.next_version_name(claimed.owner_sub) == "v0002"
    done = alice.call("GET", f"/api/training-jobs/{claimed.job_id}").json_body["job"]
    assert (done["status"], done["model_name"]) == ("DONE", "v0001")
    assert bob.call("POST", f"/api/models/{model.model_id}/active").status_code == 403
    assert alice.call("POST", f"/api/models/{model.model_id}/active").status_code == 200
    page = client.http.get("/booth", headers={"Authorization": alice.headers["Authorization"]}).body.decode()
    assert 'data-version="v0001"' in page and 'data-testid="active-version"' in page
    # Staff see each driver's active version with a form that sends exactly that version to a chosen car (through
    # the console's assign flow, which asks first when it has not passed scrutineering).
    staff_headers = {"Authorization": operator.headers["Authorization"]}
    no_cars = client.http.get("/booth?everyone=true", headers=staff_headers).body.decode()
    row = no_cars[no_cars.index('data-racer="alice"'):]
    assert "Activate a car first" in row[:row.index("</tr>")]
    car = activate_device("booth-car", make_fleet("booth-fleet"))
    html = client.http.get("/booth?everyone=true", headers=staff_headers).body.decode()
    row = html[html.index('data-racer="alice"'):]
    row = row[:row.index("</tr>")]
    assert "v0001" in row and 'hx-post="/console/models/assign"' in row
    assert f'name="model_ids" value="{model.model_id}"' in row
    assert f'<option value="{car.device_id}">booth-car (offline)</option>' in row
    assert client.http.get("/booth", headers={"Authorization": alice.headers["Authorization"]}).body.decode() \
        .count('data-testid="send-active"') == 0  # a racer does not send to cars
    # Everyone's jobs name their racer, on the page and in the fragment the page polls; a racer's own never do.
    assert '<span data-testid="job-racer">alice</span>' in html
    polled = client.http.get("/booth/jobs?everyone=true", headers=staff_headers).body.decode()
    assert '<span data-testid="job-racer">alice</span>' in polled
    own = client.http.get("/booth/jobs?everyone=true", headers={"Authorization": alice.headers["Authorization"]})
    assert 'data-testid="job"' in own.body.decode() and "job-racer" not in own.body.decode()


def test_a_worker_that_died_leaves_its_job_queued_again(alice: ModelsApi) -> None:
    from chalicelib import services

    run = drive(alice, steps=5)
    alice.call("POST", "/api/training-jobs", {"run_ids": [run["run_id"]]})
    training = services.training_service()
    claimed = training.claim_next()
    assert claimed is not None and training.claim_next() is None
    assert [j.job_id for j in training.requeue_interrupted()] == [claimed.job_id]
    again = training.claim_next()
    assert again is not None and again.job_id == claimed.job_id


def test_an_autonomous_run_needs_an_available_model_of_ones_own(alice: ModelsApi, bob: ModelsApi) -> None:
    model = alice.upload_and_complete("mine.tar.gz", onnx_archive(0.1))
    refused = bob.call("POST", "/api/runs", {"track_id": "drem_oval", "mode": "autonomous",
                                             "model_id": model["model_id"]})
    assert refused.status_code == 403
    missing_model = alice.call("POST", "/api/runs", {"track_id": "drem_oval", "mode": "autonomous"})
    assert missing_model.status_code == 400
    queued = alice.call("POST", "/api/runs", {"track_id": "drem_oval", "mode": "autonomous",
                                              "model_id": model["model_id"], "laps": 2})
    assert queued.status_code == 201 and queued.json_body["run"]["status"] == "QUEUED"


def test_a_live_drive_refuses_bad_controls_and_unknown_tracks_and_loses_nothing(alice: ModelsApi) -> None:
    assert alice.call("POST", "/api/drive", {"track_id": "nowhere"}).status_code == 404
    started = alice.call("POST", "/api/drive", {"track_id": "drem_oval"}).json_body
    path = f"/api/runs/{started['run_id']}/drive"
    for bad in ({"steering": 5}, {"throttle": "full"}, {"steering": 0, "brake": 1}):
        reply = alice.call("POST", path, bad)
        assert reply.status_code == 400, (bad, reply.json_body)
    assert alice.call("POST", path, {"throttle": 1}).json_body["frames"] == 1  # the bad ones stepped nothing
    again = alice.call("POST", "/api/drive", {"track_id": "drem_oval"})  # one car per racer: the first is saved
    assert again.status_code == 201
    first = alice.call("GET", f"/api/runs/{started['run_id']}").json_body["run"]
    assert first["status"] == "FINALISED" and first["metrics"]["frames"] == 1


def test_a_racer_may_hold_only_a_few_open_runs(alice: ModelsApi, bob: ModelsApi) -> None:
    from chalicelib.domain.booth_runs import MAX_OPEN_RUNS

    for _ in range(MAX_OPEN_RUNS):
        assert alice.call("POST", "/api/runs", {"track_id": "drem_oval"}).status_code == 201
    refused = alice.call("POST", "/api/runs", {"track_id": "drem_oval"})
    assert refused.status_code == 429 and "not finished yet" in refused.json_body["error"]["message"]
    assert alice.call("POST", "/api/drive", {"track_id": "drem_oval"}).status_code == 429
    assert bob.call("POST", "/api/runs", {"track_id": "drem_oval"}).status_code == 201  # a limit per racer


def test_a_lost_drive_is_saved_up_to_its_last_whole_controls_row(alice: ModelsApi, tmp_path: Any) -> None:
    """A kill -9 can cut the controls row being written: the saved run ends at the last whole row (the decisions
    the racer saw answered), and the half row neither fails the save nor becomes a decision."""
    service, racer, run_id, folder = drive_lost_by_a_kill(tmp_path / "drives")
    with (folder / "controls.jsonl").open("a") as handle:
        handle.write('{"index": 7, "frame": "frames/000007.png", "t_ms": 4')  # cut mid-row
    saved = service.finish(racer, run_id)
    assert saved.status.value == "FINALISED" and saved.metrics is not None and saved.metrics.frames == 7
    assert not (tmp_path / "drives" / run_id).exists()


def train_action(html: str) -> str:
    """The Train button and what is beside it, as the page (or an htmx answer) shows them."""
    start = html.index('id="train-action"')
    return html[start:html.index("</span>", html.index("</button>", start))]


def test_train_is_off_with_the_reason_when_nothing_changed_since_the_last_version(alice: ModelsApi,
                                                                                  client: Any) -> None:
    from chalicelib import services
    from chalicelib.core.principals import User

    headers = {"Authorization": alice.headers["Authorization"]}

    def get(path: str) -> str:
        answer = client.http.get(path, headers=headers)
        assert answer.status_code == 200, answer.body
        return answer.body.decode()

    assert "drive a lap first" in train_action(get("/booth"))  # no drive yet: off, and says why
    first = drive(alice, steps=10)
    shown = train_action(get("/booth"))
    assert "train-why" not in shown and "disabled" not in shown and "Train on my 1 finished drive<" in shown
    job = alice.call("POST", "/api/training-jobs", {"run_ids": [first["run_id"]], "epochs": 3}).json_body["job"]
    waiting = train_action(get("/booth"))  # pressing again while it waits could only be refused: off
    assert "disabled" in waiting and "still in the queue or running" in waiting
    assert 'id="booth-versions"' not in get("/booth/jobs?epochs=3")  # the versions ride only on the job's end

    training = services.training_service()  # the worker makes v0001 from that drive with 3 epochs
    claimed = training.claim_next()
    assert claimed is not None and claimed.job_id == job["job_id"]
    model = services.model_service().submit_archive(claimed.owner_sub, "alice", "v0001", onnx_archive(0.7))
    training.finish(claimed, model)

    why = "Nothing changed since v0001: it learned from this same drive with 3 epochs."
    polled = get("/booth/jobs?epochs=3")  # the jobs poll that sees the job end brings the button along, off
    assert 'hx-swap-oob="true"' in train_action(polled) and why in train_action(polled)
    versions = polled[polled.index('id="booth-versions"'):]  # and the new version, without a reload
    assert versions.startswith('id="booth-versions" data-testid="booth-versions-section" hx-swap-oob="true"')
    assert 'data-version="v0001"' in versions and "No trained versions yet" not in versions
    assert 'disabled aria-describedby="train-why"' in train_action(get("/booth/train-action?epochs=3"))
    again = alice.call("POST", "/api/training-jobs", {"run_ids": [first["run_id"]], "epochs": 3})
    assert again.status_code == 409 and why in again.json_body["error"]["message"]  # at once, not after training
    assert client.http.post("/booth/train", headers={**headers, "Content-Type": "application/x-www-form-urlencoded"},
                            body="epochs=3").status_code == 409

    # Other epochs make another model: on, as the field changes (and the API agrees); nonsense epochs: off, and why.
    assert "disabled" not in train_action(get("/booth/train-action?epochs=4"))
    assert "Epochs are a whole number from 1 to 30." in train_action(get("/booth/train-action?epochs=0"))
    assert "Epochs are a whole number from 1 to 30." in train_action(get("/booth/train-action?epochs="))
    # v0001 deleted: the same drives would be accepted again, so Train is on.
    services.model_service().delete(User(sub=model.owner_sub, username="alice", groups=frozenset({"racer"})),
                                    model.model_id)
    assert "disabled" not in train_action(get("/booth/train-action?epochs=3"))

    second = drive(alice, steps=10)  # something new to learn from: Train is on again
    assert "Nothing changed" not in get("/booth")
    both = alice.call("POST", "/api/training-jobs", {"run_ids": [first["run_id"], second["run_id"]], "epochs": 3})
    assert both.status_code == 201, both.json_body
