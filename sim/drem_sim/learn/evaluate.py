"""Drive a model (or any policy) round a track in the simulator and measure how it races.

The whole-lap rule is `drem_leaderboard.laps` (the one copy every figure uses). A *lap attempt* starts on the
timing line (the standing start of an episode, or a crossing) and ends either at the next crossing (a completed
lap, 100 %, timed crossing to crossing) or where the car leaves the track (the progress it had reached from the
line). The simulator then puts the car back; the stretch from there to the next crossing is no attempt: it is
neither a lap (the car never took the bend it left the track on) nor counted in completion (it would lift it with
progress measured from the wrong place). Completion % is the mean progress of the attempts, as in a DeepRacer
evaluation; an attempt from the line still under way when the drive stops counts with what it reached.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel

from drem_leaderboard.laps import LapAttempts

Policy = Callable[[np.ndarray, dict[str, Any]], dict[str, float]]

SIM_SECONDS_PER_LAP_LIMIT = 90.0  # an attempt slower than this is a stuck car, not a lap


class EvalMetrics(BaseModel):
    """What `metrics.json` holds; `track, attempts, laps_completed, completion_pct, offtrack_count, lap_times_s,
    steering_jitter_deg, source` are what the model registry's evaluation upload reads."""
    model: str
    track: str
    source: str = "sim"
    seed: int
    laps_requested: int
    attempts: int
    laps_completed: int
    laps_completed_pct: float
    completion_pct: float
    attempt_progress: list[float]
    offtrack_count: int
    resets: int
    lap_times_s: list[float]
    mean_lap_time_s: float | None
    best_lap_time_s: float | None
    steering_jitter_deg: float
    steps: int
    sim_seconds: float

    def summary(self) -> str:
        mean = f"{self.mean_lap_time_s:.2f}s" if self.mean_lap_time_s is not None else "-"
        return (f"{self.model} on {self.track}: {self.laps_completed}/{self.attempts} laps completed "
                f"({self.laps_completed_pct:.0f}%), completion {self.completion_pct:.1f}%, "
                f"off-track {self.offtrack_count}, mean lap {mean}, steering jitter {self.steering_jitter_deg:.2f} deg")


def drive(env: Any, policy: Policy, attempts: int, seed: int, label: str, track_name: str,
          max_steps: int | None = None) -> EvalMetrics:
    """Run ``policy`` until ``attempts`` lap attempts have ended. A lap counts only when the car drove it whole,
    from the timing line (the standing start of an episode, or a crossing) to the next crossing, without leaving the
    track; its time is crossing to crossing. After an off-track the env is restarted where it put the car back: the
    stretch from there to the line is no lap and no attempt (the car never took the bend it left the track on)."""
    observation, info = env.reset(seed=seed)
    params: dict[str, Any] = dict(info.get("params", {})) if isinstance(info, dict) else {}
    step_seconds = float(getattr(env, "step_seconds", 1.0 / 15.0))
    limit = max_steps or int(attempts * SIM_SECONDS_PER_LAP_LIMIT / step_seconds)
    laps = LapAttempts()  # the whole-lap rule every figure uses (drem_leaderboard.laps)
    steering: list[float] = []
    offtrack = 0
    resets_before = _resets(info)
    steps = 0
    while len(laps.attempts) < attempts and steps < limit:
        action = policy(observation, params)
        steering.append(float(action["steering_angle"]))
        observation, params, terminated, truncated, info = env.step(action)
        steps += 1
        distance = 100.0 * _laps(info) + float(params.get("progress", 0.0))  # never wraps, even backing up
        laps.moved(distance)
        if _resets(info) > resets_before or params.get("is_offtrack"):
            offtrack += 1
            laps.left_track()
            observation, info = env.reset(options={"start_offset_m": float(params.get("projection_distance", 0.0))})
            params = dict(info.get("params", {})) if isinstance(info, dict) else {}
            resets_before = _resets(info)
            continue
        for event in info.get("strip_events", []) if isinstance(info, dict) else []:
            if len(laps.attempts) < attempts:
                laps.crossed(float(event["timestamp_ms"]) / 1000.0, distance)
        if terminated or truncated:
            observation, info = env.reset(seed=seed + len(laps.attempts) + 1)
            params = dict(info.get("params", {})) if isinstance(info, dict) else {}
            resets_before = _resets(info)
            laps.restart_on_line(0.0)
    progress_log = laps.ended(out_of_time=len(laps.attempts) < attempts)[:attempts]
    lap_times = laps.lap_times_s
    completed = sum(1 for p in progress_log if p >= 100.0)
    deltas = np.diff(np.asarray(steering)) if len(steering) > 1 else np.zeros(1)
    lap_times = lap_times[:completed]
    return EvalMetrics(
        model=label, track=track_name, seed=seed, laps_requested=attempts, attempts=len(progress_log),
        laps_completed=completed, laps_completed_pct=round(100.0 * completed / max(len(progress_log), 1), 2),
        completion_pct=round(float(np.mean(progress_log)), 2), attempt_progress=[round(p, 2) for p in progress_log],
        offtrack_count=offtrack, resets=offtrack, lap_times_s=[round(t, 3) for t in lap_times],
        mean_lap_time_s=round(float(np.mean(lap_times)), 3) if lap_times else None,
        best_lap_time_s=round(float(np.min(lap_times)), 3) if lap_times else None,
        steering_jitter_deg=round(float(np.std(deltas)), 3), steps=steps, sim_seconds=round(steps * step_seconds, 2),
    )


def _laps(info: Any) -> int:
    return int(info.get("laps", 0)) if isinstance(info, dict) else 0


def _resets(info: Any) -> int:
    return int(info.get("resets", 0)) if isinstance(info, dict) else 0


def evaluate_model(archive_or_dir: str | Path, track: str, laps: int = 3, seed: int = 0) -> EvalMetrics:
    from drem_sim.learn.pilot import OnnxPilot

    pilot = OnnxPilot.from_archive(archive_or_dir)  # refuse a bad archive before building a simulator
    from drem_sim.env import RaceEnv
    from drem_sim.tracks import load_track

    env = RaceEnv(load_track(track))
    label = Path(archive_or_dir).name
    return drive(env, lambda observation, _params: pilot.act(observation), laps, seed, label, track)


def main_eval(args: argparse.Namespace) -> int:
    """Entry point for ``drem sim eval --model M --track T --laps K [--out DIR]``."""
    from drem_sim.learn.package import ArchiveError

    try:
        metrics = evaluate_model(args.model, args.track, int(args.laps), int(getattr(args, "seed", 0) or 0))
    except ArchiveError as error:
        print(f"drem sim eval: {error}", file=sys.stderr)
        return 2
    print(metrics.summary())
    out = getattr(args, "out", None)
    if out:
        path = write_metrics(metrics, Path(out))
        print(f"metrics      {path}")
    return 0


def write_metrics(metrics: EvalMetrics, out: Path) -> Path:
    """`out` ending in .json is the file itself; anything else is a folder that gets `metrics.json`."""
    path = out if out.suffix.lower() == ".json" else out / "metrics.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(metrics.model_dump(), indent=2) + "\n")
    return path
