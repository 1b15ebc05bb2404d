"""The scrutineering worker's drive as the worker runs it: a child process with its bounds, on the real simulator. A
model that laps gets its report and a top-down GIF of a bounded size; a drive over its wall-clock bound is stopped
with a reason the racer can read; a folder without a graph is reported, not crashed on."""
from __future__ import annotations

import io
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
    assert report.best_lap_time_s is not None and report.offtrack_count == 0
    assert outcome.clip is not None and len(outcome.clip) <= MAX_CLIP_BYTES
    clip = Image.open(io.BytesIO(outcome.clip))
    assert clip.format == "GIF" and clip.n_frames > 10


def test_a_drive_over_its_wall_clock_bound_is_stopped_with_the_reason(tmp_path: Path) -> None:
    outcome = BoundedClipDrive(ScrutineerLimits(wall_seconds=1.0))(_model_folder(tmp_path), ["REINVENT_2018"], 3)

    assert outcome.reports == [] and outcome.clip is None
    assert outcome.failure == "the drive took longer than 1 s and was stopped"


def test_a_folder_without_a_graph_is_reported_not_crashed_on(tmp_path: Path) -> None:
    outcome = BoundedClipDrive()(_model_folder(tmp_path, with_graph=False), ["ATOZ_SPEEDWAY", "REINVENT_2018"], 1)

    assert outcome.failure is None and outcome.clip is None
    assert [r.verdict for r in outcome.reports] == ["invalid"]  # not driven on the second track either
    assert outcome.reports[0].message.startswith("cannot scrutineer:")
