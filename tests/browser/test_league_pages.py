"""The league board and the model registry in a real browser, against the live local stack: exports pushed with
`drem league push` over HTTP, a model uploaded through the presigned POST, evaluations posted like a client would."""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import pytest
import requests

from tests.browser.console_api import PASSWORD, access_token, call, create_user, sign_in
from tests.unit.league_helpers import console_old_export, drfc_export
from tests.unit.models_helpers import DREM_METADATA, onnx_policy, tar_gz

pytestmark = pytest.mark.browser
def _push(url: str, username: str, path: Path, track: str) -> int:
    from drem_local.commands import league

    args = argparse.Namespace(action="push", api=url, token=None, username=username, password=PASSWORD, path=[path],
                              track=track, racer=None, model_name=None, dry_run=False,
                              self_reported=True)
    return league.run(args)


def test_league_board_with_hyperparameters_on_demand(live_stack: Any, app_url: str, page: Any,
                                                     tmp_path: Path) -> None:
    for name in ("lea", "ben"):
        create_user(live_stack, name, "racer")
    assert _push(app_url, "lea", console_old_export(tmp_path / "lea-fast", world="reinvent_base",
                                                        laps=[(15100, 100), (15900, 100)]), "reinvent_base") == 0
    assert _push(app_url, "ben", drfc_export(tmp_path / "ben-sac", world="reinvent_base",
                                                laps=[(15400, 100), (15500, 100)]), "reinvent_base") == 0
    page.goto(app_url + "/league/reinvent_base")
    rows = page.locator("tr.league-row")
    assert rows.count() == 2
    assert rows.nth(0).get_attribute("data-racer") == "lea"
    page.select_option("select[name=sort]", "avg")
    page.get_by_role("button", name="Show").click()
    page.wait_for_url("**sort=avg**")
    assert page.locator("tr.league-row").nth(0).get_attribute("data-racer") == "ben"
    page.locator('tr.league-row[data-racer="ben"]').click()
    hyper = page.get_by_test_id("league-hyperparameters")
    hyper.wait_for()
    assert "sac_alpha" in hyper.inner_text() and "0.2" in hyper.inner_text()


def test_model_registry_dashboard(live_stack: Any, app_url: str, page: Any) -> None:
    create_user(live_stack, "rita", "racer")
    token = access_token(live_stack, "rita")
    lineage = {"network": "DREM_SMALL_CNN", "epochs_run": 3, "batch_size": 32, "learning_rate": 0.001,
               "dataset": {"runs": [{"run_id": "run-lap-17", "track_id": "reinvent_base"}]},
               "train_losses": [0.8, 0.4, 0.2], "validation_losses": [0.9, 0.5, 0.3]}
    archive = tar_gz([("model.onnx", onnx_policy(0.3)), ("model_metadata.json", json.dumps(DREM_METADATA).encode()),
                      ("training/lineage.json", json.dumps(lineage).encode())])
    ticket = call(app_url, "POST", "/api/models", token=token, body={"filename": "rita-bc.tar.gz"})
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": ("rita-bc.tar.gz", archive)}, timeout=15)
    assert posted.status_code in (200, 204), posted.text
    model_id = ticket["model"]["model_id"]
    assert call(app_url, "POST", f"/api/models/{model_id}/complete", token=token)["model"]["status"] == "AVAILABLE"
    for track, laps in (("reinvent_base", [19.5, 18.75]), ("Oval_track", [9.25])):
        call(app_url, "POST", f"/api/models/{model_id}/evaluations", token=token,
             body={"track": track, "attempts": 2, "laps_completed": len(laps), "completion_pct": 90.0,
                   "offtrack_count": 2 - len(laps), "lap_times_s": laps, "steering_jitter_deg": 1.1})
    sign_in(page, app_url, "rita")
    page.goto(app_url + "/models/registry")
    assert page.locator("svg[data-testid=plot-tracks] rect").count() == 2
    assert page.locator("svg[data-testid=plot-lap-times] circle").count() >= 1
    row = page.locator('tr.registry-row[data-model="rita-bc"]')
    assert "reinvent_base: 90 % complete" in row.inner_text()
    row.click()
    page.get_by_test_id("registry-lineage").wait_for()
    assert "run-lap-17 (reinvent_base)" in page.get_by_test_id("registry-model").inner_text()
    assert page.locator("svg[data-testid=plot-loss] polyline").count() == 2
