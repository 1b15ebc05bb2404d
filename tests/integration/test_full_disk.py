"""The state dir on a disk that fills up, then a crash: what the desk, the API and `drem status` say, and what
survives.

The disk is a real one: a small tmpfs mounted for the test (root only), filled to the last byte with a file. On it:
- a racer registered while snapshots fail is acknowledged (the journal's reserved room takes it), and after kill -9
  of everything and a restart it has the same identity (`sub`): the board never lists it twice;
- `drem status` says the disk is full, where, what to do, and that writes still go into the journal's room;
- once that room is used up a write is refused with 507 and "drem's data disk is full at <path>: free space, then …",
  by the storage server and by the API, and nothing acknowledged before is lost.
"""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from botocore.exceptions import ClientError

from drem_local.api_client import ApiClient, ApiError
from drem_local.commands.status import describe, gather
from drem_local.stack import HEALTH_PATH, StackConfig, free_port, http_get, start_stack
from drem_local.storage_keys import load, local_client
from tests.chaos_disk import fill, mount_small_disk, unmount
from tests.stack_fixtures import read_until

pytestmark = [pytest.mark.integration, pytest.mark.durability]

PASSWORD = "Disk-Admin-Pass-1!"
BUCKET_OBJECT_BYTES = 256 * 1024


@pytest.fixture
def small_disk(tmp_path):
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root; run this test as root (CI does)")
    mount = tmp_path / "disk"
    problem = mount_small_disk(mount, "48m")
    assert problem is None, problem
    try:
        yield mount
    finally:
        unmount(mount)


def _register(admin: ApiClient, username: str) -> str:
    return admin.post("/api/users", {"username": username, "email": f"{username}@example.com",
                                     "country_code": "SE"})["sub"]


def _subs(admin: ApiClient) -> dict[str, str]:
    return {user["username"]: user["sub"] for user in admin.get("/api/users")["users"]}


def _health(url: str) -> dict:
    answer = http_get(url + HEALTH_PATH)
    assert answer is not None and answer[0] == 200
    return json.loads(answer[1])


def test_a_full_disk_is_said_in_words_and_nothing_acknowledged_changes_after_a_crash(small_disk):
    state_dir = small_disk / "state"
    config = StackConfig(state_dir=state_dir, app_port=free_port(), storage_port=free_port(), live_port=free_port(),
                         snapshot_interval=0.5)
    running = start_stack(config, "admin", PASSWORD, timeout=120)
    filler = None
    try:
        admin = ApiClient(config.app_local_url)
        admin.login("admin", PASSWORD)
        before_sub = _register(admin, "early-racer")
        s3 = local_client("s3", config.storage_url, load(state_dir))
        s3.create_bucket(Bucket="disk-test")

        filler = fill(small_disk)
        during_sub = _register(admin, "full-disk-racer")  # its account's immediate snapshot fails: no room for it

        disk = _health(config.storage_url)["disk"]
        assert disk["problem"] == "full" and disk["writes"] == "journal-only", disk
        status = describe(gather(state_dir))
        assert f"drem's data disk is full at {state_dir.resolve()}: free space on that disk" in status, status
        assert "still accepted, into the journal's reserved room" in status, status

        stored: dict[str, str] = {}
        for size in (BUCKET_OBJECT_BYTES, 16 * 1024, 1024, 16):  # until not even 16 bytes fit in the journal's room
            with pytest.raises(ClientError) as refused:
                for number in range(1000):  # the journal's room is 4 MiB: it runs out long before this
                    key, body = f"object-{size}-{number}", os.urandom(size)
                    s3.put_object(Bucket="disk-test", Key=key, Body=body)
                    stored[key] = hashlib.md5(body).hexdigest()
        assert refused.value.response["ResponseMetadata"]["HTTPStatusCode"] == 507
        assert refused.value.response["Error"]["Code"] == "DremDataDiskFull"
        assert f"drem's data disk is full at {state_dir.resolve()}" in refused.value.response["Error"]["Message"]
        assert stored, "the journal's room took no write at all"

        with pytest.raises(ApiError) as api_refused:
            admin.post("/api/events", {"name": "No room cup", "event_type": "OTHER", "date": "2026-07-01",
                                       "country_code": "SE", "tracks": [{"track_id": "1"}]})
        assert api_refused.value.status == 507, api_refused.value
        assert f"drem's data disk is full at {state_dir.resolve()}: free space" in api_refused.value.message
        status = describe(gather(state_dir))
        assert "Writes right now: REFUSED" in status, status

        # A power cut while the disk is full, then someone frees space and drem starts again.
        for process in (running.scrutineer, running.trainer, running.app, running.live, running.storage):
            if process is not None:
                process.kill_hard()
        filler.unlink()
        running.restart_storage(120)
        running.restart_app(120)

        admin = ApiClient(config.app_local_url)
        admin.login("admin", PASSWORD)
        subs = _subs(admin)
        assert subs["early-racer"] == before_sub
        assert subs["full-disk-racer"] == during_sub  # the same identity: never redrawn by the replay
        for key, md5 in stored.items():
            assert hashlib.md5(s3.get_object(Bucket="disk-test", Key=key)["Body"].read()).hexdigest() == md5
        assert _health(config.storage_url)["disk"]["writes"] == "accepted"
    finally:
        if filler is not None:
            filler.unlink(missing_ok=True)
        running.stop()


def _drem_up(state_dir: Path, cwd: Path) -> subprocess.CompletedProcess:
    drem = str(Path(sys.executable).with_name("drem"))
    return subprocess.run([drem, "up", "--state-dir", str(state_dir), "--port", str(free_port()), "--storage-port",
                           str(free_port()), "--live-port", str(free_port()), "--no-trainer"], cwd=cwd,
                          capture_output=True, text=True, timeout=600,
                          env={**os.environ, "DREM_ADMIN_PASSWORD": PASSWORD})


def test_drem_up_on_a_full_or_read_only_disk_says_so_instead_of_a_traceback(small_disk, tmp_path):
    state_dir = small_disk / "state"
    config = StackConfig(state_dir=state_dir, app_port=free_port(), storage_port=free_port(), live_port=free_port())
    start_stack(config, "admin", PASSWORD, timeout=120).stop()

    filler = fill(small_disk)
    full = _drem_up(state_dir, tmp_path)
    assert full.returncode == 1, full.stdout + full.stderr
    assert f"drem's data disk is full at {state_dir.resolve()}: free space on that disk" in full.stderr, full.stderr
    assert "Traceback" not in full.stdout + full.stderr
    filler.unlink()

    subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    read_only = _drem_up(state_dir, tmp_path)
    assert read_only.returncode == 1, read_only.stdout + read_only.stderr
    assert f"drem's data disk is read-only at {state_dir.resolve()}: make it writable again" in read_only.stderr, \
        read_only.stderr
    assert "Traceback" not in read_only.stdout + read_only.stderr
    assert f"drem's data disk is read-only at {state_dir.resolve()}" in describe(gather(state_dir))

    subprocess.run(["mount", "-o", "remount,rw", str(small_disk)], check=True)
    again = subprocess.Popen([str(Path(sys.executable).with_name("drem")), "up", "--state-dir", str(state_dir),
                              "--port", str(config.app_port), "--storage-port", str(config.storage_port),
                              "--live-port", str(free_port()), "--no-trainer"], cwd=tmp_path,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             env={**os.environ, "DREM_ADMIN_PASSWORD": PASSWORD})
    try:
        banner = read_until(again, "Press Ctrl-C", timeout=300)  # once the disk is fixed, it simply starts
        assert "admin (password set from DREM_ADMIN_PASSWORD)" in banner or "password unchanged" in banner, banner
    finally:
        again.send_signal(signal.SIGTERM)
        rest, _ = again.communicate(timeout=120)
    assert again.returncode == 0, rest
