"""A booth drive as the app holds it, for tests of what a kill -9 leaves behind."""
from __future__ import annotations

from pathlib import Path
from typing import Any

DRIVE_STEPS = 7


def drive_lost_by_a_kill(drives: Path) -> tuple[Any, Any, str, Path]:
    """alice drives DRIVE_STEPS decisions on drem_oval, then the app process forgets the drive (as a killed app does)
    while its folder stays under `drives`. Returns (the drive service, alice, the run id, the run's folder)."""
    from chalicelib import services
    from chalicelib.core.principals import User
    from chalicelib.domain.booth_drive import DriveControl, DriveService, LiveDrives, StartDrive

    live = LiveDrives()
    service = DriveService(live, services.run_service(), drives)
    racer = User(sub="alice-sub", username="alice", groups=frozenset({"racer"}))
    run_id = service.start(racer, StartDrive(track_id="drem_oval"))["run_id"]
    for _ in range(DRIVE_STEPS):
        service.step(racer, run_id, DriveControl(throttle=1.0))
    assert live.pop(run_id) is not None
    folder = next((drives / run_id).rglob("controls.jsonl")).parent
    return service, racer, run_id, folder
