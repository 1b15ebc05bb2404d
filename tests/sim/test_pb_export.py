"""The hand-written TensorFlow GraphDef of drem's network: read by OpenVINO exactly as torch computes it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from drem_sim.console.tf_export import PbExportError, verify_pb, write_pb
from drem_sim.learn.export import export_onnx
from drem_sim.learn.model import BehaviourCloningCNN

pytestmark = pytest.mark.sim


def _spirited_model() -> BehaviourCloningCNN:
    """Random weights scaled up so the outputs spread over [-1, 1]: a wrong flatten order or kernel layout shows."""
    torch.manual_seed(11)
    model = BehaviourCloningCNN()
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.mul_(3.0)
    return model.eval()


def test_openvino_reads_the_pb_and_gives_the_torch_outputs(tmp_path: Path) -> None:
    import openvino as ov

    model = _spirited_model()
    pb = write_pb(model, tmp_path / "model.pb")
    frames = np.random.default_rng(2).integers(0, 256, (6, 120, 160, 1)).astype(np.float32)
    with torch.no_grad():
        expected = model(torch.from_numpy(frames)).numpy()
    compiled = ov.Core().compile_model(ov.Core().read_model(str(pb)), "CPU", {"INFERENCE_PRECISION_HINT": "f32"})
    actual = compiled(frames)[0]
    assert np.ptp(expected[:, 0]) > 0.05, "outputs must differ between frames for the comparison to mean anything"
    np.testing.assert_allclose(actual, expected, atol=1e-4)
    assert verify_pb(pb, export_onnx(model, tmp_path / "model.onnx"), frames) <= 1e-4


def test_a_pb_that_disagrees_with_the_onnx_is_refused(tmp_path: Path) -> None:
    model = _spirited_model()
    onnx_path = export_onnx(model, tmp_path / "model.onnx")
    with torch.no_grad():
        model.head[-2].bias.add_(0.5)  # the graph written now is not the one exported
    pb = write_pb(model, tmp_path / "model.pb")
    frames = np.random.default_rng(3).integers(0, 256, (2, 120, 160, 1)).astype(np.float32)
    with pytest.raises(PbExportError, match="differs from model.onnx"):
        verify_pb(pb, onnx_path, frames)
