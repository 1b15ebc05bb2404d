"""Pictures for people (never the car's sensor): a top-down track map with the driven path, and a
video of a recorded run."""
from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from drem_sim.camera import CameraConfig, render_texture
from drem_sim.tracks import Track

PATH_COLOUR = (40, 40, 230)  # BGR red
LINE_COLOUR = (230, 120, 30)  # BGR blue: the timing line


def track_map(track: Track, path_xy: Iterable[tuple[float, float]] | None = None, px_per_m: float = 60.0,
              margin_m: float = 0.5) -> np.ndarray:
    """A BGR top-down image of the track (north up), with the timing line and an optional driven path."""
    texture = render_texture(track, CameraConfig(texture_px_per_m=px_per_m, dash_width=0.04), margin=margin_m)
    image = cv2.cvtColor(texture.image, cv2.COLOR_GRAY2BGR)
    line = np.array(track.timing_line or track.default_timing_line())
    a, b = np.round(texture.to_pixels(line)).astype(int)
    cv2.line(image, tuple(int(v) for v in a), tuple(int(v) for v in b), LINE_COLOUR, 3, cv2.LINE_AA)
    if path_xy is not None:
        points = np.asarray(list(path_xy), dtype=np.float64).reshape(-1, 2)
        if len(points) > 1:
            pixels = np.round(texture.to_pixels(points) * 16).astype(np.int32)
            cv2.polylines(image, [pixels], False, PATH_COLOUR, 2, cv2.LINE_AA, shift=4)
    return image


def save_track_png(track: Track, out: Path, path_xy: Iterable[tuple[float, float]] | None = None,
                   px_per_m: float = 60.0) -> Path:
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(out), track_map(track, path_xy, px_per_m)):
        raise OSError(f"could not write {out}")
    return out


def run_rows(run_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (Path(run_dir) / "controls.jsonl").read_text().splitlines() if line.strip()]


def run_video(run_dir: Path, out: Path, scale: int = 4, fps: float = 15.0) -> Path:
    """An MP4 (mp4v) of a run's camera frames, enlarged, with time, lap, steering and speed written on."""
    run_dir, out = Path(run_dir), Path(out)
    rows = run_rows(run_dir)
    if not rows:
        raise ValueError(f"{run_dir}: the run has no frames")
    size = (160 * scale, 120 * scale)
    out.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter.fourcc(*"mp4v"), fps, size)
    if not writer.isOpened():
        raise OSError(f"cannot open a video writer for {out}")
    try:
        for row in rows:
            gray = cv2.imread(str(run_dir / row["frame"]), cv2.IMREAD_GRAYSCALE)
            if gray is None:
                raise OSError(f"{run_dir}: cannot read the frame {row['frame']}")
            frame = cv2.cvtColor(cv2.resize(gray, size, interpolation=cv2.INTER_NEAREST), cv2.COLOR_GRAY2BGR)
            text = (f"t {row['t_ms'] / 1000:6.2f}s lap {row['lap'] + 1} steer {row['steering_angle']:+5.1f}"
                    f" speed {row['speed']:.2f}")
            cv2.putText(frame, text, (8, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 255, 255), 1, cv2.LINE_AA)
            writer.write(frame)
    finally:
        writer.release()
    return out
