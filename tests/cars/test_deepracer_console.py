from __future__ import annotations

import gzip
import io
import json
import tarfile
from pathlib import Path

import pytest

from drem_cars.drivers.deepracer_console import ConsoleError, DeepRacerConsole, DeepRacerConsoleDriver
from drem_cars.model_files import ModelError
from drem_cars.model_store import ARCHIVE_COPY, InstalledModel
from tests.cars.fake_deepracer_console import FakeConsole

pytestmark = pytest.mark.unit


def console_model(tmp_path: Path, member: str) -> InstalledModel:
    folder = tmp_path / "racer-fast"
    (folder / "agent").mkdir(parents=True)
    (folder / member).write_bytes(b"graph")
    (folder / "model_metadata.json").write_text(json.dumps({"action_space": []}))
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as tar:
        info = tarfile.TarInfo(member)
        info.size = 5
        tar.addfile(info, io.BytesIO(b"graph"))
    (folder / ARCHIVE_COPY).write_bytes(gzip.compress(buffer.getvalue()))
    return InstalledModel(model_id="m1", name="fast", folder="racer-fast", archive_md5="0" * 32, path=folder)


def test_driver_logs_in_with_csrf_uploads_loads_and_drives(tmp_path: Path) -> None:
    with FakeConsole() as fake:
        driver = DeepRacerConsoleDriver(DeepRacerConsole(fake.url, "car-password"))
        model = console_model(tmp_path, "agent/model.pb")
        driver.load_model(model)
        driver.set_throttle_cap(40)
        driver.set_tail_light("#FFA500")
        driver.emergency_stop()
        assert driver.battery_pct() == 70.0
        assert fake.state.uploads["racer-fast"] == (model.path / ARCHIVE_COPY).read_bytes()
        assert fake.state.calls == [
            ("PUT", "/api/uploadModels", "racer-fast.tar.gz"), ("PUT", "/api/models/racer-fast/model.pb", None),
            ("PUT", "/api/drive_mode", {"drive_mode": "auto"}), ("PUT", "/api/max_nav_throttle", {"throttle": 40}),
            ("POST", "/api/set_led_color", {"red": 255, "green": 165, "blue": 0}),
            ("PUT", "/api/start_stop", {"start_stop": "stop"})]


def test_wrong_password_is_a_clear_error() -> None:
    with FakeConsole() as fake:
        with pytest.raises(ConsoleError, match="refused the password"):
            DeepRacerConsole(fake.url, "nope").login()


def test_an_onnx_model_is_refused_for_the_console_without_calling_it(tmp_path: Path) -> None:
    with FakeConsole() as fake:
        driver = DeepRacerConsoleDriver(DeepRacerConsole(fake.url, "car-password"))
        with pytest.raises(ModelError, match="TensorFlow models only"):
            driver.load_model(console_model(tmp_path, "model.onnx"))
        assert fake.state.calls == []


def test_a_call_without_the_csrf_header_is_refused_by_the_console() -> None:
    with FakeConsole() as fake:
        console = DeepRacerConsole(fake.url, "car-password")
        console.login()
        console.csrf_token = "forged"
        with pytest.raises(ConsoleError, match="CSRF token is missing or invalid"):
            console.start_stop(False)
