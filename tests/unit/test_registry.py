"""Model registry: evaluations per model version (owner or staff), lineage read from the archive, SVG plots, and who
sees which models."""
from __future__ import annotations

import json
from typing import Any

import pytest

from chalicelib.views import svg_plots
from tests.unit.models_helpers import DREM_METADATA, ModelsApi, bearer, onnx_policy, tar_gz

pytestmark = pytest.mark.unit

LINEAGE = {"network": "DREM_SMALL_CNN", "parameters": 4242, "seed": 3, "epochs_run": 3, "batch_size": 32,
           "learning_rate": 0.001, "dataset": {"runs": [{"run_id": "run-2026-01-01-a", "track_id": "reinvent_base"}]},
           "train_losses": [0.9, 0.5, 0.3], "validation_losses": [1.0, 0.7, 0.45]}


def metrics(track: str, laps: list[float], attempts: int = 3, jitter: float = 1.25) -> dict[str, Any]:
    return {"model": "x.tar.gz", "track": track, "seed": 0, "laps_requested": attempts, "attempts": attempts,
            "laps_completed": len(laps), "laps_completed_pct": 0.0, "completion_pct": 100.0 * len(laps) / attempts,
            "attempt_progress": [], "offtrack_count": attempts - len(laps), "resets": 0, "lap_times_s": laps,
            "mean_lap_time_s": None, "best_lap_time_s": None, "steering_jitter_deg": jitter, "steps": 1,
            "sim_seconds": 1.0}


def _models(api: ModelsApi) -> list[dict[str, Any]]:
    v1 = api.upload_and_complete("bc-v1.tar.gz", tar_gz([
        ("model.onnx", onnx_policy(0.1)), ("model_metadata.json", json.dumps(DREM_METADATA).encode()),
        ("training/lineage.json", json.dumps(LINEAGE).encode())]))
    v2 = api.upload_and_complete("bc-v2.tar.gz", tar_gz([
        ("model.onnx", onnx_policy(0.2)), ("model_metadata.json", json.dumps(DREM_METADATA).encode())]))
    assert v1["status"] == v2["status"] == "AVAILABLE"
    return [v1, v2]


def test_owner_records_evaluations_and_sees_plots(alice: ModelsApi, client: Any) -> None:
    v1, v2 = _models(alice)
    for model, track, laps in ((v1, "reinvent_base", [20.5, 19.25]), (v2, "reinvent_base", [18.0]),
                               (v2, "Oval_track", [9.5, 9.0])):
        reply = alice.call("POST", f"/api/models/{model['model_id']}/evaluations", metrics(track, laps))
        assert reply.status_code == 201, reply.json_body
    stored = alice.call("GET", f"/api/models/{v1['model_id']}/evaluations").json_body["evaluations"]
    assert [(e["track"], e["best_lap_s"], e["mean_lap_s"], e["offtrack_count"]) for e in stored] == [
        ("reinvent_base", 19.25, 19.875, 1)]
    page = client.http.get("/models/registry", headers={"Authorization": alice.headers["Authorization"]})
    assert page.status_code == 200
    html = page.body.decode()
    rows = html[html.index('data-testid="registry-rows"'):]
    assert rows.count('class="registry-row"') == 2 and rows.index("bc-v2") < rows.index("bc-v1")  # newest first
    assert 'data-testid="plot-lap-times"' in html and "<polyline" in html and 'data-testid="plot-tracks"' in html
    assert "reinvent_base: 33 % complete, 2 off track, best 18.000 s, jitter 1.25°" in html


def test_detail_shows_lineage_and_loss_curve(alice: ModelsApi, client: Any) -> None:
    v1, v2 = _models(alice)
    detail = client.http.get(f"/models/registry/{v1['model_id']}",
                             headers={"Authorization": alice.headers["Authorization"]})
    html = detail.body.decode()
    assert detail.status_code == 200 and "<html" not in html
    assert "run-2026-01-01-a (reinvent_base)" in html and 'data-testid="plot-loss"' in html
    assert 'data-testid="registry-verdict">passed' in html
    plain = client.http.get(f"/models/registry/{v2['model_id']}",
                            headers={"Authorization": alice.headers["Authorization"]})
    assert "No training lineage" in plain.body.decode()


def test_other_racers_cannot_see_or_evaluate(alice: ModelsApi, client: Any, users: Any) -> None:
    v1, _ = _models(alice)
    bob = ModelsApi(client, bearer(users.access_token("bob", ("racer",))))
    evaluation = metrics("reinvent_base", [1.0])
    assert bob.call("POST", f"/api/models/{v1['model_id']}/evaluations", evaluation).status_code == 403
    assert bob.call("GET", f"/api/models/{v1['model_id']}/evaluations").status_code == 403
    as_json = {"Authorization": bob.headers["Authorization"], "Accept": "application/json"}
    assert client.http.get(f"/models/registry/{v1['model_id']}", headers=as_json).status_code == 403
    own = client.http.get("/models/registry", headers={"Authorization": bob.headers["Authorization"]}).body.decode()
    assert "bc-v1" not in own and 'data-testid="registry-empty"' in own
    assert client.http.get("/console/models/registry", headers={"Authorization": bob.headers["Authorization"],
                                                                  "Accept": "application/json"}).status_code == 403
    operator = ModelsApi(client, bearer(users.access_token("olga", ("operator",))))
    assert operator.call("POST", f"/api/models/{v1['model_id']}/evaluations",
                         metrics("reinvent_base", [20.0])).status_code == 201
    staff = client.http.get("/console/models/registry", headers={"Authorization": operator.headers["Authorization"]})
    assert staff.status_code == 200 and "bc-v1" in staff.body.decode() and "alice" in staff.body.decode()


def test_inconsistent_evaluation_names_the_field(alice: ModelsApi) -> None:
    v1, _ = _models(alice)
    bad = {**metrics("reinvent_base", [20.0]), "laps_completed": 2}
    reply = alice.call("POST", f"/api/models/{v1['model_id']}/evaluations", bad)
    assert reply.status_code == 400 and reply.json_body["error"]["field"] == "lap_times_s"
    reply = alice.call("POST", f"/api/models/{v1['model_id']}/evaluations", {**metrics("x y", [1.0])})
    assert reply.status_code == 400 and reply.json_body["error"]["field"] == "track"


def test_svg_plots_escape_labels() -> None:
    chart = svg_plots.line_chart([svg_plots.Series("<script>x</script>", [(0, 1.0), (1, 2.0)])], ["a&b", "v2"],
                                 title="t", y_label="s", testid="p")
    assert "<script>" not in chart and "&lt;script&gt;" in chart and "a&amp;b" in chart
    assert str(svg_plots.bar_chart([], title="none", y_label="s", testid="q")).startswith('<p class="plot-empty"')


def test_detail_shows_the_training_recipe_and_dagger_rounds(alice: ModelsApi, client: Any) -> None:
    lineage = {**LINEAGE, "augmentation": {"names": ["brightness", "shift", "blur"]},
               "dagger": {"round": 2, "rounds": 2, "train_tracks": ["reinvent_base", "reinvent_base:reverse"],
                          "held_out_tracks": ["reInvent2019_track"],
                          "previous_rounds": [{"round": 0, "evaluation": [
                              {"track": "reInvent2019_track", "laps_completed": 1, "attempts": 5}]},
                              {"round": 1, "evaluation": [
                                  {"track": "<b>reInvent2019_track</b>", "laps_completed": 4, "attempts": 5}]}]}}
    model = alice.upload_and_complete("dagger-r2.tar.gz", tar_gz([
        ("model.onnx", onnx_policy(0.1)), ("model_metadata.json", json.dumps(DREM_METADATA).encode()),
        ("training/lineage.json", json.dumps(lineage).encode())]))
    html = client.http.get(f"/models/registry/{model['model_id']}",
                           headers={"Authorization": alice.headers["Authorization"]}).body.decode()
    assert "brightness, shift, blur" in html and "2 of 2" in html
    assert "reinvent_base, reinvent_base:reverse" in html
    assert "reInvent2019_track 1/5" in html  # each earlier round's held-out result
    assert "&lt;b&gt;reInvent2019_track&lt;/b&gt; 4/5" in html and "<b>reInvent2019_track" not in html
