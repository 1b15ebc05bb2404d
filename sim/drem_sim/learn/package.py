"""DeepRacer-style model archives for ONNX policies.

Layout (all members at fixed paths, regular files only)::

    model_metadata.json       DeepRacer schema + a "drem" block describing the ONNX tensors
    model.onnx                the policy graph
    training/lineage.json     dataset snapshot manifest, seed, epochs, losses
"""
from __future__ import annotations

import io
import json
import re
import tarfile
import time
from pathlib import Path
from typing import Any

from drem_archive.member_names import RefusedMember, vet_member_name
from drem_sim.learn.contract import IMAGE_HEIGHT, IMAGE_WIDTH, INPUT_NAME, NETWORK_NAME, OUTPUT_NAME
from drem_sim.learn.dataset import ActionScale

ARCHIVE_NAME = re.compile(r"^[A-Za-z0-9_-]+\.tar\.gz$")
METADATA_MEMBER = "model_metadata.json"
ONNX_MEMBER = "model.onnx"
LINEAGE_MEMBER = "training/lineage.json"
TENSORFLOW_MEMBER = "agent/model.pb"
MAX_MEMBER_BYTES = 64 * 1024 * 1024


class ArchiveError(ValueError):
    """The archive is not a usable model package."""


def build_metadata(scale: ActionScale, *, car_loadable: bool = False) -> dict[str, Any]:
    """DeepRacer metadata; `car_loadable` (the archive also holds agent/model.pb) names the algorithm as a stock car
    requires (it accepts only clipped_ppo / sac) and keeps the real training origin in the drem block."""
    metadata: dict[str, Any] = {
        "action_space": {
            "steering_angle": {"low": scale.steering_low, "high": scale.steering_high},
            "speed": {"low": scale.speed_low, "high": scale.speed_high},
        },
        "action_space_type": "continuous",
        "sensor": ["FRONT_FACING_CAMERA"],
        "neural_network": NETWORK_NAME,
        "training_algorithm": "behaviour_cloning",
        "version": "5",
        "drem": {
            "format": "onnx",
            "model_file": ONNX_MEMBER,
            "input": {"name": INPUT_NAME, "shape": [None, IMAGE_HEIGHT, IMAGE_WIDTH, 1], "layout": "NHWC",
                      "dtype": "float32", "color": "grayscale", "scale": "raw 0..255 (the graph divides by 255)"},
            "output": {"name": OUTPUT_NAME, "shape": [None, 2], "kind": "continuous_means",
                       "order": ["steering_angle", "speed"], "range": [-1.0, 1.0]},
            "training_algorithm": "behaviour_cloning",
        },
    }
    if car_loadable:
        # The .pb is laid out like a Coach clipped-PPO graph (input/output node names), so that is what the car reads.
        metadata["training_algorithm"] = "clipped_ppo"
        metadata["drem"]["car_model_file"] = TENSORFLOW_MEMBER
    return metadata


def build_archive(path: Path, onnx_path: Path, metadata: dict[str, Any], lineage: dict[str, Any],
                  pb_path: Path | None = None) -> Path:
    if not ARCHIVE_NAME.match(path.name):
        raise ArchiveError(f"archive name {path.name!r} must match [A-Za-z0-9_-]+.tar.gz")
    if (pb_path is not None) != (metadata.get("drem", {}).get("car_model_file") == TENSORFLOW_MEMBER):
        raise ArchiveError("agent/model.pb and the metadata's drem.car_model_file go together")
    members = {
        METADATA_MEMBER: json.dumps(metadata, indent=2).encode() + b"\n",
        ONNX_MEMBER: Path(onnx_path).read_bytes(),
        **({TENSORFLOW_MEMBER: Path(pb_path).read_bytes()} if pb_path is not None else {}),
        LINEAGE_MEMBER: json.dumps(lineage, indent=2, sort_keys=True).encode() + b"\n",
    }
    mtime = int(lineage.get("created_epoch_s", time.time()))
    with tarfile.open(path, "w:gz") as archive:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size, info.mode, info.mtime = len(data), 0o644, mtime
            archive.addfile(info, io.BytesIO(data))
    return path


def read_model_files(source: Path) -> dict[str, bytes]:
    """Member bytes of a model archive (or an unpacked model folder), read without extracting anything.

    Archives are hostile input: only regular files with plain relative names are read, each size-capped;
    nothing ever touches the filesystem.
    """
    source = Path(source)
    if source.is_dir():
        return {name: (source / name).read_bytes() for name in (METADATA_MEMBER, ONNX_MEMBER, TENSORFLOW_MEMBER)
                if (source / name).is_file()}
    files: dict[str, bytes] = {}
    try:
        with tarfile.open(source, "r:*") as archive:
            for member in archive:
                try:  # the one vetting every drem reader of archives uses; a refused member is skipped here
                    name = vet_member_name(member.name)
                except RefusedMember:
                    continue
                if name is None or not member.isreg() or name not in (METADATA_MEMBER, ONNX_MEMBER, TENSORFLOW_MEMBER):
                    continue
                if member.size > MAX_MEMBER_BYTES:
                    raise ArchiveError(f"{name} is larger than {MAX_MEMBER_BYTES // (1024 * 1024)} MiB")
                handle = archive.extractfile(member)
                if handle is not None:
                    files[name] = handle.read(MAX_MEMBER_BYTES + 1)
    except (tarfile.TarError, OSError, EOFError) as error:
        raise ArchiveError(f"{source.name}: not a readable tar.gz archive ({error})") from error
    return files


def load_metadata(files: dict[str, bytes]) -> dict[str, Any]:
    if METADATA_MEMBER not in files:
        raise ArchiveError(f"the archive has no {METADATA_MEMBER}")
    try:
        metadata = json.loads(files[METADATA_MEMBER])
    except ValueError as error:
        raise ArchiveError(f"{METADATA_MEMBER} is not valid JSON ({error})") from error
    if not isinstance(metadata, dict) or "action_space" not in metadata:
        raise ArchiveError(f"{METADATA_MEMBER} has no action_space")
    return metadata
