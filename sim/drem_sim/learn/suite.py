"""Evaluate one model on several (track, direction) pairs and report each one separately.

Averages over tracks flatter a model (a gentle track hides a tight one), so the suite keeps one
`EvalMetrics` per track and direction and states its verdict per row.
"""
from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from drem_sim.learn.evaluate import EvalMetrics, drive
from drem_sim.learn.track_sets import TrackDirection, parse_spec


def evaluate_directions(policy_factory: Callable[[], Callable[[Any, dict[str, Any]], dict[str, float]]],
                        directions: Sequence[TrackDirection], laps: int, seed: int, label: str,
                        observe: bool = True) -> list[EvalMetrics]:
    """Drive a fresh policy (from `policy_factory`) for `laps` lap attempts on each track and direction."""
    from drem_sim.env import EnvConfig, RaceEnv

    results = []
    for direction in directions:
        env = RaceEnv(direction.load(), EnvConfig(observe=observe))
        results.append(drive(env, policy_factory(), laps, seed, label, direction.label))
    return results


def evaluate_archive(archive: str | Path, directions: Sequence[TrackDirection], laps: int,
                     seed: int = 0) -> list[EvalMetrics]:
    from drem_sim.learn.pilot import OnnxPilot

    pilot = OnnxPilot.from_archive(archive)
    return evaluate_directions(lambda: (lambda observation, _params: pilot.act(observation)), directions, laps,
                               seed, Path(archive).name)


def table(rows: Sequence[EvalMetrics], reference: dict[str, EvalMetrics] | None = None) -> str:
    """A plain-text table: one line per track and direction (lap time ÷ reference when given)."""
    lines = [f"{'track':<32} {'laps':>7} {'done %':>7} {'progress':>9} {'off':>4} {'mean lap':>9} {'÷ ref':>6}"]
    for row in rows:
        mean = f"{row.mean_lap_time_s:.2f}s" if row.mean_lap_time_s is not None else "-"
        ratio = "-"
        ref = (reference or {}).get(row.track)
        if ref is not None and ref.mean_lap_time_s and row.mean_lap_time_s:
            ratio = f"{row.mean_lap_time_s / ref.mean_lap_time_s:.2f}"
        lines.append(f"{row.track:<32} {row.laps_completed:>3}/{row.attempts:<3} {row.laps_completed_pct:>6.0f}% "
                     f"{row.completion_pct:>8.1f}% {row.offtrack_count:>4} {mean:>9} {ratio:>6}")
    return "\n".join(lines)


def file_label(track: str) -> str:
    """A track spec as one safe file-name part: `tracks/venue.npy:reverse` → `venue-reverse` (a path in the spec
    must not become folders under --out). Only the spec's end says the direction: a folder may have a colon in its
    name (`/media/venue:2/hall.npy:reverse` → `hall-reverse`)."""
    spec = parse_spec(track)
    stem = Path(spec.name).name.removesuffix(".npy").removesuffix(".yaml")
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).strip(".") or "track"
    return f"{name}-reverse" if spec.reverse else name


def write_suite(rows: Sequence[EvalMetrics], folder: Path) -> Path:
    """`folder/metrics-<track>.json` per row (each one the registry's evaluation upload reads) and `suite.json`."""
    folder.mkdir(parents=True, exist_ok=True)
    for row in rows:
        (folder / f"metrics-{file_label(row.track)}.json").write_text(json.dumps(row.model_dump(), indent=2) + "\n")
    path = folder / "suite.json"
    path.write_text(json.dumps({"tracks": [row.model_dump() for row in rows]}, indent=2) + "\n")
    return path


def main_suite(args: Any) -> int:
    """`drem sim eval --track A --track B:reverse [--both-directions]`: one report row per track and direction."""
    import sys

    from drem_sim.learn.package import ArchiveError
    from drem_sim.learn.track_sets import TrackSetError, expand

    if args.out and Path(args.out).suffix.lower() == ".json":
        print("drem sim eval: several tracks write a folder; give --out a folder name", file=sys.stderr)
        return 2
    try:
        directions = expand(args.track, both_directions=bool(args.both_directions))
        rows = evaluate_archive(args.model, directions, int(args.laps), int(args.seed or 0))
    except (ArchiveError, TrackSetError) as error:
        print(f"drem sim eval: {error}", file=sys.stderr)
        return 2
    print(table(rows))
    if args.out:
        print(f"suite        {write_suite(rows, Path(args.out))}")
    return 0
