"""Generated training tracks: the same track from the same seed on every machine, hairpins and coarse route files
among them, never two stretches overlapping, every one driven clean by the demonstrator both ways round, and usable
wherever a track name is (`drem train --tracks generated-1..10`, DAgger, evaluation)."""
from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from drem_sim.demonstrator import Demonstrator
from drem_sim.env import EnvConfig, RaceEnv
from drem_sim.learn.dagger import record_demonstrations
from drem_sim.learn.track_sets import TrackDirection, TrackSetError, expand, hold_out
from drem_sim.tracks import load_track

pytestmark = pytest.mark.sim

REPO = Path(__file__).resolve().parents[2]
DREM = REPO / ".venv" / "bin" / "drem"
TRAINING_SET = [f"generated-{seed}" for seed in range(1, 11)]  # what bench/lfd.py and docs/learning.md train on


def corners_deg(track) -> np.ndarray:
    step = np.roll(track.centerline, -1, axis=0) - track.centerline
    heading = np.arctan2(step[:, 1], step[:, 0])
    return np.degrees(np.abs(np.angle(np.exp(1j * (np.roll(heading, -1) - heading)))))


def test_a_seed_is_the_same_track_every_time_and_seeds_differ() -> None:
    first, again, other = load_track("generated-3"), load_track("generated-3"), load_track("generated-4")
    assert np.array_equal(first.centerline, again.centerline) and np.array_equal(first.outer, again.outer)
    assert first.length != pytest.approx(other.length)
    assert first.is_closed and first.name == "generated-3"
    back = load_track("generated-3", reverse=True)
    assert back.is_reversed and back.length == pytest.approx(first.length)


def test_the_training_set_has_coarse_route_files_with_sharp_corners_and_real_widths() -> None:
    """What the set is for: corners as sharp as a coarse real route file's (hamption_pro: 0.70 m apart, 85.5°)."""
    tracks = [load_track(name) for name in TRAINING_SET]
    coarse_and_sharp = [t.name for t in tracks
                        if np.hypot(*np.diff(t.centerline, axis=0).T).mean() >= 0.5 and corners_deg(t).max() >= 60]
    assert len(coarse_and_sharp) >= 3, coarse_and_sharp
    assert {round(t.width, 2) for t in tracks} <= {0.76, 0.91, 1.07}
    assert all(14.0 <= t.length <= 45.0 for t in tracks)


def test_the_timing_line_is_on_a_straight_so_a_car_cutting_a_corner_cannot_pass_beside_it() -> None:
    """A line across a sharp corner let a model lap to 99.9 % and never cross it (found on generated-37 and -53)."""
    for name in ("generated-37", "generated-53", *TRAINING_SET):
        at_vertex = np.roll(corners_deg(load_track(name)), 1)  # corners_deg[i] is the turn at waypoint i + 1
        leaving = sum(np.roll(at_vertex, -k) for k in range(-1, 4))  # what a car crossing at waypoint i drives into
        assert leaving[0] <= np.percentile(leaving, 10), (name, leaving[0], np.percentile(leaving, 10))


@pytest.mark.parametrize("name", TRAINING_SET)
def test_no_two_stretches_overlap_and_the_demonstrator_laps_it_both_ways(name: str) -> None:
    track = load_track(name)
    centre, s = track.centerline, track.cumulative[:-1]
    gap = np.hypot(*(centre[:, None, :] - centre[None, :, :]).transpose(2, 0, 1))
    apart = np.abs(s[:, None] - s[None, :])
    apart = np.minimum(apart, track.length - apart)
    far_along = apart > 3.0 * track.width + 1.5
    assert (gap[far_along] >= track.width + 0.4).all(), "two stretches of the loop touch"
    for direction in (track, track.reversed()):
        env = RaceEnv(direction, EnvConfig(observe=False))
        teacher = Demonstrator(direction)
        env.reset(seed=0)
        for _ in range(3000):
            _, params, _, _, info = env.step(teacher.act(env.car_state()))
            assert not params["is_offtrack"], f"{direction.name} reversed={direction.is_reversed}"
            if info["laps"] >= 2:
                break
        assert info["laps"] >= 2


def test_a_range_spec_names_each_generated_track_and_bad_ranges_are_refused() -> None:
    picked = expand(["all,generated-1..3"], both_directions=True)
    generated = [d.label for d in picked if d.name.startswith("generated-")]
    assert generated == ["generated-1", "generated-1:reverse", "generated-2", "generated-2:reverse",
                         "generated-3", "generated-3:reverse"]
    kept, held = hold_out(picked, ["generated-2"], both_directions=True)
    assert TrackDirection("generated-2") not in kept and TrackDirection("generated-2", True) in held
    kept, held = hold_out(picked, ["generated-2..3"], both_directions=False)
    assert [d.label for d in kept if d.name.startswith("generated-")] == ["generated-1", "generated-1:reverse"]
    assert [d.label for d in held] == ["generated-2", "generated-3"]
    with pytest.raises(TrackSetError, match="the range is empty"):
        expand(["generated-5..2"])
    with pytest.raises(TrackSetError, match="at most 200"):
        expand(["generated-1..5000"])


def test_demonstrations_on_a_generated_track_are_run_folders_that_name_it(tmp_path: Path) -> None:
    runs = record_demonstrations([TrackDirection("generated-2", True)], tmp_path, laps=1, noise_deg=0.0, seed=0)
    meta = json.loads((runs[0] / "metadata.json").read_text())
    assert meta["track_id"] == "generated-2" and meta["direction"] == "reverse"
    assert meta["laps"] == 1 and meta["frames"] > 100


def test_the_installed_cli_evaluates_a_model_on_a_generated_track(tmp_path: Path) -> None:
    sample = REPO / "sim" / "drem_sim" / "samples"
    archive = sorted(sample.glob("*.tar.gz"))[0]
    done = subprocess.run([str(DREM), "sim", "eval", "--model", str(archive), "--track", "generated-4",
                           "--laps", "1", "--out", str(tmp_path)], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode in (0, 1), done.stderr  # 1: the sample did not lap it; the figures are still written
    assert "generated-4" in done.stdout
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["track"] == "generated-4" and metrics["attempts"] == 1


def test_the_installed_cli_evaluates_a_range_of_generated_tracks_one_line_each(tmp_path: Path) -> None:
    archive = REPO / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
    done = subprocess.run([str(DREM), "sim", "eval", "--model", str(archive), "--track", "generated-4..5",
                           "--laps", "1", "--out", str(tmp_path)], cwd=tmp_path, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode in (0, 1), done.stderr
    assert [line.split()[0] for line in done.stdout.splitlines() if line.startswith("generated-")] == [
        "generated-4", "generated-5"]
    for name in ("generated-4", "generated-5"):
        assert json.loads((tmp_path / f"metrics-{name}.json").read_text())["track"] == name
