"""Each way the league used to be fooled (issue #32), tried over the real app (Chalice test client, moto, real
Cognito tokens) with exports built from the formats deepracer-formats.md §5 describes, and refused with a message;
the public board shows none of them. The league's own rules (whose logs count, the lap-time bound, which tracks
exist) are tried without HTTP in tests/domain/test_league_rules.py; here is what crosses the HTTP and export
boundaries."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path
from typing import Any

import pytest

from chalicelib.formats.league_export import pack_exports, read_export
from tests.unit.conftest import bearer
from tests.unit.league_helpers import console_old_export, drem_sim_export, droa_export, tar_gz_of

pytestmark = pytest.mark.unit

REINVENT = "reinvent_base"


def _push(client: Any, token: str, upload: bytes, track: str = REINVENT) -> Any:
    return client.http.post(f"/api/league/{track}/submissions", body=upload,
                            headers={**bearer(token), "Content-Type": "application/gzip"})


def _upload(path: Path) -> bytes:
    return pack_exports([read_export(path)])


def _error(reply: Any) -> dict[str, Any]:
    return json.loads(reply.body)["error"]


def _board(client: Any, track: str = REINVENT) -> list[dict[str, Any]]:
    reply = client.http.get(f"/api/league/{track}", headers={"Accept": "application/json"})
    assert reply.status_code == 200
    return [ranked["entry"] for ranked in json.loads(reply.body)["entries"]]


@pytest.fixture
def tokens(users: Any) -> dict[str, str]:
    tokens = {name: users.access_token(name, ("racer",)) for name in ("alice", "bob")}
    tokens["root"] = users.access_token("root", ("admin",))
    return tokens


def test_bob_pushing_alices_export_is_refused_and_alice_keeps_her_place(client: Any, tokens: dict[str, str],
                                                                        tmp_path: Path) -> None:
    alices = _upload(console_old_export(tmp_path / "alice", world=REINVENT, laps=[(15000, 100)]))
    assert _push(client, tokens["alice"], alices).status_code == 201
    reply = _push(client, tokens["bob"], alices)
    assert reply.status_code == 409
    assert "already pushed by alice" in _error(reply)["message"]
    assert [entry["racer"] for entry in _board(client)] == ["alice"]
    assert _push(client, tokens["alice"], alices).status_code == 201  # her own logs again: fine


def test_edited_evaluation_metrics_faster_than_the_track_allows(client: Any, tokens: dict[str, str],
                                                                tmp_path: Path) -> None:
    """EvaluationMetrics edited to "best 5.123 s" and the sim-trace left out: re:Invent 2018 is 17.71 m and the
    model's top speed 2 m/s, so no lap takes less than 8.854 s."""
    folder = console_old_export(tmp_path / "edited", world=REINVENT, laps=[(5123, 100)])
    for trace in folder.rglob("evaluation-simtrace/*.csv"):
        trace.unlink()
    log = folder / "logs/evaluation/evaluation-20201021101010-XyXyXyXyXyXyXyXyXyXyXy-robomaker.log"
    log.parent.mkdir(parents=True)
    log.write_text(f"WORLD_NAME={REINVENT}\n")
    reply = _push(client, tokens["alice"], _upload(folder))
    assert reply.status_code == 400 and _error(reply)["field"] == "trials[0].time_s"
    assert "no lap can take less than 8.854 s" in _error(reply)["message"]
    assert _board(client) == []


def test_a_json_submission_with_a_zero_lap_is_not_taken(client: Any, tokens: dict[str, str], tmp_path: Path) -> None:
    forged = {"racer": "alice", "track": REINVENT, "model_name": "m", "layout": "drfc", "sensor": ["CAMERA"],
              "algorithm": "sac", "action_space_type": "continuous", "action_space": "x", "hyperparameters": {},
              "training_episodes": 1, "trials": [{"trial": 1, "time_s": 0.0, "completion_pct": 100}]}
    reply = client.http.post(f"/api/league/{REINVENT}/submissions", body=json.dumps(forged),
                             headers={**bearer(tokens["alice"]), "Content-Type": "application/json"})
    assert reply.status_code == 400  # the server assembles submissions; it takes no ready-made JSON
    assert "not a .tar.gz" in _error(reply)["message"]
    folder = drem_sim_export(tmp_path / "zero", track=REINVENT, progress=[100], lap_times=[0.0])
    reply = _push(client, tokens["alice"], _upload(folder))
    assert reply.status_code == 400 and "0.000 s lap" in _error(reply)["message"]
    assert _board(client) == []


def test_a_lap_with_an_off_track_is_not_completed(client: Any, tokens: dict[str, str], tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "off", world=REINVENT, laps=[(16000, 100), (15000, 100)])
    path = next((folder / "metrics/evaluation").glob("*.json"))
    document = json.loads(path.read_text())
    document["metrics"][1]["off_track_count"] = 1  # went off, was reset, finished: 100 %
    path.write_text(json.dumps(document))
    assert _push(client, tokens["alice"], _upload(folder)).status_code == 201
    entry = _board(client)[0]
    assert (entry["laps_completed"], entry["best_lap_s"], entry["off_track_total"]) == (1, 16.0, 1)


def test_a_droa_archive_with_colons_in_its_names_is_pushed(client: Any, tokens: dict[str, str],
                                                           tmp_path: Path) -> None:
    folder = droa_export(tmp_path / "indy", world="Spain_track", eval_world="Spain_track",
                         laps=[(31000, 100), (30500, 100)])
    archive = tar_gz_of(folder, tmp_path / "indy.tar.gz", top="indy")
    reply = _push(client, tokens["alice"], _upload(archive), "Spain_track")
    assert reply.status_code == 201, reply.body
    assert _board(client, "Spain_track")[0]["best_lap_s"] == 30.5


def test_a_missing_file_is_named_with_where_it_comes_from(client: Any, tokens: dict[str, str],
                                                          tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "logs", world=REINVENT, laps=[(15000, 100)])
    (folder / "model/model_metadata.json").unlink()
    reply = _push(client, tokens["alice"], _upload(folder))
    assert reply.status_code == 400 and _error(reply)["field"] == "model/model_metadata.json"
    assert "model download" in _error(reply)["message"]


def test_an_upload_that_is_not_an_archive(client: Any, tokens: dict[str, str]) -> None:
    reply = _push(client, tokens["alice"], b"PK\x03\x04 zip")
    assert reply.status_code == 400 and "not a .tar.gz" in _error(reply)["message"]
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz") as archive:
        info = tarfile.TarInfo("../../etc/model_metadata.json")
        info.size = 2
        archive.addfile(info, io.BytesIO(b"{}"))
    reply = _push(client, tokens["alice"], buffer.getvalue())
    assert reply.status_code == 400 and _error(reply)["field"] == "model/model_metadata.json"


def test_staff_register_a_track_drems_set_lacks(client: Any, tokens: dict[str, str], tmp_path: Path) -> None:
    folder = drem_sim_export(tmp_path / "bc", track="venue_figure8", progress=[100], lap_times=[12.0])
    assert _push(client, tokens["alice"], _upload(folder), "venue_figure8").status_code == 404

    def register(token: str, track: str, length_m: float) -> Any:
        return client.http.put(f"/api/league-tracks/{track}", body=json.dumps({"length_m": length_m}),
                               headers={**bearer(token), "Content-Type": "application/json"})

    assert register(tokens["alice"], "venue_figure8", 21.5).status_code == 403
    assert register(tokens["root"], "reinvent_base", 5.0).status_code == 400  # drem's own length stays
    assert register(tokens["root"], "venue_figure8", 21.5).status_code == 200
    assert _push(client, tokens["alice"], _upload(folder), "venue_figure8").status_code == 201
    assert _board(client, "venue_figure8")[0]["best_lap_s"] == 12.0
    too_fast = drem_sim_export(tmp_path / "fast", track="venue_figure8", progress=[100], lap_times=[10.0])
    reply = _push(client, tokens["alice"], _upload(too_fast), "venue_figure8")
    assert reply.status_code == 400 and "venue_figure8 is 21.50 m long" in _error(reply)["message"]
