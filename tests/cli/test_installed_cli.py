"""Every `drem` subcommand, run the way docs/ tell users to: the installed entry point, as a subprocess, from a
directory outside the repository, with no PYTHONPATH. In-process tests (calling `run()`) cannot see an import that
only works because pytest put functions/ on sys.path; these can.
"""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import requests

from drem_local import stack as local_stack
from drem_local.cli import SUBCOMMANDS
from tests.browser.console_api import PASSWORD, create_user

pytestmark = pytest.mark.integration

DREM = Path(sys.executable).parent / "drem"
REPO_ROOT = Path(__file__).resolve().parents[2]
SAMPLE_MODEL = REPO_ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-oval.tar.gz"


def drem(*args: str, cwd: Path, env: dict[str, str] | None = None, timeout: float = 120) -> subprocess.CompletedProcess:
    """The installed `drem`, from `cwd` (outside the repo), with the user's environment minus any PYTHONPATH or
    DREM_STAGE (a stage of the caller's would pick another deployment record)."""
    assert REPO_ROOT not in cwd.resolve().parents, "these tests must run from outside the repository"
    full_env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DREM_STAGE")}
    full_env.update(env or {})
    return subprocess.run([str(DREM), *args], cwd=cwd, env=full_env, capture_output=True, text=True,
                          timeout=timeout)


def ok(result: subprocess.CompletedProcess) -> str:
    assert result.returncode == 0, f"exit {result.returncode}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert "Traceback" not in result.stderr, result.stderr
    return result.stdout


@pytest.fixture(scope="module")
def as_admin(live_stack) -> dict[str, str]:
    """The connection a staff member gives the CLI: the API URL and their sign-in, through the environment."""
    return {"DREM_API": live_stack.url, "DREM_USERNAME": live_stack.admin_username,
            "DREM_PASSWORD": live_stack.admin_password}


@pytest.fixture(scope="module")
def outside(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("user-home")


@pytest.mark.parametrize("subcommand", sorted(SUBCOMMANDS))
def test_every_subcommand_starts_from_outside_the_repo(subcommand: str, outside: Path) -> None:
    out = ok(drem(subcommand, "--help", cwd=outside))
    assert out.startswith("usage: drem " + subcommand)


def test_top_level_help_lists_every_subcommand(outside: Path) -> None:
    out = drem("--help", cwd=outside).stdout
    for name in SUBCOMMANDS:
        assert re.search(rf"^\s+{re.escape(name)}\s", out, re.M), f"{name} missing from drem --help"


def test_up_serves_and_stops_cleanly_on_ctrl_c(outside: Path, tmp_path: Path) -> None:
    app_port, storage_port, live_port = local_stack.free_port(), local_stack.free_port(), local_stack.free_port()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    process = subprocess.Popen([str(DREM), "up", "--state-dir", str(tmp_path / "state"), "--port", str(app_port),
                                "--storage-port", str(storage_port), "--live-port", str(live_port)], cwd=outside,
                               env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen: list[str] = []
    try:
        # Wait for the banner a user waits for (the app may answer before `drem up` has finished starting).
        for line in process.stdout:  # type: ignore[union-attr]
            seen.append(line)
            if "Press Ctrl-C" in line:  # the banner's last line
                break
        assert "drem is running" in "".join(seen), "".join(seen)
        assert requests.get(f"http://127.0.0.1:{app_port}/api/ping", timeout=5).status_code == 200
        # The live server is one of drem up's children: announced, answering, and named by drem status.
        assert f"Live pages:          http://127.0.0.1:{live_port}" in "".join(seen), "".join(seen)
        assert requests.get(f"http://127.0.0.1:{live_port}/live/healthz", timeout=5).json()["ok"] is True
        status = ok(drem("status", "--state-dir", str(tmp_path / "state"), cwd=outside))
        assert f"live server is pushing the public pages at http://127.0.0.1:{live_port}" in status, status
        # The learning booth's trainer is one of drem up's children, shown by drem status.
        assert "The learning booth's trainer is running" in status, status
        trainer_pid = json.loads(ok(drem("status", "--state-dir", str(tmp_path / "state"), "--json",
                                         cwd=outside)))["processes"]["trainer"]["pid"]
    finally:
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=60)
    out = "".join(seen) + out
    assert process.returncode == 0, out
    assert "Traceback" not in out and "stopped cleanly" in out, out
    assert not local_stack.pid_is_drem(trainer_pid)  # stopped with the rest
    assert local_stack.http_get(f"http://127.0.0.1:{live_port}/live/healthz") is None  # stopped with the rest


def test_status_reports_the_running_stack(live_stack, outside: Path) -> None:
    facts = json.loads(ok(drem("status", "--state-dir", str(live_stack.state_dir), "--json", cwd=outside)))
    assert str(live_stack.url.rsplit(":", 1)[1]) in json.dumps(facts)


def test_users_events_fleets_cars_and_devices(live_stack, as_admin, outside: Path, tmp_path: Path) -> None:
    created = ok(drem("users", "create", "cli-racer-1", "--email", "cli1@example.com", "--country", "SE",
                      cwd=outside, env=as_admin))
    assert "cli-racer-1" in created and "password" in created.lower()
    assert "cli-racer-1" in ok(drem("users", "list", "--prefix", "cli-", cwd=outside, env=as_admin))

    fleet = json.loads(ok(drem("fleets", "--json", "create", "cli-fleet", cwd=outside, env=as_admin)))
    fleet_id = fleet["fleet_id"]
    assert "cli-fleet" in ok(drem("fleets", "list", cwd=outside, env=as_admin))

    event = json.loads(ok(drem("events", "--json", "create", "CLI Cup", "--date", "2026-11-24", "--country", "SE",
                               "--track", f"Main@{fleet_id}", cwd=outside, env=as_admin)))
    assert "CLI Cup" in ok(drem("events", "list", cwd=outside, env=as_admin))

    code = json.loads(ok(drem("cars", "--json", "activate-code", "cli-timer", "--fleet", fleet_id, "--kind", "timer",
                              cwd=outside, env=as_admin)))
    config = tmp_path / "timer-config"
    ok(drem("car", "--config-dir", str(config), "activate", "--code", code["code"], "--api", live_stack.url,
            "--hostname", "cli-timer", "--kind", "timer", cwd=outside))
    assert "cli-timer" in ok(drem("car", "--config-dir", str(config), "status", cwd=outside))
    # A laptop has no GPIO: gpiozero's mock pins stand in for the strips, the agent talks to the real stack.
    timed = ok(drem("timer", "--config-dir", str(config), "--event", event["event_id"], "--seconds", "2",
                    cwd=outside, env={"GPIOZERO_PIN_FACTORY": "mock"}))
    assert "crossings queued 0" in timed
    assert "cli-timer" in ok(drem("cars", "list", cwd=outside, env=as_admin))


def test_models_upload_and_list(live_stack, outside: Path) -> None:
    # A racer of this test's own: other tests of the session upload the same sample, and a second identical upload by
    # one account is refused (its first copy is kept).
    as_racer = {"DREM_API": live_stack.url, "DREM_USERNAME": create_user(live_stack, "cli-uploader", "racer"),
                "DREM_PASSWORD": PASSWORD}
    uploaded = ok(drem("models", "upload", str(SAMPLE_MODEL), cwd=outside, env=as_racer, timeout=180))
    assert "drem-bc-oval" in uploaded
    listed = ok(drem("models", "list", cwd=outside, env=as_racer))
    assert "drem-bc-oval" in listed and "Ready to race" in listed and "AVAILABLE" not in listed


def test_export_then_import_under_a_new_id(live_stack, as_admin, outside: Path, tmp_path: Path) -> None:
    event = json.loads(ok(drem("events", "--json", "create", "Exported Cup", "--date", "2026-11-24",
                               "--country", "GB", cwd=outside, env=as_admin)))
    folder = tmp_path / "export"
    exported = ok(drem("export", event["event_id"], "--out", str(folder), "--state-dir", str(live_stack.state_dir),
                       cwd=outside))
    assert f"Exported event {event['event_id']}" in exported and (folder / "manifest.json").is_file()
    imported = ok(drem("import", str(folder), "--event-id", "exported-cup-copy",
                       "--state-dir", str(live_stack.state_dir), "--report", str(tmp_path / "report.json"),
                       cwd=outside))
    assert "as exported-cup-copy" in imported
    assert "Exported Cup" in ok(drem("events", "show", "exported-cup-copy", cwd=outside, env=as_admin))


def test_export_and_import_count_the_same_races(live_stack, as_admin, outside: Path, tmp_path: Path) -> None:
    """Issue 31: export reported 25 races and import 26 (the audit entry of a lap edit was counted as a race)."""
    url = live_stack.url
    bearer = {"Authorization": "Bearer " + requests.post(url + "/api/auth/token", timeout=10, json={
        "username": live_stack.admin_username, "password": live_stack.admin_password}).json()["access_token"]}

    def api(method: str, path: str, body: dict) -> dict:
        reply = requests.request(method, url + path, json=body, headers=bearer, timeout=15)
        assert reply.status_code in (200, 201), reply.text
        return reply.json()

    api("POST", "/api/users", {"username": "cli-count", "email": "count@example.test", "country_code": "GB"})
    event = api("POST", "/api/events", {"name": "Counted Cup", "event_type": "OFFICIAL_TRACK_RACE",
                                        "date": "2026-11-25", "country_code": "GB"})
    for _ in range(2):
        race = api("POST", f"/api/events/{event['event_id']}/races", {"track_id": "1", "racer_username": "cli-count"})
        path = f"/api/events/{event['event_id']}/races/{race['race_id']}"
        for kind in ("start", "capture_lap", "end", "submit"):
            api("POST", path + "/commands", {"kind": kind})
    api("PUT", path + "/laps/0", {"time_ms": 9_500, "is_valid": True})  # race admin's lap edit: an audit entry

    folder = tmp_path / "counted"
    exported = ok(drem("export", event["event_id"], "--out", str(folder), "--state-dir", str(live_stack.state_dir),
                       cwd=outside))
    imported = ok(drem("import", str(folder), "--event-id", "counted-cup-copy", "--state-dir",
                       str(live_stack.state_dir), "--report", str(tmp_path / "counted.json"), cwd=outside))
    exported_races = re.search(r"\b(\d+) races\b", exported)
    imported_races = re.search(r"\b(\d+) races\b", imported)
    assert exported_races and imported_races, (exported, imported)
    assert exported_races.group(1) == imported_races.group(1) == "2", (exported, imported)


def test_league_pull_answers_for_a_track(as_admin, outside: Path) -> None:
    board = json.loads(ok(drem("league", "pull", "--track", "reinvent_base", "--json", cwd=outside, env=as_admin)))
    assert isinstance(board, (dict, list))


def test_sim_record_then_train_a_model(outside: Path, tmp_path: Path) -> None:
    assert "drem_oval" in ok(drem("sim", "tracks", cwd=outside))
    runs = tmp_path / "runs"
    ok(drem("sim", "record", "--track", "drem_oval", "--laps", "1", "--out", str(runs), cwd=outside, timeout=240))
    out = tmp_path / "model"
    ok(drem("train", "--runs", str(runs), "--out", str(out), "--name", "cli-model", "--epochs", "1",
            cwd=outside, timeout=300))
    assert (out / "cli-model.tar.gz").is_file()


def test_build_vendors_the_shared_packages_into_a_copy(outside: Path, tmp_path: Path) -> None:
    functions = tmp_path / "functions"
    functions.mkdir()
    out = ok(drem("build", "--functions-dir", str(functions), cwd=outside))
    assert "vendored drem_leaderboard" in out and (functions / "vendor" / "drem_leaderboard").is_dir()


def test_a_command_finds_the_stack_by_its_state_dir_and_registers_a_real_name(live_stack, outside: Path) -> None:
    """Issue 31: with `--state-dir` and no $DREM_API/$DREM_STATE_DIR, `drem users` said "cannot reach
    http://127.0.0.1:8000" while the stack ran on another port."""
    env = {"DREM_API": "", "DREM_STATE_DIR": "", "DREM_USERNAME": live_stack.admin_username,
           "DREM_PASSWORD": live_stack.admin_password}
    created = ok(drem("users", "create", "cli-yamada", "--email", "yamada@example.com", "--country", "JP",
                      "--display-name", "山田太郎", "--state-dir", str(live_stack.state_dir), cwd=outside, env=env))
    assert "Created racer cli-yamada for 山田太郎 (JP)." in created


def test_car_run_says_it_started_and_where_it_reports(live_stack, as_admin, outside: Path, tmp_path: Path) -> None:
    """Issue 31: `drem car run` printed nothing when it started."""
    fleet = json.loads(ok(drem("fleets", "--json", "create", "cli-run-fleet", cwd=outside, env=as_admin)))
    code = json.loads(ok(drem("cars", "--json", "activate-code", "cli-run-car", "--fleet", fleet["fleet_id"],
                              "--kind", "car", cwd=outside, env=as_admin)))
    config = tmp_path / "car-config"
    ok(drem("car", "--config-dir", str(config), "activate", "--code", code["code"], "--api", live_stack.url,
            "--hostname", "cli-run-car", "--kind", "car", cwd=outside))
    # A crossing the car recorded for an event the server does not know (as after the event was deleted): refused.
    from drem_cars.outbox import STRIP_EVENT, Outbox

    waiting = Outbox(config / "outbox.sqlite3")
    waiting.enqueue(STRIP_EVENT, {"event_id": "no-such-event", "track_id": "1", "timestamp_ms": 1_700_000_000_000,
                                  "sensor": 17}, "cli-refused-1")
    waiting.close()
    result = drem("car", "--config-dir", str(config), "run", "--sim", "--seconds", "1", cwd=outside)
    ran = ok(result)
    first = ran.splitlines()[0]
    assert first.startswith("drem car run: cli-run-car (car ") and f"reporting to {live_stack.url}" in first, ran
    assert "1 crossing(s) waiting to be sent" in first, ran
    # Issue 31: a refused crossing showed only in `drem car status`; it is said where the agent runs.
    assert "drem car: the server refused strip_event #1" in result.stderr, result.stderr
