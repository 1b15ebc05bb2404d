"""Issue 13 (event day), the CLI as a user runs it: the installed `drem` as a subprocess from a folder outside the
repository, against a running stack."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
import requests

pytestmark = pytest.mark.integration

REPO = Path(__file__).resolve().parents[2]
DREM = REPO / ".venv" / "bin" / "drem"
SAMPLE = REPO / "sim" / "drem_sim" / "samples" / "drem-bc-oval.tar.gz"


def drem(*argv: str, cwd: Path, env: dict[str, str] | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items() if not k.startswith("DREM_")}
    return subprocess.run([str(DREM), *argv], cwd=cwd, capture_output=True, text=True, timeout=timeout,
                          env={**clean, **(env or {})})


def drem_python(code: str, *, cwd: Path, env: dict[str, str]) -> subprocess.CompletedProcess:
    """The interpreter of the installed `drem` (its shebang), to ask where a package was imported from."""
    clean = {k: v for k, v in os.environ.items() if not k.startswith("DREM_")}
    python = DREM.read_text().splitlines()[0].removeprefix("#!").strip() or sys.executable
    return subprocess.run([python, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=60,
                          env={**clean, **env})


def test_the_cli_finds_the_running_stacks_port_and_takes_options_after_the_action(live_stack, tmp_path):
    # The stack runs on a free port, not 8000: the CLI reads it from the state dir (./.drem or $DREM_STATE_DIR).
    assert not live_stack.url.endswith(":8000")
    login = ["--username", live_stack.admin_username, "--password", live_stack.admin_password]
    by_env = drem("fleets", "create", "CLI port fleet", *login, cwd=tmp_path,
                  env={"DREM_STATE_DIR": str(live_stack.state_dir)})
    assert by_env.returncode == 0, by_env.stderr
    (tmp_path / ".drem").symlink_to(live_stack.state_dir)
    listed = drem("fleets", "list", *login, cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    assert "CLI port fleet" in listed.stdout
    # The classic order still works.
    before = drem("fleets", *login, "--api", live_stack.url, "list", cwd=tmp_path.parent)
    assert before.returncode == 0 and "CLI port fleet" in before.stdout


def test_sim_eval_runs_without_torch(tmp_path):
    """`make up` installs the sim extra, not torch: the registry page's `drem sim eval` must still work."""
    no_torch = tmp_path / "no-torch" / "torch"
    no_torch.mkdir(parents=True)
    (no_torch / "__init__.py").write_text('raise ModuleNotFoundError("No module named \'torch\'", name="torch")\n')
    ran = drem("sim", "eval", "--model", str(SAMPLE), "--track", "drem_oval", "--laps", "1", "--out", "eval",
               cwd=tmp_path, env={"PYTHONPATH": str(no_torch.parent)})
    assert ran.returncode == 0, ran.stderr
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert metrics["track"] == "drem_oval" and metrics["laps_completed"] == 1


def test_league_push_takes_drems_own_sample_model(live_stack, tmp_path):
    # The racer uploaded this very model before (for a race, say): the push uses that model instead of refusing the
    # identical upload.
    env = {"DREM_STATE_DIR": str(live_stack.state_dir)}
    login = ["--username", live_stack.admin_username, "--password", live_stack.admin_password]
    drem("models", "upload", str(SAMPLE), *login, cwd=tmp_path, env=env, timeout=240)  # new, or already there
    ran = drem("league", "push", str(SAMPLE), "--track", "drem_oval", *login, cwd=tmp_path, env=env, timeout=240)
    assert ran.returncode == 0, ran.stderr
    assert "drem-bc-oval.tar.gz is your model 'drem-bc-oval', uploaded before: pushing with it" in ran.stdout
    assert "pushed drem-bc-oval" in ran.stdout and "drem re-drives drem-bc-oval.tar.gz on drem_oval" in ran.stdout
    # The model came with the push: the scrutineering worker re-drives it on drem_oval and the board then ranks what
    # drem measured, marked verified.
    deadline = time.monotonic() + 240
    while True:
        board = requests.get(live_stack.url + "/api/league/drem_oval", timeout=10).json()
        entry = next(ranked["entry"] for ranked in board["entries"]
                     if ranked["entry"]["model_name"].startswith("drem-bc-oval"))
        if entry["verification"] != "pending" or time.monotonic() > deadline:
            break
        time.sleep(1)
    assert entry["verification"] == "verified", entry
    assert entry["laps_completed"] >= 1 and entry["best_lap_s"] is not None
    page = requests.get(live_stack.url + "/league/drem_oval", timeout=10).text
    assert "verified by drem" in page


def test_car_run_sim_works_in_a_fresh_clone_without_the_shared_track_files(live_stack, tmp_path):
    """No ../shared beside the clone: the real DeepRacer tracks ship inside drem_sim; the car drives re:Invent 2018."""
    token = requests.post(live_stack.url + "/api/auth/token", timeout=10, json={
        "username": live_stack.admin_username, "password": live_stack.admin_password}).json()["access_token"]
    headers = {"Authorization": f"Bearer {token}"}
    fleet = requests.post(live_stack.url + "/api/fleets", json={"name": "fresh clone"}, headers=headers,
                          timeout=10).json()
    code = requests.post(live_stack.url + "/api/devices/activation-codes", headers=headers, timeout=10, json={
        "fleet_id": fleet["fleet_id"], "hostname": "fresh-sim", "device_kind": "car"}).json()["code"]
    event = requests.post(live_stack.url + "/api/events", headers=headers, timeout=10, json={
        "name": "Fresh clone cup", "event_type": "OTHER", "date": "2026-07-01", "country_code": "SE",
        "tracks": [{"track_id": "1", "fleet_id": fleet["fleet_id"]}]}).json()
    config = tmp_path / "car"
    activated = drem("car", "activate", "--code", code, "--hostname", "fresh-sim", "--api", live_stack.url,
                     "--config-dir", str(config), cwd=tmp_path)
    assert activated.returncode == 0, activated.stderr
    # A fresh clone has no ../shared beside it. The installed `drem` runs with drem_sim as a fresh clone lays it out,
    # in a checkout under tmp_path with nothing beside it: PYTHONPATH puts that copy ahead of the editable install.
    clone = tmp_path / "fresh-clone"
    shutil.copytree(REPO / "sim" / "drem_sim", clone / "sim" / "drem_sim",
                    ignore=shutil.ignore_patterns("__pycache__"))
    fresh = {"PYTHONPATH": str(clone / "sim")}
    where = drem_python("import drem_sim.tracks as t; print(t.__file__); print(sorted(t.available_tracks()))",
                        cwd=tmp_path, env=fresh)
    assert where.returncode == 0, where.stderr
    assert where.stdout.startswith(str(clone))  # the clone's own drem_sim
    assert "reinvent_base" in where.stdout and "thunder_hill_pro" in where.stdout  # the real tracks came with it
    ran = drem("car", "--config-dir", str(config), "run", "--sim", "--seconds", "3", "--event", event["event_id"],
               "--race-track", "1", cwd=tmp_path, env=fresh)
    assert ran.returncode == 0, ran.stderr
    assert "Traceback" not in ran.stderr and "drive loop:" in ran.stdout
    # The sim car times its track with its own timing line: the timekeeper must not say there is no timer.
    desk = requests.get(f"{live_stack.url}/console/timekeeper/{event['event_id']}/1", headers=headers, timeout=10)
    assert desk.status_code == 200, desk.text[:300]
    assert "Timed by sim car fresh-sim" in desk.text and "No timer in this track" not in desk.text
