"""The names and records of an event export folder: files, tables, accounts and archive entries."""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from chalicelib.core.errors import InvalidInput
from chalicelib.formats.logo_image import LogoImage

FORMAT = "drem-event-export"
FORMAT_VERSION = 1
MANIFEST = "manifest.json"
USERS_FILE = "users.json"
ARCHIVES_FILE = "archives.json"
ARCHIVE_DIR = "archives"
# The event's logo, when it has one: the image file itself (named in the manifest's "logo"), drawn again on import.
LOGO_FILES = {"image/png": "logo.png", "image/webp": "logo.webp"}
# file → logical table; the order is the order of writes on import (the event item last).
ITEM_FILES: dict[str, str] = {"fleets.json": "fleet", "profiles.json": "profiles", "models.json": "models",
                              "races.json": "races", "leaderboards.json": "leaderboards", "event.json": "events"}
EVENT_SCOPED_TABLES = frozenset({"events", "races", "leaderboards"})
# The key prefixes each file may hold: anything else in a file is refused on import.
ALLOWED_PK = {"fleet": ("FLEET#",), "profiles": ("USER#", "USERNAME#"), "models": ("OWNER#", "MODELID#")}
EVENT_ID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
ATTRIBUTE_TYPES = frozenset({"S", "N", "B", "BOOL", "NULL", "M", "L", "SS", "NS", "BS"})
NOT_CARRIED = ["devices and their credentials (cars and timers re-activate on the target)", "live races",
               "device commands and strip idempotency records", "raw and quarantined uploads", "soft-deleted models",
               "passwords"]

Item = dict[str, Any]  # one DynamoDB item in attribute-value JSON


class InvalidExport(InvalidInput):
    """The export folder is not one drem can import; the message names the file (and field) at fault."""


class Account(BaseModel):
    """A person the event refers to, as their account was on the source stack."""
    model_config = ConfigDict(frozen=True, extra="forbid")

    username: str = Field(min_length=1, max_length=128)
    sub: str = Field(min_length=8, max_length=128)
    email: str | None = None
    country_code: str | None = None
    groups: list[str] = Field(default_factory=list)
    enabled: bool = True


class ArchiveEntry(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")

    model_id: str = Field(min_length=1)
    key: str = Field(min_length=1, description="object key in the models bucket (holds the owner's sub)")
    file: str = Field(min_length=1)
    md5: str = Field(pattern=r"^[0-9a-f]{32}$")
    bytes: int = Field(ge=0)


@dataclass
class EventBundle:
    event_id: str
    items: dict[str, list[Item]]  # logical table → items
    accounts: list[Account]
    archives: list[ArchiveEntry]
    archive_data: dict[str, bytes]  # file → content
    logo: LogoImage | None = None  # on import: already drawn again from the file's pixels


def archive_file(model_id: str) -> str:
    """Where a model's archive sits in the folder."""
    return f"{ARCHIVE_DIR}/{model_id}.tar.gz"


def sorted_items(items: Iterable[Item]) -> list[Item]:
    return sorted(items, key=lambda i: (i["pk"]["S"], i["sk"]["S"]))
