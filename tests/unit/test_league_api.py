"""League round trip over the real app (Chalice test client, moto, real Cognito tokens): upload three racers'
exports on two tracks (the server assembles them), pull the boards sorted both ways, and read the CSV/JSON outputs
back."""
from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path
from typing import Any

import pytest

from chalicelib.domain.league import BOARD_COLUMNS
from chalicelib.formats.league_export import pack_exports, read_export
from drem_local.commands.league import rows_of, table, to_csv
from tests.unit.conftest import bearer
from tests.unit.league_helpers import console_old_export, drem_sim_export, drfc_export

pytestmark = pytest.mark.unit

REINVENT, OVAL = "reinvent_base", "drem_oval"


def _upload(*paths: Path) -> bytes:
    """What `drem league push PATH ...` sends: the export's files, packed."""
    return pack_exports([read_export(path) for path in paths])


def _push(client: Any, token: str, upload: bytes, track: str, *, racer: str | None = None,
          model_name: str | None = None) -> Any:
    query = "&".join(f"{key}={value}" for key, value in (("racer", racer), ("model_name", model_name)) if value)
    return client.http.post(f"/api/league/{track}/submissions{'?' + query if query else ''}",
                            headers={**bearer(token), "Content-Type": "application/gzip"}, body=upload)


@pytest.fixture
def pushed(client: Any, users: Any, tmp_path: Path) -> dict[str, str]:
    tokens = {name: users.access_token(name, ("racer",)) for name in ("alice", "bob", "carol")}
    # alice: best 15.0 but slow average; bob: steady 15.5s; carol: no completed lap on reinvent.
    exports = [
        ("alice", REINVENT, console_old_export(tmp_path / "a1", world=REINVENT, laps=[(15000, 100), (18000, 100)])),
        ("bob", REINVENT, drfc_export(tmp_path / "b1", world=REINVENT, laps=[(15500, 100), (15600, 100)])),
        ("carol", REINVENT, drem_sim_export(tmp_path / "c1", track=REINVENT, progress=[80.0, 60.0], lap_times=[])),
        ("alice", OVAL, console_old_export(tmp_path / "a2", world=OVAL, laps=[(10000, 100)])),
        ("carol", OVAL, drem_sim_export(tmp_path / "c2", track=OVAL, progress=[100, 100], lap_times=[9.5, 9.7])),
    ]
    for racer, track, path in exports:
        reply = _push(client, tokens[racer], _upload(path), track, model_name=path.name)
        assert reply.status_code == 201, reply.body
    return tokens


def _board(client: Any, track: str, query: str = "") -> dict[str, Any]:
    reply = client.http.get(f"/api/league/{track}{query}", headers={"Accept": "application/json"})
    assert reply.status_code == 200, reply.body
    return json.loads(reply.body)


def _order(board: dict[str, Any]) -> list[str]:
    return [ranked["entry"]["racer"] for ranked in board["entries"]]


def test_boards_rank_by_best_and_by_average(pushed: dict[str, str], client: Any) -> None:
    assert _order(_board(client, REINVENT)) == ["alice", "bob", "carol"]
    assert _order(_board(client, REINVENT, "?sort=avg")) == ["bob", "alice", "carol"]
    assert _order(_board(client, OVAL)) == ["carol", "alice"]
    best = _board(client, REINVENT)["entries"][0]["entry"]
    assert (best["best_lap_s"], best["average_lap_s"], best["laps_completed"]) == (15.0, 16.5, 2)


def test_filters(pushed: dict[str, str], client: Any) -> None:
    assert _order(_board(client, REINVENT, "?algorithm=sac")) == ["bob"]
    assert _order(_board(client, REINVENT, "?sensor=SECTOR_LIDAR")) == ["bob"]
    assert _order(_board(client, REINVENT, "?since=2000-01-01&until=2999-01-01")) == ["alice", "bob", "carol"]
    assert _order(_board(client, REINVENT, "?until=2000-01-01")) == []
    reply = client.http.get(f"/api/league/{REINVENT}?since=yesterday", headers={"Accept": "application/json"})
    assert reply.status_code == 400 and json.loads(reply.body)["error"]["field"] == "since"


def test_a_new_push_replaces_the_board_entry_and_keeps_history(pushed: dict[str, str], client: Any,
                                                              tmp_path: Path) -> None:
    faster = console_old_export(tmp_path / "a3", world=REINVENT, laps=[(14000, 100)])
    assert _push(client, pushed["alice"], _upload(faster), REINVENT, model_name="a3").status_code == 201
    entries = _board(client, REINVENT)["entries"]
    assert [e["entry"]["racer"] for e in entries].count("alice") == 1
    assert entries[0]["entry"]["best_lap_s"] == 14.0 and entries[0]["entry"]["model_name"] == "a3"
    latest = json.loads(client.http.get(f"/api/league/{REINVENT}/racers/alice").body)["submission"]
    assert latest["hyperparameters"]["lr"] == 0.0003 and latest["model_name"] == "a3"


def test_csv_and_json_outputs_parse_back_to_the_same_rows(pushed: dict[str, str], client: Any) -> None:
    rows = rows_of(_board(client, REINVENT, "?sort=avg"))
    parsed = list(csv.DictReader(io.StringIO(to_csv(rows, BOARD_COLUMNS))))
    assert [r["racer"] for r in parsed] == ["bob", "alice", "carol"]
    assert [(r["rank"], r["best_lap_s"], r["average_lap_s"]) for r in parsed] == [
        (str(r["rank"]), "" if r["best_lap_s"] is None else str(r["best_lap_s"]),
         "" if r["average_lap_s"] is None else str(r["average_lap_s"])) for r in rows]
    assert json.loads(json.dumps(rows)) == rows
    printed = table(rows, BOARD_COLUMNS).splitlines()
    assert printed[0].split()[:3] == ["rank", "racer", "model"] and len(printed) == 2 + len(rows)
    assert printed[2].split()[1] == "bob" and printed[4].split()[5] == "-"  # carol: no best lap


def test_racers_push_only_as_themselves(pushed: dict[str, str], client: Any, users: Any, tmp_path: Path) -> None:
    forged = _upload(console_old_export(tmp_path / "f", world=REINVENT, laps=[(12000, 100)]))
    reply = _push(client, pushed["alice"], forged, REINVENT, racer="bob")
    assert reply.status_code == 403
    assert _board(client, REINVENT)["entries"][1]["entry"]["best_lap_s"] == 15.5  # bob's entry untouched
    admin = users.access_token("root", ("admin",))
    assert _push(client, admin, forged, REINVENT, racer="bob").status_code == 201
    anonymous = client.http.post(f"/api/league/{REINVENT}/submissions", headers={"Content-Type": "application/gzip"},
                                 body=forged)
    assert anonymous.status_code == 401


def test_push_to_a_different_track_than_the_evaluation(pushed: dict[str, str], client: Any, tmp_path: Path) -> None:
    upload = _upload(console_old_export(tmp_path / "x", world=REINVENT, laps=[(14000, 100)]))
    reply = _push(client, pushed["alice"], upload, "Spain_track")
    assert reply.status_code == 400 and "track_len" in json.loads(reply.body)["error"]["field"]
    assert _board(client, "Spain_track")["entries"] == []


def test_invalid_export_names_the_file_and_field(pushed: dict[str, str], client: Any, tmp_path: Path) -> None:
    folder = console_old_export(tmp_path / "x", world=REINVENT, laps=[(14000, 100)])
    path = next((folder / "metrics/evaluation").glob("*.json"))
    path.write_text(path.read_text().replace('"completion_percentage": 100', '"completion_percentage": -5'))
    reply = _push(client, pushed["alice"], _upload(folder), REINVENT)
    assert reply.status_code == 400
    assert json.loads(reply.body)["error"]["field"].endswith("metrics[0].completion_percentage")
    assert _board(client, REINVENT)["entries"][0]["entry"]["best_lap_s"] == 15.0  # nothing half-written


def test_only_admins_delete(pushed: dict[str, str], client: Any, users: Any) -> None:
    path = f"/api/league/{REINVENT}/racers/bob"
    assert client.http.delete(path, headers=bearer(pushed["bob"])).status_code == 403
    admin = users.access_token("root", ("admin",))
    reply = client.http.delete(path, headers=bearer(admin))
    assert reply.status_code == 200 and json.loads(reply.body) == {"deleted": 1}
    assert _order(_board(client, REINVENT)) == ["alice", "carol"]
    assert client.http.get(path, headers={"Accept": "application/json"}).status_code == 404
    assert client.http.delete(path, headers=bearer(admin)).status_code == 404


def test_public_page_and_hyperparameter_fragment(pushed: dict[str, str], client: Any) -> None:
    page = client.http.get(f"/league/{REINVENT}?sort=avg")
    assert page.status_code == 200
    html = page.body.decode()
    assert html.index('data-racer="bob"') < html.index('data-racer="alice"') < html.index('data-racer="carol"')
    assert 'hx-get="/league/reinvent_base/racers/bob"' in html
    fragment = client.http.get(f"/league/{REINVENT}/racers/bob", headers={"HX-Request": "true"}).body.decode()
    assert "<html" not in fragment and "sac_alpha" in fragment and "15.500 s" in fragment


def test_the_league_page_names_racers_by_their_display_name(pushed: dict[str, str], client: Any) -> None:
    """Issue 31: the league showed sign-in names while every other board showed the racer's own spelling."""
    reply = client.http.put("/api/me/profile", headers={**bearer(pushed["alice"]), "Content-Type": "application/json"},
                            body=json.dumps({"display_name": "Zoë.Müller"}))
    assert reply.status_code == 200, reply.body
    html = client.http.get(f"/league/{REINVENT}").body.decode()
    assert '<td data-label="Racer">Zoë.Müller</td>' in html
    assert 'hx-get="/league/reinvent_base/racers/alice"' in html  # the row still opens alice's submission


def test_two_racers_called_bjorn_are_told_apart_on_the_league_board(pushed: dict[str, str], client: Any) -> None:
    """Issue 31: alice and bob both go by Björn; the board shows each with their sign-in name, 山田 as she writes it."""
    for racer, name in (("alice", "Björn"), ("bob", "björn"), ("carol", "山田")):
        reply = client.http.put("/api/me/profile", body=json.dumps({"display_name": name}),
                                headers={**bearer(pushed[racer]), "Content-Type": "application/json"})
        assert reply.status_code == 200, reply.body
    html = client.http.get(f"/league/{REINVENT}?sort=avg").body.decode()
    shown = re.findall(r'<td data-label="Racer">([^<]*)</td>', html)
    assert shown == ["björn (bob)", "Björn (alice)", "山田"], shown
    # On the oval alice races without bob: her name alone.
    oval = client.http.get(f"/league/{OVAL}").body.decode()
    assert sorted(re.findall(r'<td data-label="Racer">([^<]*)</td>', oval)) == ["Björn", "山田"]
    detail = client.http.get(f"/league/{REINVENT}/racers/carol", headers={"HX-Request": "true"}).body.decode()
    assert "<h3>山田 · " in detail
