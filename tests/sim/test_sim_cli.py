"""`drem sim ...` through the real `drem` entry point."""
from __future__ import annotations

import json

import pytest

from drem_local.cli import main

pytestmark = pytest.mark.sim


def test_tracks_lists_length_width_and_direction(capsys) -> None:
    assert main(["sim", "tracks"]) == 0
    lines = {line.split()[0]: line.split() for line in capsys.readouterr().out.splitlines()[1:]}
    assert lines["reinvent_base"][1:] == ["17.71", "0.762", "CCW"]
    assert lines["Straight_track"][-1] == "open"
    assert "drem_oval" in lines


def test_demo_prints_lap_times_and_writes_a_map(capsys, tmp_path) -> None:
    assert main(["sim", "demo", "--track", "drem_chicane", "--reverse", "--png", str(tmp_path / "m.png")]) == 0
    out = capsys.readouterr().out
    assert "drem_chicane: 1 lap(s), resets 0, lap times" in out
    assert (tmp_path / "m.png").stat().st_size > 1000


def test_demo_on_an_open_route_is_a_clear_error(capsys) -> None:
    assert main(["sim", "demo", "--track", "Straight_track"]) == 2
    assert "open route" in capsys.readouterr().err


def test_record_writes_a_run_folder(capsys, tmp_path) -> None:
    assert main(["sim", "record", "--track", "drem_oval", "--laps", "1", "--noise", "1.0",
                 "--out", str(tmp_path)]) == 0
    (meta_path,) = tmp_path.glob("drem_oval/*/*/metadata.json")
    meta = json.loads(meta_path.read_text())
    assert meta["laps"] == 1 and meta["frames"] > 100
    assert f"run          {meta_path.parent}" in capsys.readouterr().out


def test_record_upload_without_a_local_stack_is_refused(capsys, tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("AWS_ENDPOINT_URL", raising=False)
    assert main(["sim", "record", "--upload", "--out", str(tmp_path)]) == 2
    assert "AWS_ENDPOINT_URL" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_eval_refuses_a_broken_archive(capsys, tmp_path) -> None:
    bad = tmp_path / "bad.tar.gz"
    bad.write_bytes(b"not an archive")
    assert main(["sim", "eval", "--model", str(bad), "--track", "reinvent_base", "--laps", "1"]) == 2
    assert "bad.tar.gz" in capsys.readouterr().err
