"""Background scrutineering on the running stack, as racers see it through the API: an uploaded model is queued, the
stack's scrutineering worker drives it in the simulator by itself, and the model's record then shows the figures and
a top-down GIF that only its owner and model staff may fetch."""
from __future__ import annotations

import io
import signal
import sys
import time
from pathlib import Path

import pytest
import requests
from PIL import Image

from drem_local import stack as local_stack
from tests.browser.console_api import access_token, call, create_user, upload_model

pytestmark = pytest.mark.integration

SAMPLE = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
SETTLED = ("passed", "failed", "cannot_scrutineer")



def wait_until_scrutineered(url: str, token: str, model_id: str, timeout: float = 240.0) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        model = call(url, "GET", f"/api/models/{model_id}", token=token)["model"]
        if model["scrutineer_status"] in SETTLED:
            return model
        assert time.monotonic() < deadline, f"still {model['scrutineer_status']} after {timeout:.0f}s"
        time.sleep(0.5)


def test_an_uploaded_model_is_scrutineered_by_itself_and_its_clip_is_the_owners(live_stack) -> None:
    url = live_stack.url
    create_user(live_stack, "scr-ann", "racer")
    create_user(live_stack, "scr-bob", "racer")
    ann, bob = access_token(live_stack, "scr-ann"), access_token(live_stack, "scr-bob")
    admin = access_token_admin(live_stack)

    model = upload_model(url, ann, "scr-sample.tar.gz", SAMPLE.read_bytes())
    assert model["status"] == "AVAILABLE" and model["scrutineer_status"] in ("queued", "driving", "passed")

    done = wait_until_scrutineered(url, ann, model["model_id"])
    result = done["scrutineer_result"]
    # Driven on the coming events' track types (other tests of the session may have created some), else on
    # REINVENT_2018, where the shipped sample laps cleanly: the figures are there either way.
    assert done["scrutineer_status"] in ("passed", "failed"), result
    assert result["track_type"] in ("REINVENT_2018", "REINVENT_2019", "ATOZ_SPEEDWAY", "SUMMIT_SPEEDWAY",
                                    "FOREVER_RACEWAY") and result["laps"] == 2
    assert 0 <= result["laps_completed"] <= 2 and result["offtrack_count"] >= 0
    if done["scrutineer_status"] == "passed":
        assert result["laps_completed"] == 2 and result["best_lap_time_s"] > 0
    clip_path = done["scrutineer_clip"]
    assert clip_path == f"/api/models/{model['model_id']}/scrutineer/clip.gif"

    owner = requests.get(url + clip_path, headers={"Authorization": f"Bearer {ann}"}, timeout=15)
    assert owner.status_code == 200 and owner.headers["Content-Type"] == "image/gif"
    gif = Image.open(io.BytesIO(owner.content))
    assert gif.format == "GIF" and gif.n_frames > 10 and gif.size[0] >= 200  # an animation, not a still
    assert len(owner.content) <= 1_500_000
    staff = requests.get(url + clip_path, headers={"Authorization": f"Bearer {admin}"}, timeout=15)
    assert staff.status_code == 200 and staff.content == owner.content
    other = requests.get(url + clip_path, headers={"Authorization": f"Bearer {bob}"}, timeout=15)
    assert other.status_code == 403
    nobody = requests.get(url + clip_path, timeout=15)
    assert nobody.status_code == 401


def access_token_admin(live_stack) -> str:
    reply = live_stack.client("cognito-idp").initiate_auth(
        AuthFlow="USER_PASSWORD_AUTH", ClientId=live_stack.outputs.user_pool_client_id,
        AuthParameters={"USERNAME": live_stack.admin_username, "PASSWORD": live_stack.admin_password})
    return reply["AuthenticationResult"]["AccessToken"]


def _worker(live_stack, lease_s: float, log: Path) -> local_stack.ManagedProcess:
    """A scrutineer worker started (and later stopped) as `drem up` starts its own."""
    env = {**live_stack.env, "DREM_SCRUTINEER_LEASE_S": str(lease_s)}
    return local_stack.spawn("scrutineer", [sys.executable, "-m", "drem_local.workers.scrutineer", "--poll-s", "0.2"],
                             log, env=env)


def test_a_worker_killed_mid_drive_leaves_a_job_the_next_worker_drives(live_stack, tmp_path: Path) -> None:
    url = live_stack.url
    create_user(live_stack, "scr-kill", "racer")
    token = access_token(live_stack, "scr-kill")
    running = live_stack.running
    running.scrutineer.stop()  # this test's own workers, with a short lease, take the queue meanwhile
    first = second = None
    try:
        model = upload_model(url, token, "scr-kill.tar.gz", SAMPLE.read_bytes())
        model_id = model["model_id"]
        first = _worker(live_stack, lease_s=6, log=tmp_path / "first.log")
        deadline = time.monotonic() + 60
        while call(url, "GET", f"/api/models/{model_id}", token=token)["model"]["scrutineer_status"] != "driving":
            assert time.monotonic() < deadline, "the first worker never started driving"
            time.sleep(0.1)
        first.popen.send_signal(signal.SIGKILL)  # a crash mid-drive: nothing is given back
        first.popen.wait(30)
        assert call(url, "GET", f"/api/models/{model_id}", token=token)["model"]["scrutineer_status"] == "driving"

        second = _worker(live_stack, lease_s=6, log=tmp_path / "second.log")
        done = wait_until_scrutineered(url, token, model_id, timeout=120)
        assert done["scrutineer_status"] in ("passed", "failed") and done["scrutineer_clip"], done
        assert second.stop(timeout=60) == 0, second.log_tail()  # stops cleanly when asked, as drem up asks it
    finally:
        for worker in (first, second):
            if worker is not None and worker.alive():
                worker.popen.kill()
                worker.popen.wait(30)
        running.restart_scrutineer()
