"""Every shipped track loads and races in both directions; an open route is refused for racing; a damaged, malformed
or changed route file is refused with a message naming the track."""
from __future__ import annotations

import hashlib
import shutil

import numpy as np
import pytest

from drem_sim.env import RaceEnv
from drem_sim.tracks import CHECKSUMS_FILE, PACKAGE_TRACKS_DIR, TrackError, available_tracks, load_track

pytestmark = pytest.mark.sim

SHIPPED = sorted(available_tracks())


def test_every_real_track_ships_inside_drem_byte_for_byte(tracks_dir, monkeypatch) -> None:
    """The 22 route files of the shared test data are package data (found with no other folder configured), with the
    same bytes as their upstream checksums, and the licence notice beside them."""
    monkeypatch.delenv("DREM_TRACKS_DIR", raising=False)
    upstream = {line.split()[1]: line.split()[0]
                for line in (tracks_dir / "SHA256SUMS").read_text().splitlines() if line.strip()}
    assert len(upstream) == 22
    found = available_tracks()
    for name, digest in upstream.items():
        assert found[name.removesuffix(".npy")].parent == PACKAGE_TRACKS_DIR, name
        assert hashlib.sha256((PACKAGE_TRACKS_DIR / name).read_bytes()).hexdigest() == digest, name
    assert "Apache License" in (PACKAGE_TRACKS_DIR / "LICENSE-Apache-2.0.txt").read_text()
    assert "deepracer-simapp" in (PACKAGE_TRACKS_DIR / "NOTICE.md").read_text()
    assert {"drem_oval", "drem_chicane"} <= set(SHIPPED)


@pytest.mark.parametrize("name", [n for n in SHIPPED if (PACKAGE_TRACKS_DIR / f"{n}.npy").is_file()])
def test_repeated_waypoints_leave_no_zero_length_segment(name: str) -> None:
    raw = np.load(PACKAGE_TRACKS_DIR / f"{name}.npy")
    track = load_track(name)
    steps = np.hypot(*np.diff(track.centerline, axis=0).T)
    assert steps.min() > 1e-6 and np.isfinite(track.length)
    assert track.n_waypoints <= len(raw)
    progress = track.progress(track.centerline[len(track.centerline) // 2])
    assert 0.0 < progress < 100.0 and np.isfinite(progress)


def _copy_of_shipped_folder(tmp_path, monkeypatch):
    folder = tmp_path / "tracks"
    shutil.copytree(PACKAGE_TRACKS_DIR, folder)
    monkeypatch.setattr("drem_sim.tracks.PACKAGE_TRACKS_DIR", folder)
    return folder


def test_a_route_file_that_does_not_match_its_checksum_is_refused_naming_the_track(tmp_path, monkeypatch) -> None:
    folder = _copy_of_shipped_folder(tmp_path, monkeypatch)
    data = np.load(folder / "reinvent_base.npy")
    data[5, 0] += 0.5  # a valid array with one waypoint moved
    np.save(folder / "reinvent_base.npy", data)
    with pytest.raises(TrackError, match=r"track 'reinvent_base': .* does not match its checksum"):
        load_track("reinvent_base")
    assert load_track("Spain_track").length == pytest.approx(60.0, abs=0.05)  # the others still load


def test_a_truncated_route_file_is_refused_naming_the_track(tmp_path, monkeypatch) -> None:
    folder = _copy_of_shipped_folder(tmp_path, monkeypatch)
    (folder / CHECKSUMS_FILE).unlink()  # without the checksum, the reader itself must notice
    path = folder / "Austin.npy"
    path.write_bytes(path.read_bytes()[:700])
    with pytest.raises(TrackError, match=r"track 'Austin': .* not a readable \.npy route file"):
        load_track("Austin")


def test_a_staff_track_folder_adds_tracks_but_never_replaces_a_shipped_one(tmp_path, monkeypatch) -> None:
    staff = tmp_path / "staff"
    staff.mkdir()
    data = np.load(PACKAGE_TRACKS_DIR / "reinvent_base.npy")
    np.save(staff / "venue_copy.npy", data)
    np.save(staff / "reinvent_base.npy", data * 2.0)  # same name, other shape: must not win
    np.save(staff / "flat.npy", np.zeros((10, 4)))
    monkeypatch.setenv("DREM_TRACKS_DIR", str(staff))
    assert load_track("venue_copy").length == pytest.approx(17.71, abs=0.05)
    assert load_track("reinvent_base").length == pytest.approx(17.71, abs=0.05)
    with pytest.raises(TrackError, match=r"track 'flat': .*N×6"):
        load_track("flat")


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("reverse", [False, True])
def test_track_loads_in_both_directions(name: str, reverse: bool) -> None:
    track = load_track(name, reverse=reverse)
    assert track.length > 4.0
    assert 0.5 < track.width < 1.5  # Austin and Singapore are 1.43 and 1.45 m wide
    assert track.is_reversed == reverse
    if track.is_closed:
        forward = load_track(name)
        assert track.length == pytest.approx(forward.length)
        assert track.direction != forward.direction or not reverse


def test_known_track_facts() -> None:
    base = load_track("reinvent_base")
    assert base.length == pytest.approx(17.71, abs=0.05)
    assert base.width == pytest.approx(0.762, abs=0.01)
    assert base.direction == "CCW"
    assert load_track("reinvent_base", reverse=True).direction == "CW"


def test_open_route_is_refused_for_racing_with_a_clear_error() -> None:
    straight = load_track("Straight_track")
    assert not straight.is_closed
    with pytest.raises(TrackError, match="open route"):
        RaceEnv(straight)


def test_unknown_track_names_the_known_ones() -> None:
    with pytest.raises(TrackError, match="reinvent_base"):
        load_track("no_such_track")


def test_malformed_yaml_track_is_rejected(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("track_id: bad\ncenterline: [[0, 0], [1, 0], [1, 1]]\n")  # neither width nor borders
    with pytest.raises(TrackError, match="width"):
        load_track(bad)
