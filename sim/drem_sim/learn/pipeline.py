"""One call from recorded runs to a shippable model archive: snapshot → train → ONNX → verify → package."""
from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from drem_sim.learn.dataset import ActionScale, DatasetSnapshot, load_snapshot
from drem_sim.learn.export import export_onnx, verify_onnx
from drem_sim.learn.model import NETWORK_NAME, parameter_count
from drem_sim.learn.package import build_archive, build_metadata
from drem_sim.learn.train import TrainConfig, TrainResult, plot_loss_curve, train_behaviour_cloning

VERIFY_SAMPLES = 16
EXPORTING = "exporting the model (ONNX, checked against the trained network)"


@dataclass
class TrainedModel:
    archive: Path
    onnx: Path
    manifest: Path
    loss_curve: Path
    lineage: dict
    result: TrainResult
    snapshot: DatasetSnapshot
    max_export_difference: float


def train_to_archive(runs: Sequence[str | Path], out_dir: Path, name: str, config: TrainConfig,
                     progress: TextIO | None = sys.stderr, initial_state: dict | None = None,
                     extra_lineage: dict[str, Any] | None = None, scale: ActionScale | None = None) -> TrainedModel:
    """`extra_lineage` (e.g. the DAgger round and its tracks) is added to lineage.json and the archive's lineage."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    snapshot = load_snapshot(runs, scale=scale)
    result = train_behaviour_cloning(snapshot, config, progress=progress, initial_state=initial_state)
    if progress is not None:
        progress.write(f"{EXPORTING}\n")
    onnx_path = export_onnx(result.model, out_dir / "model.onnx")
    picks = np.random.default_rng(config.seed).choice(len(snapshot), size=min(VERIFY_SAMPLES, len(snapshot)),
                                                      replace=False)
    difference = verify_onnx(result.model, onnx_path, snapshot.images[np.sort(picks)])
    manifest_path = snapshot.write_manifest(out_dir / "snapshot_manifest.json")
    loss_curve = plot_loss_curve(result, out_dir / "loss_curve.png")
    lineage = {
        "created_epoch_s": int(time.time()),
        "network": NETWORK_NAME,
        "parameters": parameter_count(result.model),
        "dataset": snapshot.manifest,
        "seed": config.seed,
        "epochs_requested": config.epochs,
        "epochs_run": result.epochs_run,
        "batch_size": config.batch_size,
        "learning_rate": config.learning_rate,
        "augment": config.augment,
        "augmentation": aug.as_dict() if (aug := config.effective_augmentation) is not None else None,
        "balance_steering": {"cap": config.balance_cap} if config.balance_steering else None,
        "train_frames": result.train_frames,
        "validation_frames": result.validation_frames,
        "train_losses": [round(v, 6) for v in result.train_losses],
        "validation_losses": [round(v, 6) for v in result.validation_losses],
        "train_seconds": round(result.seconds, 2),
        "onnx_max_abs_difference": difference,
        **(extra_lineage or {}),
    }
    pb_path, pb_note = _car_graph(result.model, onnx_path, out_dir / "model.pb", snapshot.images[np.sort(picks)])
    lineage["car_model"] = pb_note
    (out_dir / "lineage.json").write_text(json.dumps(lineage, indent=2, sort_keys=True) + "\n")
    metadata = build_metadata(snapshot.scale, car_loadable=pb_path is not None)
    archive = build_archive(out_dir / f"{name}.tar.gz", onnx_path, metadata, lineage, pb_path)
    return TrainedModel(archive, onnx_path, manifest_path, loss_curve, lineage, result, snapshot, difference)


def _car_graph(model, onnx_path: Path, pb_path: Path, frames: np.ndarray) -> tuple[Path | None, dict]:  # noqa: ANN001
    """Write agent/model.pb for stock cars, but ship it only once OpenVINO (the car's runtime) reproduces the ONNX."""
    import importlib.util

    if importlib.util.find_spec("openvino") is None:
        return None, {"written": False, "reason": "OpenVINO is not installed, so the .pb could not be verified"}
    from drem_sim.console.tf_export import verify_pb, write_pb

    write_pb(model, pb_path)
    difference = verify_pb(pb_path, onnx_path, frames)  # raises PbExportError: never ship a graph that differs
    return pb_path, {"written": True, "file": "agent/model.pb", "openvino_max_abs_difference": difference}
