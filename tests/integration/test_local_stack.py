"""`drem up` / `drem status` and the `live_stack` fixture, as a user sees them."""
from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from drem_local.commands.status import describe, gather
from drem_local.stack import free_port, http_get, read_stack_file
from tests.stack_fixtures import read_until

pytestmark = pytest.mark.integration


def test_live_stack_serves_the_app_and_its_admin_can_log_in(live_stack):
    assert http_get(live_stack.url + "/healthz")[0] == 200
    health = json.loads(http_get(live_stack.storage_url + "/_drem/health")[1])
    assert health["writable"] and health["state_dir"] == str(live_stack.state_dir.resolve())

    cognito = live_stack.client("cognito-idp")
    tokens = cognito.initiate_auth(
        ClientId=live_stack.outputs.user_pool_client_id, AuthFlow="USER_PASSWORD_AUTH",
        AuthParameters={"USERNAME": live_stack.admin_username, "PASSWORD": live_stack.admin_password})
    claims = json.loads(_b64(tokens["AuthenticationResult"]["IdToken"].split(".")[1]))
    assert "admin" in claims["cognito:groups"]
    assert live_stack.env["AWS_ENDPOINT_URL"] == live_stack.storage_url
    assert live_stack.env["DREM_USER_POOL_ID"] == live_stack.outputs.user_pool_id


def test_status_describes_a_running_stack_in_plain_words(live_stack):
    facts = gather(live_stack.state_dir)
    text = describe(facts)

    assert facts["processes"]["storage"]["alive"] and facts["app_answering"]
    assert facts["processes"]["scrutineer"]["alive"]
    assert "The scrutineering worker is running" in text
    assert f"open {live_stack.url}" in text
    assert "Admin user: admin." in text
    assert str(live_stack.state_dir.resolve()) in text


def test_status_says_nothing_runs_where_nothing_was_started(tmp_path):
    text = describe(gather(tmp_path / "never-used"))

    assert "nothing has been started here yet" in text and "drem up" in text


def _start_up(state_dir, app_port, storage_port, env=None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "drem_local.cli", "up", "--state-dir", str(state_dir),
                             "--port", str(app_port), "--storage-port", str(storage_port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)


def test_drem_up_stops_cleanly_on_ctrl_c_and_keeps_the_admin_on_restart(tmp_path):
    state_dir = tmp_path / "state"
    app_port, storage_port = free_port(), free_port()

    first = _start_up(state_dir, app_port, storage_port)
    banner = read_until(first, "Press Ctrl-C")
    assert f"http://127.0.0.1:{app_port}" in banner
    assert "Admin login:         admin / " in banner  # the generated password, shown once
    pids = read_stack_file(state_dir)["pids"]
    first.send_signal(signal.SIGINT)
    rest, _ = first.communicate(timeout=60)
    assert first.returncode == 0 and "stopped cleanly" in rest, rest

    second = _start_up(state_dir, app_port, storage_port)
    banner = read_until(second, "Press Ctrl-C")
    assert "admin (password unchanged)" in banner
    assert read_stack_file(state_dir)["pids"]["storage"] != pids["storage"]
    second.send_signal(signal.SIGTERM)
    rest, _ = second.communicate(timeout=60)
    assert second.returncode == 0 and "stopped cleanly" in rest, rest


def test_drem_up_names_the_busy_port(tmp_path):
    with socket.socket() as squatter:
        squatter.bind(("127.0.0.1", 0))
        squatter.listen()
        busy = squatter.getsockname()[1]
        result = subprocess.run([sys.executable, "-m", "drem_local.cli", "up", "--state-dir", str(tmp_path),
                                 "--port", str(free_port()), "--storage-port", str(busy)],
                                capture_output=True, text=True, timeout=60)

    assert result.returncode == 1
    assert f"port {busy} on 127.0.0.1 is already in use" in result.stderr and "--storage-port" in result.stderr


def _b64(segment: str) -> bytes:
    import base64

    return base64.urlsafe_b64decode(segment + "=" * (-len(segment) % 4))


def _drem_up(cwd, state_dir, app_port, storage_port, env) -> subprocess.Popen:
    """The installed `drem` as a user runs it, from a directory outside the repo."""
    drem = str(Path(sys.executable).with_name("drem"))
    return subprocess.Popen([drem, "up", "--state-dir", str(state_dir), "--port", str(app_port),
                             "--storage-port", str(storage_port), "--live-port", str(free_port())], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)


def test_drem_up_restarts_a_crashed_storage_server_live_server_and_app_and_the_event_goes_on(tmp_path):
    state_dir = tmp_path / "state"
    app_port, storage_port = free_port(), free_port()
    env = {**os.environ, "DREM_ADMIN_PASSWORD": "Admin-Pass-123!"}
    up = _drem_up(tmp_path, state_dir, app_port, storage_port, env)
    try:
        banner = read_until(up, "Press Ctrl-C")
        # A fresh state dir: the admin was just created with the password from the environment.
        assert "admin (created now, with the password in DREM_ADMIN_PASSWORD)" in banner
        assert "password unchanged" not in banner

        for role in ("storage", "live", "app", "scrutineer"):
            before = read_stack_file(state_dir)["pids"][role]
            os.kill(before, signal.SIGKILL)
            said = read_until(up, "is running again")
            assert "was killed by SIGKILL; restarting it in" in said, said
            assert read_stack_file(state_dir)["pids"][role] != before
            assert up.poll() is None
            deadline = time.monotonic() + 30
            while (answer := http_get(f"http://127.0.0.1:{app_port}/healthz")) is None or answer[0] != 200:
                assert time.monotonic() < deadline, answer
                time.sleep(0.1)
        live = read_stack_file(state_dir)["urls"]["live_local"]
        assert http_get(live + "/live/healthz")[0] == 200  # the restarted live server answers (its workers too)
        from drem_local.storage_keys import load, local_client

        cognito = local_client("cognito-idp", f"http://127.0.0.1:{storage_port}", load(state_dir))
        client_id = read_stack_file(state_dir)["outputs"]["user_pool_client_id"]
        cognito.initiate_auth(ClientId=client_id, AuthFlow="USER_PASSWORD_AUTH",
                              AuthParameters={"USERNAME": "admin", "PASSWORD": "Admin-Pass-123!"})
    finally:
        up.send_signal(signal.SIGTERM)
        rest, _ = up.communicate(timeout=60)
    assert up.returncode == 0 and "stopped cleanly" in rest, rest
