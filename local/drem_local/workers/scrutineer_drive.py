"""One bounded background test drive (the child the scrutineering worker starts): drive a model folder on the
simulator twins of some event track types, print the reports as one JSON line, and write a top-down GIF of the drive
on the first track.

    python -m drem_local.workers.scrutineer_drive --folder DIR --track-type REINVENT_2018 [--laps 2] [--clip out.gif]
    python -m drem_local.workers.scrutineer_drive --folder DIR --track reinvent_base [--laps 3]   (a league re-drive)

The folder holds model_metadata.json and model.onnx (the worker wrote them there). Verdicts are those of
drem_sim.learn.scrutineer (a lap with an off-track is no completed lap); the clip is drawn with the simulator's own
top-down renderer (drem_sim.render.track_map) and encoded with Pillow, its size bounded by MAX_CLIP_BYTES.
"""
from __future__ import annotations

import argparse
import io
import json
import sys
from pathlib import Path
from typing import Any

MAX_CLIP_BYTES = 1_500_000
CLIP_WIDTH_PX = 360
CLIP_FRAMES = 48
CLIP_FRAME_MS = 120
CAR_COLOUR = (60, 220, 60)  # BGR green: the car on the map, apart from the red path


class RecordingEnv:
    """A RaceEnv seen through `drive`, keeping where the car was after every step (for the clip)."""

    def __init__(self, env: Any) -> None:
        self._env = env
        self.path: list[tuple[float, float]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._env, name)

    def reset(self, *args: Any, **kwargs: Any) -> Any:
        return self._env.reset(*args, **kwargs)

    def step(self, action: Any) -> Any:
        answer = self._env.step(action)
        params = answer[1]
        if isinstance(params, dict) and "x" in params and "y" in params:
            self.path.append((float(params["x"]), float(params["y"])))
        return answer


def drive_track(folder: Path, track_type: str, laps: int, *,
                track_name: str | None = None) -> tuple[dict[str, Any], Any, list[tuple[float, float]]]:
    """(report, track, driven path) for one track type, or for the track named `track_name` (a league board's)."""
    from drem_sim.env import RaceEnv
    from drem_sim.learn.evaluate import drive
    from drem_sim.learn.package import ArchiveError
    from drem_sim.learn.pilot import NotRaceableModel, OnnxPilot, TensorFlowModelError
    from drem_sim.learn.scrutineer import PASS_COMPLETION_PCT, EventTrack, track_for_event
    from drem_sim.learn.scrutiny_words import (
        PlainFailure,
        archive_unusable,
        console_model_unusable,
        model_stopped,
        not_raceable,
        track_unavailable,
    )
    from drem_sim.tracks import TrackError, load_track

    event_track = EventTrack(track_type="LEAGUE", track=track_name) if track_name else track_for_event(track_type)
    base: dict[str, Any] = {"track": event_track.track, "track_type": event_track.track_type, "laps": laps}

    def stopped(verdict: str, failure: PlainFailure) -> tuple[dict[str, Any], None, list[tuple[float, float]]]:
        return {**base, "verdict": verdict, "message": failure.message, "detail": failure.detail}, None, []

    try:
        track = load_track(event_track.track)
    except TrackError as error:
        return stopped("cannot_scrutineer", track_unavailable(event_track.track, error))
    try:
        pilot = OnnxPilot.from_archive(folder)
    except NotRaceableModel as error:  # the same sentence as a drive by hand (drem_sim.learn.scrutineer)
        return stopped("invalid", not_raceable(error.reason, error.detail))
    except TensorFlowModelError as error:
        return stopped("cannot_scrutineer", console_model_unusable(str(error).removeprefix("cannot scrutineer: ")))
    except ArchiveError as error:
        return stopped("invalid", archive_unusable(str(error)))
    except Exception as error:  # onnxruntime refusing a racer's graph
        return stopped("cannot_scrutineer", model_stopped(event_track.track, error))
    env = RecordingEnv(RaceEnv(track))
    try:
        metrics = drive(env, lambda observation, _params: pilot.act(observation), laps, 0, folder.name,
                        event_track.track)
    except Exception as error:  # a graph that loads but fails on a frame
        return stopped("cannot_scrutineer", model_stopped(event_track.track, error))
    passed = metrics.completion_pct >= PASS_COMPLETION_PCT
    lap = f", mean lap {metrics.mean_lap_time_s:.2f}s" if metrics.mean_lap_time_s is not None else ""
    note = f" ({event_track.note})" if event_track.note else ""
    report = {**base, "verdict": "passed" if passed else "failed",
              "message": f"{metrics.laps_completed}/{metrics.attempts} laps completed on {event_track.track}, "
                         f"completion {metrics.completion_pct:.1f}%{lap}{note}",
              "laps_completed": metrics.laps_completed, "attempts": metrics.attempts,
              "completion_pct": metrics.completion_pct, "best_lap_time_s": metrics.best_lap_time_s,
              "mean_lap_time_s": metrics.mean_lap_time_s, "offtrack_count": metrics.offtrack_count}
    return report, track, env.path


def clip_gif(track: Any, path: list[tuple[float, float]], *, frames: int = CLIP_FRAMES,
             width_px: int = CLIP_WIDTH_PX) -> bytes:
    """A looping GIF: the track from above, the path driven so far in red and the car as a dot."""
    import cv2
    import numpy as np
    from PIL import Image

    from drem_sim.camera import CameraConfig, render_texture
    from drem_sim.render import track_map

    x0, _y0, x1, _y1 = track.bounds
    margin = 0.5
    px_per_m = width_px / (x1 - x0 + 2 * margin)
    background = track_map(track, None, px_per_m=px_per_m, margin_m=margin)
    # The same transform track_map draws with (its texture), to put the path and the car on that picture.
    texture = render_texture(track, CameraConfig(texture_px_per_m=px_per_m, dash_width=0.04), margin=margin)
    points = np.round(texture.to_pixels(np.asarray(path, dtype=np.float64).reshape(-1, 2))).astype(np.int32)
    count = max(1, min(frames, len(points)))
    ends = np.linspace(1, len(points), count).astype(int) if len(points) else [0]
    images = []
    for end in ends:
        frame = background.copy()
        if end > 1:
            cv2.polylines(frame, [points[:end]], False, (40, 40, 230), 2, cv2.LINE_AA)
        if end >= 1:
            x, y = (int(v) for v in points[end - 1])
            cv2.circle(frame, (x, y), 6, CAR_COLOUR, -1, cv2.LINE_AA)
        rgb = Image.fromarray(cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))
        images.append(rgb.quantize(colors=32, method=Image.Quantize.MEDIANCUT))
    out = io.BytesIO()
    images[0].save(out, format="GIF", save_all=True, append_images=images[1:], duration=CLIP_FRAME_MS, loop=0,
                   optimize=True)
    return out.getvalue()


def bounded_clip(track: Any, path: list[tuple[float, float]]) -> bytes | None:
    """The clip, with fewer frames (then a smaller picture) until it fits MAX_CLIP_BYTES; None if it never does."""
    for frames, width in ((CLIP_FRAMES, CLIP_WIDTH_PX), (CLIP_FRAMES // 2, CLIP_WIDTH_PX),
                          (CLIP_FRAMES // 4, CLIP_WIDTH_PX * 2 // 3)):
        data = clip_gif(track, path, frames=frames, width_px=width)
        if len(data) <= MAX_CLIP_BYTES:
            return data
    return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drem_local.workers.scrutineer_drive")
    parser.add_argument("--folder", type=Path, required=True)
    parser.add_argument("--track-type", action="append", default=[])
    parser.add_argument("--track", default=None, help="drive this track by name (a league board's) instead")
    parser.add_argument("--laps", type=int, default=2)
    parser.add_argument("--clip", type=Path, default=None)
    args = parser.parse_args(argv)
    if args.track:
        report, _track, _path = drive_track(args.folder, "", max(1, min(args.laps, 3)), track_name=args.track)
        print(json.dumps({"reports": [report]}))
        return 0
    if not args.track_type:
        parser.error("give --track-type (one or more) or --track")
    reports = []
    for index, track_type in enumerate(args.track_type):
        report, track, path = drive_track(args.folder, track_type, max(1, min(args.laps, 3)))
        reports.append(report)
        if index == 0 and args.clip is not None and track is not None and path:
            data = bounded_clip(track, path)
            if data is not None:
                args.clip.write_bytes(data)
        if report["verdict"] in ("cannot_scrutineer", "invalid"):
            break  # the same model will not drive on another track either
    print(json.dumps({"reports": reports}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
