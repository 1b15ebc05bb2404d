"""`drem up --demo` drives a real DeepRacer track (shipped with drem), and our own oval when that file is gone."""
from __future__ import annotations

from pathlib import Path

import pytest

from drem_local import demo

pytestmark = pytest.mark.unit

SAMPLES = Path(demo.__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples"


def test_the_demo_races_on_re_invent_2018_which_ships_with_drem(monkeypatch):
    import drem_sim.tracks as tracks

    monkeypatch.delenv(tracks.TRACKS_DIR_ENV, raising=False)  # nothing but what the package holds

    assert demo.demo_track_and_sample() == ("reinvent_base", "drem-bc-sample")


def test_an_install_missing_the_route_file_races_on_the_oval_that_ships_with_drem(monkeypatch, tmp_path):
    import shutil

    import drem_sim.tracks as tracks

    damaged = tmp_path / "tracks"
    shutil.copytree(tracks.PACKAGE_TRACKS_DIR, damaged)
    (damaged / "reinvent_base.npy").unlink()
    monkeypatch.setattr(tracks, "PACKAGE_TRACKS_DIR", damaged)
    monkeypatch.delenv(tracks.TRACKS_DIR_ENV, raising=False)

    assert demo.demo_track_and_sample() == ("drem_oval", "drem-bc-oval")


def test_every_demo_sample_ships_with_drem():
    for _track, sample in demo.SIM_TRACKS_AND_SAMPLES:
        assert (SAMPLES / f"{sample}.tar.gz").is_file(), sample
