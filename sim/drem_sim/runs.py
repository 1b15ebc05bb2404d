"""Run folders: what a driver saw and did, frame by frame, for behaviour cloning.

Layout `runs/{track_id}/{date}/{run_id}/` (the same keys under the runs bucket):
- `frames/{index:06d}.png`: the 160x120 grayscale camera frame the driver acted on;
- `controls.jsonl`: one row per frame (index, frame, t_ms, steering_angle, speed, progress, x, y,
  heading, lap, offtrack, and for a person's drive car_speed); `speed` is the speed commanded, `car_speed`
  the speed the car really reached by the end of that decision (what a person did, whatever key they held);
  `offtrack` is true when the action taken on that frame ended off the track, so a dataset can leave
  those bad examples out;
- `metadata.json`: track, direction, driver, start/end, frames, laps and lap times (the whole laps only, by the one
  rule of `drem_leaderboard.laps`: none finished after a put-back), resets, seed, camera.
In a bucket the frames travel as one object, `frames.tar` (an uncompressed tar of `frames/{index:06d}.png`: PNGs are
compressed already), so a run of 1,800 frames is three objects, not 1,800; `download_run` unpacks it (and still reads
runs stored frame by frame).
This module is the only one in drem_sim that talks to S3; the boto3 client is injected (or built
lazily from the environment, which honours AWS_ENDPOINT_URL for the local stack).
"""
from __future__ import annotations

import datetime as dt
import io
import json
import os
import re
import secrets
import tarfile
from collections.abc import Callable, Iterator
from pathlib import Path, PurePosixPath
from typing import Any

import cv2
import numpy as np

from drem_sim.camera import CameraConfig
from drem_sim.env import RaceEnv

Policy = Callable[[np.ndarray, dict[str, Any]], dict[str, float]]
RUN_FILES = ("controls.jsonl", "metadata.json")
FRAMES_BUNDLE = "frames.tar"
FRAME_MEMBER = re.compile(r"^frames/\d{6}\.png$")
MAX_FRAME_BYTES = 1024 * 1024  # a 160x120 grayscale camera PNG is ~2 KB
MAX_BUNDLE_FRAMES = 50_000  # as many as a run may have rows


class RunError(ValueError):
    """A run folder or S3 run prefix is missing or malformed."""


def new_run_id(now: dt.datetime) -> str:
    return f"{now:%H%M%S}-{secrets.token_hex(3)}"


class RunRecorder:
    """Writes one run folder as frames arrive; `close()` writes the metadata."""

    def __init__(self, root: Path, track_id: str, *, direction: str, driver: str, seed: int | None,
                 camera: CameraConfig | None = None, run_id: str | None = None,
                 started_at: dt.datetime | None = None, extra: dict[str, Any] | None = None,
                 row_by_row: bool = False) -> None:
        """`row_by_row` hands each controls row to the OS as it is added (line buffering), so a process killed
        mid-run leaves every row it had added on disk: the booth's live drive acknowledges each one."""
        self.started_at = started_at or dt.datetime.now(dt.UTC)
        self.run_id = run_id or new_run_id(self.started_at)
        self.path = Path(root) / track_id / f"{self.started_at:%Y-%m-%d}" / self.run_id
        (self.path / "frames").mkdir(parents=True, exist_ok=False)
        self._controls = (self.path / "controls.jsonl").open("w", buffering=1 if row_by_row else -1)
        self.frames = 0
        self._meta = {"run_id": self.run_id, "track_id": track_id, "direction": direction, "driver": driver,
                      "source": "sim", "seed": seed, "camera": camera.as_dict() if camera else None, **(extra or {})}

    def add(self, frame: np.ndarray, action: dict[str, float], params: dict[str, Any], *, t_ms: int, lap: int,
            offtrack: bool, car_speed: float | None = None, extra: dict[str, Any] | None = None) -> None:
        if frame.shape != (120, 160) or frame.dtype != np.uint8:
            raise RunError(f"a run frame is 160x120 uint8 grayscale, got {frame.shape} {frame.dtype}")
        name = f"frames/{self.frames:06d}.png"
        if not cv2.imwrite(str(self.path / name), frame):
            raise RunError(f"could not write {self.path / name}")
        row = {"index": self.frames, "frame": name, "t_ms": int(t_ms),
               "steering_angle": round(float(action["steering_angle"]), 4), "speed": round(float(action["speed"]), 4),
               "progress": round(float(params["progress"]), 3), "x": round(float(params["x"]), 4),
               "y": round(float(params["y"]), 4), "heading": round(float(params["heading"]), 3), "lap": lap,
               "offtrack": bool(offtrack), **(extra or {})}
        if car_speed is not None:
            row["car_speed"] = round(float(car_speed), 4)
        self._controls.write(json.dumps(row) + "\n")
        self.frames += 1

    def add_labelled(self, frame: np.ndarray, label: dict[str, float], executed: dict[str, float],
                     params: dict[str, Any], *, t_ms: int, lap: int, executed_offtrack: bool) -> None:
        """A DAgger row: `label` (what the demonstrator would do) is the training target; what was really
        executed, and whether that left the track, is kept beside it."""
        self.add(frame, label, params, t_ms=t_ms, lap=lap, offtrack=False,
                 extra={"executed_steering_angle": round(float(executed["steering_angle"]), 4),
                        "executed_speed": round(float(executed["speed"]), 4), "model_offtrack": executed_offtrack})

    def close(self, *, laps: int, lap_times_ms: list[int], resets: int = 0) -> Path:
        self._controls.close()
        meta = {**self._meta, "started_at": self.started_at.isoformat(),
                "ended_at": dt.datetime.now(dt.UTC).isoformat(), "frames": self.frames, "laps": laps,
                "lap_times_ms": lap_times_ms, "resets": resets}
        (self.path / "metadata.json").write_text(json.dumps(meta, indent=2) + "\n")
        return self.path


def record_run(env: RaceEnv, policy: Policy, root: Path, *, laps: int, driver: str, seed: int = 0,
               max_steps: int | None = None, run_id: str | None = None) -> Path:
    """Drive `policy` in `env` until `laps` laps are done (or `max_steps` frames) and write a run folder."""
    if env.camera is None:
        raise RunError("recording needs a camera: build the env with EnvConfig(observe=True)")
    limit = max_steps or int(laps * 120 * env.config.decision_hz)  # 2 min a lap is a stuck car
    track = env.track
    recorder = RunRecorder(Path(root), track.track_id, direction="reverse" if track.is_reversed else "forward",
                           driver=driver, seed=seed, camera=env.camera.config, run_id=run_id,
                           extra={"track_direction": track.direction, "decision_hz": env.config.decision_hz})
    obs, info = env.reset(seed=seed)
    params = info["params"]
    for _ in range(limit):
        assert obs is not None  # the env has a camera (checked above)
        action = policy(obs, params)
        t_ms, lap, seen = round(env.sim_time * 1000), env.laps, params
        next_obs, params, terminated, truncated, info = env.step(action)
        recorder.add(obs, action, seen, t_ms=t_ms, lap=lap, offtrack=bool(params["is_offtrack"]))
        obs = next_obs
        # A row shows the lap the car was on when it saw its frame, so the crossing shows on the row after it: stop
        # once a row has recorded the last lap (stopping on the crossing step itself would lose that lap).
        if lap >= laps or terminated or truncated:
            break
    return recorder.close(**whole_lap_figures(env))


def whole_lap_figures(env: RaceEnv, *, since_lap: int = 0, since_resets: int = 0) -> dict[str, Any]:
    """A run's `laps`, `lap_times_ms` and `resets` for its metadata: the laps that count (`env.whole_laps`), not every
    time the car came round (`env.laps` also counts a lap finished from where the car was put back)."""
    times = env.whole_laps.lap_times_s[since_lap:]
    return {"laps": len(times), "lap_times_ms": [round(t * 1000) for t in times], "resets": env.resets - since_resets}


# ---- S3 ---------------------------------------------------------------------------------------
def run_key_prefix(run_dir: Path) -> str:
    """`runs/{track_id}/{date}/{run_id}/` from a run folder's last three path parts."""
    run_dir = Path(run_dir)
    if not (run_dir / "controls.jsonl").is_file() or not (run_dir / "metadata.json").is_file():
        raise RunError(f"{run_dir}: not a finished run folder (needs controls.jsonl and metadata.json)")
    track_id, date, run_id = run_dir.parts[-3:]
    return f"runs/{track_id}/{date}/{run_id}/"


def pack_frames(run_dir: Path, rows: int | None = None) -> bytes:
    """The run folder's frames as one uncompressed tar (`frames/{index:06d}.png` members, in order).

    With `rows` (how many whole controls rows the run has) only the frames those rows name go in: a process killed
    while it wrote a frame leaves that frame empty or cut, with no row yet (the frame is written first), and a bundle
    holding it would be refused whole by `read_frames`, losing every answered decision with it."""
    paths = sorted((Path(run_dir) / "frames").glob("*.png"))
    if rows is not None:
        paths = [path for path in paths if path.stem.isdigit() and int(path.stem) < rows]
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w", format=tarfile.USTAR_FORMAT) as bundle:
        for path in paths:
            data = path.read_bytes()
            info = tarfile.TarInfo(f"frames/{path.name}")
            info.size, info.mode = len(data), 0o600
            bundle.addfile(info, io.BytesIO(data))
    return buffer.getvalue()


def read_frames(data: bytes) -> Iterator[tuple[str, bytes]]:
    """(name, PNG bytes) of each frame in a frames bundle; refuses anything but `frames/NNNNNN.png` files (no links,
    no paths out of the folder, nothing but a PNG, bounded sizes and count): a bundle may come from anyone."""
    try:
        with tarfile.open(fileobj=io.BytesIO(data), mode="r:") as bundle:
            for count, member in enumerate(bundle, start=1):
                if count > MAX_BUNDLE_FRAMES:
                    raise RunError(f"{FRAMES_BUNDLE} holds more than {MAX_BUNDLE_FRAMES} frames")
                if not member.isfile() or not FRAME_MEMBER.fullmatch(member.name):
                    raise RunError(f"{FRAMES_BUNDLE}: {member.name[:60]!r} is not a frames/NNNNNN.png file")
                if member.size > MAX_FRAME_BYTES:
                    raise RunError(f"{FRAMES_BUNDLE}: {member.name} is larger than a frame may be")
                handle = bundle.extractfile(member)
                png = handle.read() if handle is not None else b""
                if not png.startswith(b"\x89PNG\r\n\x1a\n"):
                    raise RunError(f"{FRAMES_BUNDLE}: {member.name} is not a PNG image")
                yield member.name, png
    except tarfile.TarError as error:
        raise RunError(f"{FRAMES_BUNDLE} is not a tar of frames: {error}") from None


def unpack_frames(data: bytes, run_dir: Path) -> int:
    """Write a frames bundle's PNGs into `run_dir/frames/`; returns the number of frames."""
    (Path(run_dir) / "frames").mkdir(parents=True, exist_ok=True)
    frames = 0
    for name, png in read_frames(data):
        (Path(run_dir) / name).write_bytes(png)
        frames += 1
    return frames


def run_objects(run_dir: Path, controls: bytes | None = None) -> dict[str, bytes]:
    """What a run folder stores in a bucket, metadata aside: the controls (`controls`, when given, instead of the
    file: a lost drive's whole rows), the frames those rows name in one bundle, and the first frame on its own (the
    run page links to it)."""
    run_dir = Path(run_dir)
    if controls is None:
        controls = (run_dir / "controls.jsonl").read_bytes()
    rows = controls.count(b"\n") + (0 if controls.endswith(b"\n") or not controls else 1)
    objects = {FRAMES_BUNDLE: pack_frames(run_dir, rows), "controls.jsonl": controls}
    first = run_dir / "frames" / "000000.png"
    if first.is_file():
        objects["frames/000000.png"] = first.read_bytes()
    return objects


def upload_run(s3_client: Any, bucket: str, run_dir: Path) -> str:
    """Upload a run folder (controls, one frames bundle, then metadata); returns its `s3://bucket/runs/.../` URI.
    Metadata goes last: its presence marks a complete upload."""
    run_dir = Path(run_dir)
    prefix = run_key_prefix(run_dir)
    for name, data in run_objects(run_dir).items():
        s3_client.put_object(Bucket=bucket, Key=prefix + name, Body=data)
    s3_client.upload_file(str(run_dir / "metadata.json"), bucket, prefix + "metadata.json")
    return f"s3://{bucket}/{prefix}"


def parse_s3_uri(uri: str) -> tuple[str, str]:
    if not uri.startswith("s3://") or "/" not in uri[5:]:
        raise RunError(f"{uri!r}: expected s3://bucket/runs/{{track_id}}/{{date}}/{{run_id}}/")
    bucket, _, prefix = uri[5:].partition("/")
    return bucket, prefix.rstrip("/") + "/"


def download_run(uri: str, target: Path, s3_client: Any | None = None) -> Path:
    """Download the run at `s3://bucket/runs/.../` into `target/{run_id}`; returns that folder."""
    bucket, prefix = parse_s3_uri(uri)
    client = s3_client or default_s3_client()
    folder = Path(target) / PurePosixPath(prefix).name
    keys = []
    for page in client.get_paginator("list_objects_v2").paginate(Bucket=bucket, Prefix=prefix):
        keys += [item["Key"] for item in page.get("Contents", [])]
    if prefix + "metadata.json" not in keys:
        raise RunError(f"{uri}: no complete run there (metadata.json missing)")
    if prefix + FRAMES_BUNDLE in keys:  # one object for all the frames; loose ones (the first) are copies
        body = client.get_object(Bucket=bucket, Key=prefix + FRAMES_BUNDLE)["Body"]
        unpack_frames(body.read(), folder)
        keys = [key for key in keys if not key.startswith(prefix + "frames/") and key != prefix + FRAMES_BUNDLE]
    for key in keys:
        relative = PurePosixPath(key[len(prefix):])
        if ".." in relative.parts or relative.is_absolute():
            raise RunError(f"{uri}: refusing key {key!r} that leaves the run folder")
        local = folder.joinpath(*relative.parts)
        local.parent.mkdir(parents=True, exist_ok=True)
        client.download_file(bucket, key, str(local))
    return folder


def default_s3_client() -> Any:
    import boto3  # only when S3 is really used

    return boto3.client("s3")


def runs_bucket_name() -> str:
    """The stage's runs bucket (DREM_STAGE, or DREM_BUCKET_RUNS to override)."""
    from drem_infra.resources import bucket_name

    return bucket_name(os.environ.get("DREM_STAGE", "local"), "runs")
