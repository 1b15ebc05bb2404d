"""drem on an organiser's own laptop: a copy of the repository with nothing of ours beside it (no ../shared, and the
wheel folder pointed at a path that does not exist), installed with `make install` from the runtime lock into its own
fresh venv, started with its own `drem up`, then a console model and a drem model uploaded with its own `drem models
upload` and test-driven on every DREM event track type. Each drive must end in a verdict (passed or failed), never in
"could not scrutineer": the real tracks ship inside drem.

The test data (the console model) comes from ../shared, as test data does; the product under test never sees it.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest
import requests

from drem_leaderboard.models import TrackType
from drem_local import stack as local_stack
from tests import console_fixture
from tests.waiting import wait_until

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
DREM_SAMPLE = REPO_ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
NO_WHEELS = "/nonexistent/wheel-folder"
ADMIN, PASSWORD = "organiser", "Organiser-laptop-2026"


def copy_of_the_repository(target: Path) -> Path:
    """What `git clone` gives: the tracked files (and new ones not yet committed), none of the build output."""
    listed = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=REPO_ROOT,
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        source = REPO_ROOT / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


@pytest.fixture(scope="module")
def laptop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    home = tmp_path_factory.mktemp("organiser")
    clone = copy_of_the_repository(home / "drem")
    assert not (home / "shared").exists()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "DREM_TRACKS_DIR")}
    installed = subprocess.run(["make", "--no-print-directory", "install", f"WHEELS={NO_WHEELS}"], cwd=clone, env=env,
                               capture_output=True, text=True, timeout=900)
    assert installed.returncode == 0, installed.stdout[-3000:] + installed.stderr[-3000:]
    assert "--find-links" not in installed.stdout, "no wheel folder is named when it does not exist"
    return clone


def test_the_runtime_venv_has_no_torch_and_its_drem_is_the_copy(laptop: Path) -> None:
    python = laptop / ".venv" / "bin" / "python"
    probe = subprocess.run([str(python), "-c", "import importlib.util as u, drem_sim.tracks as t; "
                            "print(u.find_spec('torch') is None); print(t.__file__); print(len(t.available_tracks()))"],
                           cwd=laptop.parent, capture_output=True, text=True, timeout=120)
    assert probe.returncode == 0, probe.stderr
    no_torch, tracks_module, count = probe.stdout.split()
    assert no_torch == "True", "the runtime lock needs no torch"
    assert tracks_module.startswith(str(laptop)), "drem_sim is the copy's own"
    assert int(count) == 24, "22 real DeepRacer tracks and drem's two"


@pytest.fixture(scope="module")
def running(laptop: Path) -> Iterator[str]:
    ports = [local_stack.free_port() for _ in range(3)]
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "DREM_TRACKS_DIR")}
    env.update(DREM_ADMIN_USERNAME=ADMIN, DREM_ADMIN_PASSWORD=PASSWORD)
    log = (laptop.parent / "drem-up.log").open("w")
    process = subprocess.Popen([str(laptop / ".venv" / "bin" / "drem"), "up", "--state-dir", str(laptop / ".drem"),
                                "--port", str(ports[0]), "--storage-port", str(ports[1]), "--live-port",
                                str(ports[2]), "--no-trainer"], cwd=laptop, env=env, stdout=log,
                               stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{ports[0]}"
    try:
        wait_until(lambda: process.poll() is not None or local_stack.http_get(url + "/healthz") is not None,
                   240, "drem up on the laptop to answer /healthz")
        assert process.poll() is None, (laptop.parent / "drem-up.log").read_text()[-3000:]
        yield url
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()
        log.close()


def upload(laptop: Path, url: str, archive: Path) -> str:
    done = subprocess.run([str(laptop / ".venv" / "bin" / "drem"), "models", "upload", str(archive), "--api", url,
                           "--username", ADMIN, "--password", PASSWORD], cwd=laptop.parent, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    token = requests.post(url + "/api/auth/token", json={"username": ADMIN, "password": PASSWORD},
                          timeout=30).json()["access_token"]
    models = requests.get(url + "/api/models", headers={"Authorization": f"Bearer {token}"}, timeout=30).json()
    name = archive.name.removesuffix(".tar.gz")
    found = [m for m in models["models"] if m["name"] == name]
    assert found and found[0]["status"] == "AVAILABLE", (done.stdout, found)
    return found[0]["model_id"]


@pytest.mark.parametrize("archive", [console_fixture.ARCHIVE, DREM_SAMPLE], ids=["console model", "drem model"])
def test_a_model_gets_a_verdict_on_every_event_track_type(laptop: Path, running: str, archive: Path,
                                                          tmp_path: Path) -> None:
    source = console_fixture.require_fixture() if archive == console_fixture.ARCHIVE else archive
    named = tmp_path / f"laptop-{'console' if archive == console_fixture.ARCHIVE else 'drem'}.tar.gz"
    shutil.copy(source, named)
    model_id = upload(laptop, running, named)
    token = requests.post(running + "/api/auth/token", json={"username": ADMIN, "password": PASSWORD},
                          timeout=30).json()["access_token"]
    verdicts = {}
    for track_type in TrackType:
        answer = requests.post(f"{running}/api/models/{model_id}/scrutineer", timeout=180,
                               headers={"Authorization": f"Bearer {token}"},
                               json={"track_type": track_type.value, "laps": 1})
        assert answer.status_code == 200, (track_type, answer.text[:500])
        result = answer.json()["model"]["scrutineer_result"]
        verdicts[track_type.value] = result["verdict"]
        assert result["verdict"] in ("passed", "failed"), (track_type, result)
        assert result["track"], "it names the simulator track it drove"
    assert set(verdicts) == {t.value for t in TrackType}
