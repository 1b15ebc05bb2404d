"""`drem sim eval` metrics: the file the model registry's evaluation upload accepts, written where --out says."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from chalicelib.domain.model_registry import EvaluationInput
from drem_local.cli import main

pytestmark = pytest.mark.sim

SAMPLES = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples"


@pytest.mark.parametrize("out_name", ["eval/sample-metrics.json", "eval-folder"])
def test_eval_writes_registry_ready_metrics_to_a_file_or_folder(tmp_path: Path, capsys, out_name: str) -> None:
    out = tmp_path / out_name
    assert main(["sim", "eval", "--model", str(SAMPLES / "drem-bc-sample.tar.gz"), "--track", "reinvent_base",
                 "--laps", "1", "--out", str(out)]) == 0

    path = out if out.suffix == ".json" else out / "metrics.json"
    metrics = json.loads(path.read_text())
    accepted = EvaluationInput.model_validate(metrics)
    assert accepted.track == "reinvent_base" and accepted.source == "sim"
    assert accepted.attempts == 1 and accepted.laps_completed == 1 and accepted.completion_pct == 100.0
    assert len(accepted.lap_times_s) == 1 and 7.0 < accepted.lap_times_s[0] < 15.0
    assert f"metrics      {path}" in capsys.readouterr().out


@pytest.mark.parametrize(("archive", "track"), [
    ("drem-bc-sample.tar.gz", "reinvent_base"),
    ("drem-bc-wide.tar.gz", "reInvent2019_wide"),
    ("drem-bc-wide-cw.tar.gz", "reInvent2019_wide_cw"),
    ("drem-bc-oval.tar.gz", "drem_oval"),
])
def test_each_sample_model_laps_its_track(archive: str, track: str) -> None:
    from drem_sim.learn.evaluate import evaluate_model

    metrics = evaluate_model(SAMPLES / archive, track, laps=2)
    assert metrics.laps_completed == 2, metrics.summary()
    assert (SAMPLES / archive).stat().st_size < 2_000_000
