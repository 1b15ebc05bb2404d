"""Behaviour cloning end to end on a small recorded demonstrator run: train → ONNX → archive → validator."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import cv2
import numpy as np
import onnx
import onnxruntime
import pytest
import torch

from chalicelib.formats.model_archive.report import ArchiveStatus
from chalicelib.formats.model_archive.verdict import inspect_archive
from drem_sim.demonstrator import Demonstrator
from drem_sim.env import RaceEnv
from drem_sim.learn.dataset import load_snapshot
from drem_sim.learn.export import IR_VERSION
from drem_sim.learn.pipeline import train_to_archive
from drem_sim.learn.train import TrainConfig, train_behaviour_cloning
from drem_sim.runs import record_run
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim

TINY = TrainConfig(epochs=2, seed=7, batch_size=32, num_threads=1)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    track = load_track("drem_oval")
    driver = Demonstrator(track)
    return record_run(RaceEnv(track), lambda _obs, params: driver.act(params), tmp_path_factory.mktemp("runs"),
                      laps=1, driver="demonstrator", seed=1, max_steps=96)


@pytest.fixture(scope="module")
def trained(run_dir: Path, tmp_path_factory: pytest.TempPathFactory):  # noqa: ANN201 - TrainedModel
    progress = io.StringIO()
    model = train_to_archive([run_dir], tmp_path_factory.mktemp("model"), "tiny_bc-1", TINY, progress=progress)
    return model, progress.getvalue()


def test_exported_onnx_gives_the_torch_model_outputs(trained, run_dir: Path) -> None:
    model, _ = trained
    frames = np.stack([cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
                       for p in sorted((run_dir / "frames").glob("*.png"))[:8]])
    inputs = frames.astype(np.float32)[..., None]
    with torch.no_grad():
        expected = model.result.model(torch.from_numpy(inputs)).numpy()
    session = onnxruntime.InferenceSession(str(model.onnx), providers=["CPUExecutionProvider"])
    actual = session.run(["policy"], {"observation": inputs})[0]
    assert actual.shape == (8, 2)
    np.testing.assert_allclose(actual, expected, atol=1e-4)
    assert np.ptp(actual[:, 0]) > 0  # the frames differ, so do the outputs: not a constant graph


def test_archive_passes_the_upload_validator_and_loads_in_onnxruntime(trained) -> None:
    model, _ = trained
    report = inspect_archive(model.archive)
    assert report.status == ArchiveStatus.AVAILABLE, report.reason
    assert report.model_kind == "onnx"
    assert report.action_space_type == "continuous"
    assert report.training_algorithm == "behaviour_cloning", "drem shows the real origin, the car reads clipped_ppo"
    with tarfile.open(model.archive) as archive:
        graph_bytes = archive.extractfile("model.onnx").read()
        metadata = json.loads(archive.extractfile("model_metadata.json").read())
    graph = onnx.load_from_string(graph_bytes)
    assert graph.ir_version == IR_VERSION <= 13
    session = onnxruntime.InferenceSession(graph_bytes, providers=["CPUExecutionProvider"])
    (tensor,) = session.get_inputs()
    assert tensor.name == "observation" and tensor.shape[1:] == [120, 160, 1]
    assert metadata["drem"]["input"]["layout"] == "NHWC"
    assert metadata["action_space_type"] == "continuous"


def test_training_shows_progress_and_writes_a_loss_curve(trained) -> None:
    model, progress = trained
    assert "epoch 1/2 [" in progress and "epoch 2/2 train" in progress
    assert len(model.result.train_losses) == 2 and len(model.result.validation_losses) == 2
    curve = cv2.imread(str(model.loss_curve))
    assert curve is not None and curve.shape == (360, 640, 3)
    assert (curve < 200).any(axis=2).sum() > 500  # lines and text drawn, not a blank canvas
    lineage = model.lineage
    assert lineage["seed"] == 7 and lineage["dataset"]["frame_count"] == len(model.snapshot)


def test_same_seed_gives_the_same_weights_and_another_seed_does_not(run_dir: Path) -> None:
    snapshot = load_snapshot([run_dir])
    one_epoch = TrainConfig(epochs=1, seed=3, batch_size=32, num_threads=1)
    first = train_behaviour_cloning(snapshot, one_epoch, progress=None).model.state_dict()
    again = train_behaviour_cloning(snapshot, one_epoch, progress=None).model.state_dict()
    other = train_behaviour_cloning(snapshot, TrainConfig(epochs=1, seed=4, batch_size=32, num_threads=1),
                                    progress=None).model.state_dict()
    assert all(torch.equal(first[key], again[key]) for key in first)
    assert not all(torch.equal(first[key], other[key]) for key in first)


def test_the_car_agent_reads_the_archive_like_the_simulator(trained, run_dir: Path, tmp_path: Path) -> None:
    from drem_cars.parts.pilot_onnx import OnnxPilot as CarPilot
    from drem_sim.learn.pilot import OnnxPilot as SimPilot

    model, _ = trained
    with tarfile.open(model.archive) as archive:
        archive.extractall(tmp_path, filter="data")
    frame = cv2.imread(str(sorted((run_dir / "frames").glob("*.png"))[5]), cv2.IMREAD_GRAYSCALE)
    steering, speed, _ = CarPilot(tmp_path).run(frame)
    expected = SimPilot.from_archive(model.archive).act(frame)
    assert steering == pytest.approx(expected["steering_angle"], abs=1e-4)
    assert speed == pytest.approx(expected["speed"], abs=1e-4)


def test_the_archive_also_carries_a_pb_a_stock_car_accepts(trained, run_dir: Path, tmp_path: Path) -> None:
    import openvino as ov

    from chalicelib.formats.model_metadata import check_for_stock_car, parse_model_metadata_json
    from drem_sim.console.convert import convert
    from drem_sim.console.tf_export import INPUT_NODE, OUTPUT_NODE

    model, _ = trained
    with tarfile.open(model.archive) as archive:
        pb = archive.extractfile("agent/model.pb").read()
        raw_metadata = archive.extractfile("model_metadata.json").read()
    metadata = json.loads(raw_metadata)
    # what the car validates (webserver_pkg constants.py): clipped_ppo; our real origin kept in the drem block
    assert metadata["training_algorithm"] == "clipped_ppo"
    assert metadata["drem"]["training_algorithm"] == "behaviour_cloning"
    check_for_stock_car(parse_model_metadata_json(raw_metadata))
    assert model.lineage["car_model"]["openvino_max_abs_difference"] <= 1e-4
    (tmp_path / "model.pb").write_bytes(pb)
    graph = ov.Core().read_model(str(tmp_path / "model.pb"))  # OpenVINO's TensorFlow frontend, as on the car
    assert {n.split(":")[0] for n in graph.inputs[0].get_names()} == {INPUT_NODE}
    assert {n.split(":")[0] for n in graph.outputs[0].get_names()} == {OUTPUT_NODE}
    frames = np.stack([cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
                       for p in sorted((run_dir / "frames").glob("*.png"))[:8]]).astype(np.float32)[..., None]
    compiled = ov.Core().compile_model(graph, "CPU", {"INFERENCE_PRECISION_HINT": "f32"})
    session = onnxruntime.InferenceSession(str(model.onnx), providers=["CPUExecutionProvider"])
    np.testing.assert_allclose(compiled(frames)[0], session.run(["policy"], {"observation": frames})[0], atol=1e-4)
    # and drem's own upload converter reads it back like any console model
    assert convert(tmp_path / "model.pb", metadata, tmp_path / "back.onnx").outcome == "converted"
