"""`drem up --demo` drives a real DeepRacer track when the route files are there, and our own oval when they are not."""
from __future__ import annotations

from pathlib import Path

import pytest

from drem_local import demo

pytestmark = pytest.mark.unit

SAMPLES = Path(demo.__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples"


def test_the_demo_races_on_re_invent_2018_when_the_route_files_are_there():
    assert demo.demo_track_and_sample() == ("reinvent_base", "drem-bc-sample")


def test_a_clone_without_the_route_files_races_on_the_oval_that_ships_with_drem(monkeypatch, tmp_path):
    import drem_sim.tracks as tracks

    monkeypatch.setattr(tracks, "DEFAULT_NPY_DIR", tmp_path / "no-shared-folder")
    monkeypatch.delenv(tracks.TRACKS_DIR_ENV, raising=False)

    assert demo.demo_track_and_sample() == ("drem_oval", "drem-bc-oval")


def test_every_demo_sample_ships_with_drem():
    for _track, sample in demo.SIM_TRACKS_AND_SAMPLES:
        assert (SAMPLES / f"{sample}.tar.gz").is_file(), sample
