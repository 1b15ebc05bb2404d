"""The statistics page's read of the `races` table: every submitted race of every event, in one paginated Scan.

One Scan (filtered to `RACE#` items with status SUBMITTED, only the `event_id` and `doc` attributes) instead of one
Query per event: the page needs all of them anyway, and a Scan reads each item once, where 50 Queries cost 50 round
trips (and, on the local moto server, 50 passes over the table). Items are grouped by event for `domain.stats`.
"""
from __future__ import annotations

from typing import Any

from chalicelib.storage.aws_errors import call
from drem_leaderboard.models import Race

_SERVICE = "The races table"


def submitted_races_by_event(dynamodb: Any, table: str) -> dict[str, list[Race]]:
    kwargs: dict[str, Any] = {
        "TableName": table, "ProjectionExpression": "event_id, doc",
        "FilterExpression": "begins_with(sk, :race) AND #status = :submitted",
        "ExpressionAttributeNames": {"#status": "status"},
        "ExpressionAttributeValues": {":race": {"S": "RACE#"}, ":submitted": {"S": "SUBMITTED"}}}
    grouped: dict[str, list[Race]] = {}
    while True:
        page = call(dynamodb, "scan", _SERVICE, **kwargs)
        for item in page.get("Items", []):
            race = _race(item["doc"]["S"])
            grouped.setdefault(item["event_id"]["S"], []).append(race)
        if "LastEvaluatedKey" not in page:
            return grouped
        kwargs["ExclusiveStartKey"] = page["LastEvaluatedKey"]


def _race(doc: str) -> Race:
    from chalicelib.domain.races import RaceRecord  # the stored document is a whole RaceRecord

    return RaceRecord.model_validate_json(doc).race
