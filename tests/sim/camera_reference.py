"""Saved camera frames: what the simulator's camera rendered before the speed work of issue 33 (commit 664cf14).

The sample models were trained on these frames, so a faster renderer must keep drawing them. Regenerate only when
the camera is meant to change (then retrain the samples): `.venv/bin/python -m tests.sim.camera_reference`.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

REFERENCE_FILE = Path(__file__).resolve().parent / "data" / "camera_frames_664cf14.npz"
TRACKS = ("reinvent_base", "2024_reinvent_champ_ccw")


def reference_poses(track_name: str) -> list[tuple[float, float, float]]:
    """Poses round the lap: on the centre line, near either border, turned across the track and looking out over
    the grass beyond the mat (where the texture ends)."""
    from drem_sim.tracks import load_track

    track = load_track(track_name)
    poses = []
    for k, fraction in enumerate((0.0, 0.13, 0.29, 0.41, 0.58, 0.77, 0.9)):
        x, y, heading = track.pose_at(fraction * track.length)
        side = (0.0, 0.3, -0.3, 0.0, 0.2, -0.2, 0.0)[k] * track.width
        turn = (0.0, 0.25, -0.35, math.pi / 2, -math.pi / 2, math.pi, 0.1)[k]
        poses.append((x - side * math.sin(heading), y + side * math.cos(heading), heading + turn))
    return poses


def render_all() -> dict[str, np.ndarray]:
    from drem_sim.camera import Camera
    from drem_sim.tracks import load_track

    frames = {}
    for name in TRACKS:
        camera = Camera(load_track(name))
        frames[name] = np.stack([camera.render(*pose) for pose in reference_poses(name)])
    return frames


if __name__ == "__main__":
    REFERENCE_FILE.parent.mkdir(exist_ok=True)
    np.savez_compressed(REFERENCE_FILE, **render_all())
    print(f"wrote {REFERENCE_FILE} ({REFERENCE_FILE.stat().st_size} bytes)")
