"""The scrutineering worker's drive as the worker runs it: a child process with its bounds, on the real simulator. A
model that laps gets its report and a top-down GIF of a bounded size; a drive over its wall-clock bound is stopped
with a reason the racer can read; a folder without a graph is reported, not crashed on."""
from __future__ import annotations

import io
import re
import shutil
import tarfile
from pathlib import Path

import pytest
from PIL import Image

from drem_local.workers.scrutineer import BoundedClipDrive, ScrutineerLimits
from drem_local.workers.scrutineer_drive import MAX_CLIP_BYTES

pytestmark = pytest.mark.sim

SAMPLE = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"


def _model_folder(tmp_path: Path, *, with_graph: bool = True) -> Path:
    folder = tmp_path / "model"
    folder.mkdir()
    with tarfile.open(SAMPLE) as tar:
        for member in tar.getmembers():
            name = member.name.removeprefix("./")
            if name in ("model_metadata.json", "model.onnx") and (with_graph or name != "model.onnx"):
                (folder / name).write_bytes(tar.extractfile(member).read())  # type: ignore[union-attr]
    return folder


def test_a_model_that_laps_gets_its_figures_and_a_bounded_animated_clip(tmp_path: Path) -> None:
    outcome = BoundedClipDrive()(_model_folder(tmp_path), ["REINVENT_2018"], 2)

    assert outcome.failure is None and len(outcome.reports) == 1
    report = outcome.reports[0]
    assert report.verdict == "passed" and report.track == "reinvent_base" and report.laps_completed == 2
    assert (report.attempts, report.completion_pct) == (2, 100.0)  # what a league re-drive's board entry shows
    assert report.best_lap_time_s is not None and report.offtrack_count == 0
    assert outcome.clip is not None and len(outcome.clip) <= MAX_CLIP_BYTES
    clip = Image.open(io.BytesIO(outcome.clip))
    assert clip.format == "GIF" and clip.n_frames > 10


def test_a_drive_over_its_wall_clock_bound_is_stopped_with_the_reason(tmp_path: Path) -> None:
    # 0.3 s: less than starting the drive's process and loading its model takes, however fast the simulator is.
    outcome = BoundedClipDrive(ScrutineerLimits(wall_seconds=0.3))(_model_folder(tmp_path), ["REINVENT_2018"], 3)

    assert outcome.reports == [] and outcome.clip is None
    assert outcome.failure is not None and outcome.failure.startswith("The test drive took longer than 0.3 s")
    assert "Drive again" in outcome.failure and outcome.failure_detail == "wall-clock limit of 0.3 s reached"


def test_a_folder_without_a_graph_is_reported_not_crashed_on(tmp_path: Path) -> None:
    outcome = BoundedClipDrive()(_model_folder(tmp_path, with_graph=False), ["ATOZ_SPEEDWAY", "REINVENT_2018"], 1)

    assert outcome.failure is None and outcome.clip is None
    assert [r.verdict for r in outcome.reports] == ["invalid"]  # not driven on the second track either
    assert outcome.reports[0].message.startswith("drem could not read the model inside this archive")
    assert "model.onnx" in (outcome.reports[0].detail or "")


CODE_NAMES = re.compile(r"\b[A-Za-z_.]*(Error|Exception|Traceback)\b|\w+\.\w+\.\w+")


def test_a_damaged_track_file_is_told_in_words_naming_the_track(tmp_path: Path, monkeypatch) -> None:
    import numpy as np

    import drem_sim.tracks as tracks
    from drem_local.workers.scrutineer_drive import drive_track

    damaged = tmp_path / "tracks"
    shutil.copytree(tracks.PACKAGE_TRACKS_DIR, damaged)
    data = np.load(damaged / "reInvent2019_wide.npy")
    np.save(damaged / "reInvent2019_wide.npy", data[::-1])  # reordered bytes: no longer the checksummed file
    monkeypatch.setattr(tracks, "PACKAGE_TRACKS_DIR", damaged)

    report, track, path = drive_track(_model_folder(tmp_path), "ATOZ_SPEEDWAY", 1)

    assert report["verdict"] == "cannot_scrutineer" and track is None and path == []
    assert "“reInvent2019_wide”" in report["message"] and "tell the staff" in report["message"]
    assert not CODE_NAMES.search(report["message"]), report["message"]
    assert "TrackError" in report["detail"] and "checksum" in report["detail"]


def test_a_graph_onnxruntime_refuses_is_told_in_words_with_the_detail_for_staff(tmp_path: Path) -> None:
    folder = _model_folder(tmp_path)
    (folder / "model.onnx").write_bytes(b"\x08\x07not-a-graph")

    outcome = BoundedClipDrive()(folder, ["REINVENT_2018"], 1)

    report = outcome.reports[0]
    assert report.verdict in ("cannot_scrutineer", "invalid")
    assert not CODE_NAMES.search(report.message), report.message
    assert report.detail, "staff get what the software said"


def test_a_league_re_drive_names_the_track_it_drives(tmp_path: Path) -> None:
    """The league's re-drive (domain/league_intake.LeagueVerifier) drives the board's track by its name."""
    outcome = BoundedClipDrive()(_model_folder(tmp_path), [], 1, track="reinvent_base")

    assert outcome.failure is None and len(outcome.reports) == 1
    report = outcome.reports[0]
    assert report.track == "reinvent_base" and report.track_type == "LEAGUE"
    assert report.verdict == "passed" and report.laps_completed == 1 and report.best_lap_time_s is not None
