"""Run folders: layout, rows a dataset can learn from, and an S3 round trip (moto in-process)."""
from __future__ import annotations

import io
import json
import tarfile

import boto3
import cv2
import pytest
from moto import mock_aws

from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.runs import RunError, download_run, record_run, unpack_frames, upload_run

pytestmark = pytest.mark.sim

PNG_MAGIC = b"\x89PNG\r\n\x1a\n" + bytes(20)
ROW_KEYS = {"index", "frame", "t_ms", "steering_angle", "speed", "progress", "x", "y", "heading", "lap", "offtrack"}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    env = RaceEnv("drem_oval")
    driver = Demonstrator(env.track)
    return record_run(env, lambda _obs, params: driver.act(params), tmp_path_factory.mktemp("runs"), laps=1,
                      driver="demonstrator", seed=4, run_id="run-a")


def test_run_folder_layout(run_dir) -> None:
    track_id, date, run_id = run_dir.parts[-3:]
    assert (track_id, run_id) == ("drem_oval", "run-a") and len(date) == 10
    rows = [json.loads(line) for line in (run_dir / "controls.jsonl").read_text().splitlines()]
    meta = json.loads((run_dir / "metadata.json").read_text())
    assert meta["frames"] == len(rows) == len(list((run_dir / "frames").glob("*.png"))) > 100
    assert meta["laps"] == 1 and len(meta["lap_times_ms"]) == 1 and meta["seed"] == 4
    assert meta["track_id"] == "drem_oval" and meta["direction"] == "forward" and meta["driver"] == "demonstrator"
    assert meta["camera"]["width"] == 160 and meta["started_at"] <= meta["ended_at"]
    assert set(rows[0]) == ROW_KEYS and rows[0]["frame"] == "frames/000000.png" and rows[0]["t_ms"] == 0
    assert [r["index"] for r in rows] == list(range(len(rows)))
    assert rows[-1]["t_ms"] == pytest.approx(meta["lap_times_ms"][0], abs=70)
    frame = cv2.imread(str(run_dir / rows[5]["frame"]), cv2.IMREAD_UNCHANGED)
    assert frame.shape == (120, 160) and frame.dtype.name == "uint8"


def test_the_learning_dataset_reads_a_recorded_run(run_dir) -> None:
    from drem_sim.learn.dataset import load_snapshot

    snapshot = load_snapshot([run_dir])
    assert len(snapshot) > 100 and snapshot.images.shape[1:] == (120, 160)
    assert snapshot.manifest["runs"][0]["track_id"] == "drem_oval"


def test_s3_round_trip(run_dir, tmp_path) -> None:
    with mock_aws():
        s3 = boto3.client("s3", region_name="us-east-1")
        s3.create_bucket(Bucket="drem-test-runs")
        uri = upload_run(s3, "drem-test-runs", run_dir)
        assert uri == f"s3://drem-test-runs/runs/drem_oval/{run_dir.parts[-2]}/run-a/"
        stored = s3.list_objects_v2(Bucket="drem-test-runs", Prefix=uri.removeprefix("s3://drem-test-runs/"))["Contents"]
        assert len(stored) == 4  # controls, metadata, the frames in one bundle, the first frame (the run page's)
        back = download_run(uri, tmp_path, s3_client=s3)
        for name in ("controls.jsonl", "metadata.json", "frames/000007.png"):
            assert (back / name).read_bytes() == (run_dir / name).read_bytes()
        assert len(list((back / "frames").iterdir())) == len(list((run_dir / "frames").iterdir()))
        with pytest.raises(RunError, match="metadata.json missing"):
            download_run("s3://drem-test-runs/runs/drem_oval/2020-01-01/nothing/", tmp_path, s3_client=s3)


@pytest.mark.parametrize("member, data, reason", [
    ("../escape.png", PNG_MAGIC, "is not a frames/NNNNNN.png file"),
    ("frames/000001.png", b"GIF89a", "is not a PNG image"),
    ("frames/evil.sh", PNG_MAGIC, "is not a frames/NNNNNN.png file"),
])
def test_a_frames_bundle_holds_only_frames(tmp_path, member: str, data: bytes, reason: str) -> None:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as bundle:
        info = tarfile.TarInfo(member)
        info.size = len(data)
        bundle.addfile(info, io.BytesIO(data))
    with pytest.raises(RunError, match=reason):
        unpack_frames(buffer.getvalue(), tmp_path)
    assert not any(tmp_path.rglob("*.png")) and not (tmp_path.parent / "escape.png").exists()


def test_a_link_in_a_frames_bundle_is_refused(tmp_path) -> None:
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w") as bundle:
        info = tarfile.TarInfo("frames/000000.png")
        info.type, info.linkname = tarfile.SYMTYPE, "/etc/passwd"
        bundle.addfile(info)
    with pytest.raises(RunError, match="is not a frames/NNNNNN.png file"):
        unpack_frames(buffer.getvalue(), tmp_path)
    with pytest.raises(RunError, match="not a tar of frames"):
        unpack_frames(b"not a tar at all" * 40, tmp_path)


def test_recording_without_a_camera_is_refused(tmp_path) -> None:
    env = RaceEnv("drem_oval", EnvConfig(observe=False))
    with pytest.raises(RunError, match="camera"):
        record_run(env, lambda _o, _p: {"steering_angle": 0.0, "speed": 1.0}, tmp_path, laps=1, driver="x")
