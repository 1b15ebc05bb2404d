"""A track board of 5,000 racers on the local stack: stored in parts no bigger than DynamoDB allows (moto refuses an
item over 400 KB, as DynamoDB does), the first page read with one GetItem, further pages with `?page=N`, and one
racer's new lap re-ranks the whole board."""
from __future__ import annotations

import json
from typing import Any

import pytest

from drem_local.bootstrap import StackOutputs

pytestmark = pytest.mark.unit

EVENT = "big-event"
RACERS = 5_000


def _row(index: int, first_lap_ms: int) -> Any:
    """Racer `index` with three submitted laps, the first `first_lap_ms` long."""
    from chalicelib.domain.leaderboards import BoardRow
    from drem_leaderboard.models import Lap, LapSource, RaceConfig, Racer, RaceStatus, new_race
    from drem_leaderboard.ranking import RacerProfile
    from drem_leaderboard.summary import summarise_racer

    racer = Racer(sub=f"9f0c3a51-7d2e-4b8a-a1c6-{index:012d}", username=f"racer-{index:05d}")
    laps = tuple(Lap(lap_id=i, time_ms=first_lap_ms + 101 * i, is_valid=True, source=LapSource.MANUAL,
                     captured_at_ms=1_000 + i) for i in range(3))
    race = new_race(race_id=f"race-{index}", event_id=EVENT, track_id="1", racer=racer, config=RaceConfig(),
                    now_ms=1).model_copy(update={"laps": laps, "status": RaceStatus.SUBMITTED,
                                                 "submitted_at_ms": 2_000})
    summary = summarise_racer([race])
    assert summary is not None
    return BoardRow(summary=summary, profile=RacerProfile(username=racer.username, country_code="SE"))


def _rows(count: int) -> list[Any]:
    return [_row(index, 40_000 + 37 * index) for index in range(count)]


def _publisher() -> Any:
    from chalicelib.domain.leaderboards import LeaderboardPublisher
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients
    from chalicelib.storage.leaderboards import DynamoBoardStore

    return LeaderboardPublisher(DynamoBoardStore(clients.dynamodb(), get_settings().table("leaderboards")),
                                lambda: 5_000, cache=None)


def _items(stack: StackOutputs) -> list[dict[str, Any]]:
    from chalicelib.settings import get_settings
    from chalicelib.storage import clients

    client = clients.dynamodb()
    items: list[dict[str, Any]] = []
    kwargs: dict[str, Any] = {"TableName": get_settings().table("leaderboards")}
    while True:
        page = client.scan(**kwargs)
        items += page["Items"]
        if "LastEvaluatedKey" not in page:
            return items
        kwargs["ExclusiveStartKey"] = page["LastEvaluatedKey"]


def _item_bytes(item: dict[str, Any]) -> int:
    """DynamoDB's item size: attribute names plus values (binary as its bytes)."""
    total = 0
    for name, value in item.items():
        (kind, raw), = value.items()
        total += len(name) + (len(raw) if kind == "B" else len(json.dumps(raw)))
    return total


def test_a_5000_racer_board_is_stored_within_the_item_limit_and_read_page_by_page(stack: StackOutputs) -> None:
    from drem_leaderboard.models import RaceConfig

    method = RaceConfig().ranking_method
    publisher = _publisher()
    rows = _rows(RACERS)
    publisher.rebuild(EVENT, {"1": rows}, method, ["1"])  # one item of all rows would be ~3.5 MB: moto refuses it

    sizes = {item["sk"]["S"]: _item_bytes(item) for item in _items(stack)}
    assert max(sizes.values()) < 350_000, sorted(sizes.items(), key=lambda kv: -kv[1])[:3]
    assert any("~STATE#" in key for key in sizes) and any("~PAGE#" in key for key in sizes)

    first = json.loads(publisher.board(EVENT, "1").body)
    assert (first["page"], first["pages"], first["total_entries"]) == (1, 25, RACERS)
    assert [e["position"] for e in first["entries"]] == list(range(1, 201))
    last = publisher.board_page(EVENT, "1", 25)
    assert last is not None and json.loads(last.body)["entries"][-1]["username"] == "racer-04999"
    assert publisher.board_page(EVENT, "1", 26) is None
    combined = json.loads(publisher.board(EVENT, "combined").body)
    assert combined["total_entries"] == RACERS

    # The slowest racer sets the fastest lap: the whole board re-ranks from the stored rows.
    fastest = _row(RACERS - 1, 30_000)
    publisher.refresh_racer(EVENT, "1", fastest.summary.racer_sub, fastest, method, all_tracks=["1"])
    top = json.loads(publisher.board(EVENT, "1").body)["entries"]
    assert (top[0]["username"], top[0]["position"], top[1]["username"]) == ("racer-04999", 1, "racer-00000")
    page_2 = publisher.board_page(EVENT, "1", 2)
    assert page_2 is not None and json.loads(page_2.body)["entries"][0]["username"] == "racer-00199"
    assert json.loads(publisher.board(EVENT, "combined").body)["entries"][0]["username"] == "racer-04999"
    parts = [key for key in (item["sk"]["S"] for item in _items(stack)) if "~STATE#" in key]
    assert len({key.split("#")[3] for key in parts}) == 1, "the replaced write's state parts are deleted"


def test_a_small_board_is_one_item_as_before(stack: StackOutputs) -> None:
    from drem_leaderboard.models import RaceConfig

    publisher = _publisher()
    publisher.rebuild(EVENT, {"1": _rows(50)}, RaceConfig().ranking_method, ["1"])
    keys = sorted(item["sk"]["S"] for item in _items(stack))
    assert keys == ["BOARD#1", "BOARD#combined"]
    body = json.loads(publisher.board(EVENT, "1").body)
    assert len(body["entries"]) == 50 and "page" not in body


def test_the_api_serves_further_pages(desk: Any, stack: StackOutputs) -> None:
    from drem_leaderboard.models import RaceConfig

    _publisher().rebuild(EVENT, {"1": _rows(450)}, RaceConfig().ranking_method, ["1"])
    first = desk.ok(desk.anonymous_get(f"/api/leaderboard/{EVENT}?track=1"))
    assert (len(first["entries"]), first["pages"]) == (200, 3)
    third = desk.anonymous_get(f"/api/leaderboard/{EVENT}?track=1&page=3")
    assert third.status_code == 200 and [e["position"] for e in json.loads(third.body)["entries"]][:1] == [401]
    assert desk.anonymous_get(f"/api/leaderboard/{EVENT}?track=1&page=4").status_code == 404
    assert desk.anonymous_get(f"/api/leaderboard/{EVENT}?track=1&page=x").status_code == 400


class _BigBoardStack:
    """A stack whose event has a board stored in parts (what `drem export` reads through its StackReader)."""

    def get_item(self, table: str, pk: str, sk: str) -> dict[str, Any] | None:
        if table == "events":
            return {"pk": {"S": pk}, "sk": {"S": sk}, "doc": {"S": json.dumps({"event_id": EVENT, "tracks": []})}}
        return None

    def partition(self, table: str, pk: str, sk_prefix: str = "") -> list[dict[str, Any]]:
        if table != "leaderboards":
            return []
        return [{"pk": {"S": pk}, "sk": {"S": "BOARD#1"}, "state_ref": {"S": "abc"}, "state_parts": {"N": "2"}},
                {"pk": {"S": pk}, "sk": {"S": "BOARD#1~STATE#abc#0"}, "data": {"B": "eA=="}}]

    def accounts_by_sub(self) -> dict[str, Any]:
        return {}

    def read_object(self, bucket: str, key: str) -> bytes | None:
        return None

    def read_logo(self, event_id: str) -> Any:
        return None


def test_exporting_an_event_whose_board_is_in_parts_is_refused_with_a_reason() -> None:
    from chalicelib.core.errors import Conflict
    from chalicelib.domain.event_transfer.export import collect_event

    with pytest.raises(Conflict, match="too many racers to export yet"):
        collect_event(_BigBoardStack(), EVENT)
