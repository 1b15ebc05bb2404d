"""Dataset snapshots: frames and normalised action targets taken from recorded run folders.

A run folder (written by the simulator's recorder) holds ``frames/{i:06d}.png`` (120x160 grayscale),
``controls.jsonl`` (one row per frame: steering_angle, speed, offtrack, ...) and ``metadata.json``.
The speed a frame teaches is what the driver really did: a person's drive records ``car_speed`` (the speed the car
reached by the end of the decision), so letting go of ↑ teaches "slower here", not "skip this frame"; a program's
run (the demonstrator) has only its commanded ``speed``, which its car follows.
A snapshot freezes which runs and frames a model learned from; its manifest (runs, counts, content
hash) travels next to the model so its lineage is always known.
"""
from __future__ import annotations

import hashlib
import json
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from drem_sim.learn.contract import IMAGE_HEIGHT, IMAGE_WIDTH

MAX_STEERING_DEG = 30.0
MIN_SPEED_SPREAD = 0.2  # m/s; a constant-speed demonstrator still gets a usable speed range
MIN_MODEL_SPEED = 0.3  # m/s; the slowest a model is taught to go: a person who stopped mid-lap made no racing example


class DatasetError(ValueError):
    """A run folder is missing, malformed or empty."""


@dataclass(frozen=True)
class ActionScale:
    """Maps real actions (degrees, m/s) to the network's [-1, 1] outputs; the ranges go into model_metadata.json,
    from which the car (and the pilot) map the outputs back."""

    steering_low: float = -MAX_STEERING_DEG
    steering_high: float = MAX_STEERING_DEG
    speed_low: float = 0.5
    speed_high: float = 4.0

    def normalise(self, steering: np.ndarray, speed: np.ndarray) -> np.ndarray:
        return np.stack([
            _to_unit(steering, self.steering_low, self.steering_high),
            _to_unit(speed, self.speed_low, self.speed_high),
        ], axis=-1).astype(np.float32)

    @classmethod
    def from_speeds(cls, speeds: np.ndarray) -> ActionScale:
        low, high = float(np.min(speeds)), float(np.max(speeds))
        if high - low < MIN_SPEED_SPREAD:
            middle = (high + low) / 2
            low, high = middle - MIN_SPEED_SPREAD / 2, middle + MIN_SPEED_SPREAD / 2
        low = max(low, MIN_MODEL_SPEED)
        high = max(high, low + MIN_SPEED_SPREAD)
        return cls(speed_low=round(low, 3), speed_high=round(min(high, 4.0), 3))


def _to_unit(value: np.ndarray, low: float, high: float) -> np.ndarray:
    return np.clip(2.0 * (np.asarray(value, dtype=np.float64) - low) / (high - low) - 1.0, -1.0, 1.0)


@dataclass
class DatasetSnapshot:
    images: np.ndarray            # uint8 [N, 120, 160]
    steering: np.ndarray          # float32 degrees [N]
    speed: np.ndarray             # float32 m/s [N]
    scale: ActionScale
    manifest: dict[str, Any] = field(default_factory=dict)

    @property
    def targets(self) -> np.ndarray:
        return self.scale.normalise(self.steering, self.speed)

    def __len__(self) -> int:
        return int(self.images.shape[0])

    def write_manifest(self, path: Path) -> Path:
        path.write_text(json.dumps(self.manifest, indent=2, sort_keys=True) + "\n")
        return path


def load_snapshot(runs: Sequence[str | Path], scale: ActionScale | None = None,
                  include_offtrack: bool = False) -> DatasetSnapshot:
    """Load every usable frame of the given run folders (or ``s3://`` run prefixes)."""
    if not runs:
        raise DatasetError("no runs given: pass at least one run folder")
    run_dirs = [resolve_run(run) for run in runs]
    images: list[np.ndarray] = []
    steering: list[float] = []
    speed: list[float] = []
    digest = hashlib.sha256()
    run_entries = []
    for run_dir in run_dirs:
        rows = _read_controls(run_dir)
        used = 0
        for row in _driving_rows(rows):
            if row.get("offtrack") and not include_offtrack:
                continue
            frame_path = _frame_path(run_dir, row)
            raw = frame_path.read_bytes()
            image = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_GRAYSCALE)
            if image is None or image.shape != (IMAGE_HEIGHT, IMAGE_WIDTH):
                raise DatasetError(f"{frame_path}: not a {IMAGE_WIDTH}x{IMAGE_HEIGHT} grayscale image")
            digest.update(raw)
            label = speed_label(row)
            digest.update(f"{row['steering_angle']:.6f},{label:.6f}".encode())
            images.append(image)
            steering.append(float(row["steering_angle"]))
            speed.append(label)
            used += 1
        run_entries.append({"run": str(run_dir), **_run_identity(run_dir), "rows": len(rows), "frames_used": used})
    if not images:
        raise DatasetError("the given runs hold no on-track frames")
    speeds = np.asarray(speed, dtype=np.float32)
    scale = scale or ActionScale.from_speeds(speeds)
    manifest = {
        "runs": run_entries,
        "frame_count": len(images),
        "content_sha256": digest.hexdigest(),
        "include_offtrack": include_offtrack,
        "action_scale": scale.__dict__,
    }
    return DatasetSnapshot(np.stack(images), np.asarray(steering, dtype=np.float32), speeds, scale, manifest)


def speed_label(row: dict[str, Any]) -> float:
    """The speed a frame teaches: the car's real speed when the run recorded it, else the commanded speed."""
    return float(row["car_speed"] if "car_speed" in row else row["speed"])


def _driving_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows from the car's first movement to its last. A person's drive (rows with ``car_speed``) keeps every
    frame in between, slow or stopped; only standing at the line before setting off and after the end is not
    driving. A program's run without ``car_speed`` leaves out every frame it commanded no speed on."""
    if not any("car_speed" in row for row in rows):
        return [row for row in rows if float(row["speed"]) > 0.0]
    moving = [index for index, row in enumerate(rows) if float(row.get("car_speed", 0.0)) > 0.0]
    return rows[moving[0]:moving[-1] + 1] if moving else []


def resolve_run(run: str | Path) -> Path:
    """A local run folder as is; an ``s3://bucket/runs/...`` prefix downloaded through the runs module."""
    text = str(run)
    if text.startswith("s3://"):
        return _download_run(text)
    path = Path(text)
    if not (path / "controls.jsonl").is_file():
        raise DatasetError(f"{path}: not a run folder (no controls.jsonl)")
    return path


def _download_run(uri: str) -> Path:
    from drem_sim import runs as runs_module  # the simulator's run store owns S3 access

    download = getattr(runs_module, "download_run", None)
    if download is None:
        raise DatasetError("this build of drem_sim.runs cannot download runs from S3")
    target = Path(tempfile.mkdtemp(prefix="drem-run-"))
    return Path(download(uri, target))


def _read_controls(run_dir: Path) -> list[dict[str, Any]]:
    rows = []
    with (run_dir / "controls.jsonl").open() as handle:
        for number, line in enumerate(handle, 1):
            if not line.strip():
                continue
            try:
                row = json.loads(line)
                float(row["steering_angle"]), float(row["speed"]), float(row.get("car_speed", 0.0))
            except (ValueError, KeyError, TypeError) as error:
                raise DatasetError(f"{run_dir}/controls.jsonl line {number}: {error}") from error
            rows.append(row)
    if not rows:
        raise DatasetError(f"{run_dir}: controls.jsonl is empty")
    return rows


def _frame_path(run_dir: Path, row: dict[str, Any]) -> Path:
    frame: Any = row.get("frame", row.get("index"))  # a path (str) or a frame number, as the run wrote it
    if isinstance(frame, str):
        candidate = (run_dir / frame).resolve()
        if run_dir.resolve() not in candidate.parents:
            raise DatasetError(f"{run_dir}: frame path {frame!r} leaves the run folder")
    else:
        candidate = run_dir / "frames" / f"{int(frame):06d}.png"
    if not candidate.is_file():
        raise DatasetError(f"{candidate}: frame listed in controls.jsonl is missing")
    return candidate


def _run_identity(run_dir: Path) -> dict[str, Any]:
    meta_path = run_dir / "metadata.json"
    if not meta_path.is_file():
        return {}
    meta = json.loads(meta_path.read_text())
    keys = ("run_id", "track_id", "track", "driver", "source", "seed", "laps")
    return {key: meta[key] for key in keys if key in meta}


AUGMENTATIONS = ("brightness", "noise", "flip", "shift", "blur")


@dataclass(frozen=True)
class Augmentation:
    """Training-time image changes that match what the car's camera really does; each one switchable.

    brightness: gain/offset (venue lighting, auto-exposure); noise: sensor noise; flip: mirror image with the
    steering sign negated (a left bend becomes a right one); shift: a few pixels of translation and a small roll
    (the camera mount is never exactly where the simulator puts it; small enough to keep the label); blur: a
    light Gaussian blur on some frames (motion and focus blur).
    """
    brightness: float = 0.25
    noise: float = 6.0
    flip: bool = True
    shift_px: float = 0.0
    rotate_deg: float = 0.0
    blur_probability: float = 0.0

    @classmethod
    def from_names(cls, names: Iterable[str]) -> Augmentation:
        """`["brightness", "shift", ...]` → those switched on (camera-matched strengths), the rest off."""
        chosen = {name.strip() for name in names if name.strip()}
        unknown = chosen - set(AUGMENTATIONS) - {"none"}
        if unknown:
            raise DatasetError(f"unknown augmentation(s) {sorted(unknown)}; "
                               f"choose from {', '.join(AUGMENTATIONS)} or none")
        return cls(brightness=0.25 if "brightness" in chosen else 0.0, noise=6.0 if "noise" in chosen else 0.0,
                   flip="flip" in chosen, shift_px=4.0 if "shift" in chosen else 0.0,
                   rotate_deg=2.0 if "shift" in chosen else 0.0, blur_probability=0.3 if "blur" in chosen else 0.0)

    @property
    def names(self) -> list[str]:
        on = {"brightness": self.brightness > 0, "noise": self.noise > 0, "flip": self.flip,
              "shift": self.shift_px > 0 or self.rotate_deg > 0, "blur": self.blur_probability > 0}
        return [name for name in AUGMENTATIONS if on[name]]

    def as_dict(self) -> dict[str, Any]:
        return {"names": self.names, **self.__dict__}


def augment_batch(images: np.ndarray, targets: np.ndarray, rng: np.random.Generator,
                  flip: bool = True, brightness: float = 0.25, noise: float = 6.0,
                  augmentation: Augmentation | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Apply `augmentation` (default: brightness/contrast, pixel noise and mirroring, as the keyword arguments say)."""
    aug = augmentation or Augmentation(brightness=brightness, noise=noise, flip=flip)
    out = images.astype(np.float32)
    targets = targets.copy()
    count = out.shape[0]
    if aug.shift_px > 0 or aug.rotate_deg > 0:
        out = _shift_and_roll(out, rng, aug.shift_px, aug.rotate_deg)
    if aug.blur_probability > 0:
        for i in np.flatnonzero(rng.random(count) < aug.blur_probability):
            out[i] = cv2.GaussianBlur(out[i], (5, 5), float(rng.uniform(0.6, 1.2)))
    if aug.brightness > 0:
        gain = rng.uniform(1 - aug.brightness, 1 + aug.brightness, size=(count, 1, 1)).astype(np.float32)
        offset = rng.uniform(-aug.brightness * 60, aug.brightness * 60, size=(count, 1, 1)).astype(np.float32)
        out = out * gain + offset
    if aug.noise > 0:
        out = out + rng.normal(0.0, aug.noise, size=out.shape).astype(np.float32)
    if aug.flip:
        mirrored = rng.random(count) < 0.5
        out[mirrored] = out[mirrored, :, ::-1]
        targets[mirrored, 0] = -targets[mirrored, 0]
    return np.clip(out, 0, 255), targets


def _shift_and_roll(images: np.ndarray, rng: np.random.Generator, shift_px: float, rotate_deg: float) -> np.ndarray:
    """Per image: translate by up to ±shift_px and roll by up to ±rotate_deg about the centre (edge pixels repeat,
    as a slightly moved camera still sees floor there, not black)."""
    count, height, width = images.shape
    shifts: np.ndarray = rng.uniform(-shift_px, shift_px, size=(count, 2))
    angles = rng.uniform(-rotate_deg, rotate_deg, size=(count,))
    out = np.empty_like(images)
    for i in range(count):
        matrix = cv2.getRotationMatrix2D((width / 2, height / 2), float(angles[i]), 1.0)
        matrix[:, 2] += shifts[i]
        out[i] = cv2.warpAffine(images[i], matrix, (width, height), flags=cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)
    return out


def iter_run_dirs(root: Path) -> Iterable[Path]:
    """Every run folder below ``root`` (folders that hold a controls.jsonl)."""
    return sorted(path.parent for path in Path(root).rglob("controls.jsonl"))
