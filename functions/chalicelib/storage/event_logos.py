"""DynamoDB adapter for event logos: item `EVENT#{eventId}` / `LOGO` in the events table, beside the event's `META`.

The image (at most formats.logo_image.MAX_STORED_BYTES) is a binary attribute of the item, so a logo is written in one
acknowledged put, like everything else the event has, and pages learn its version with a projected read.
"""
from __future__ import annotations

from typing import Any

from botocore.exceptions import BotoCoreError, ClientError

from chalicelib.domain.event_logos import LogoVersion
from chalicelib.formats.logo_image import LogoImage
from chalicelib.storage.aws_errors import translate_common

_SERVICE = "The events table"
# Named through placeholders: whether a plain word is reserved in DynamoDB's expressions is not worth betting on.
_VERSION_ONLY = {"ProjectionExpression": "#v, #w, #h",
                 "ExpressionAttributeNames": {"#v": "version", "#w": "width", "#h": "height"}}


def logo_key(event_id: str) -> dict[str, Any]:
    return {"pk": {"S": f"EVENT#{event_id}"}, "sk": {"S": "LOGO"}}


class DynamoLogoStore:
    def __init__(self, client: Any, table: str) -> None:
        self._client = client
        self._table = table

    def get(self, event_id: str) -> LogoImage | None:
        item = self._get(event_id)
        if item is None:
            return None
        return LogoImage(data=item["image"]["B"], content_type=item["contentType"]["S"],
                         width=int(item["width"]["N"]), height=int(item["height"]["N"]))

    def version(self, event_id: str) -> LogoVersion | None:
        item = self._get(event_id, **_VERSION_ONLY)
        if item is None:
            return None
        return LogoVersion(version=item["version"]["S"], width=int(item["width"]["N"]),
                           height=int(item["height"]["N"]))

    def put(self, event_id: str, logo: LogoImage) -> None:
        # The version is stored beside the image so that pages can read it without the image's bytes.
        item = {**logo_key(event_id), "version": {"S": logo.version}, "contentType": {"S": logo.content_type},
                "width": {"N": str(logo.width)}, "height": {"N": str(logo.height)}, "image": {"B": logo.data}}
        try:
            self._client.put_item(TableName=self._table, Item=item)
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, _SERVICE) from exc

    def delete(self, event_id: str) -> None:
        try:
            self._client.delete_item(TableName=self._table, Key=logo_key(event_id))
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, _SERVICE) from exc

    def _get(self, event_id: str, **options: Any) -> dict[str, Any] | None:
        try:
            reply = self._client.get_item(TableName=self._table, Key=logo_key(event_id), ConsistentRead=True,
                                          **options)
        except (ClientError, BotoCoreError) as exc:
            raise translate_common(exc, _SERVICE) from exc
        item: dict[str, Any] | None = reply.get("Item")
        return item
