"""`drem car run` as staff start it: a camera size or rate it cannot send is refused in words before anything runs."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from drem_cars.credentials import CredentialStore, StoredCredential

DREM = Path(sys.executable).parent / "drem"


@pytest.mark.parametrize(("option", "value", "said"), [
    ("--video-size", "480", "WIDTHxHEIGHT, e.g. 480x360"),
    ("--video-size", "4000x3000", "16..1920 by 16..1080"),
    ("--video-fps", "99", "1 to 30 frames a second"),
])
def test_a_camera_setting_the_car_cannot_send_is_refused_in_words(tmp_path: Path, option: str, value: str,
                                                                 said: str) -> None:
    CredentialStore(tmp_path).save(StoredCredential(api="http://127.0.0.1:9", device_id="car-1", device_kind="car",
                                                    hostname="car-1", fleet_id=None, credential="car-1.secret"))
    result = subprocess.run([str(DREM), "car", "--config-dir", str(tmp_path), "run", "--sim", option, value],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2
    assert said in result.stderr
