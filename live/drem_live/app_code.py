"""The one place the live server imports the app's code (chalicelib, in functions/).

In a container functions/ is on sys.path (PYTHONPATH); from a clone `drem_local.app_source` puts it there, the way the
local stack does. Everything the live server needs from the app goes through `AppCode`, so the rest of drem_live never
imports chalicelib.
"""
from __future__ import annotations

import importlib.util
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if importlib.util.find_spec("chalicelib") is None:
    from drem_local.app_source import use_app_source

    use_app_source()

from chalicelib import services  # noqa: E402  (after functions/ is on sys.path)
from chalicelib.domain.leaderboards import LeaderboardPublisher, PublicView, PublicViewCache  # noqa: E402
from chalicelib.live_wake import (  # noqa: E402
    MAX_WAKE_BODY_BYTES,
    MIN_WAKE_SECRET_CHARS,
    WAKE_PATH,
    WAKE_SECRET_ENV,
    WAKE_SECRET_HEADER,
    LiveWaker,
)
from chalicelib.live_wake import socket_path as wake_socket_path  # noqa: E402
from chalicelib.routes.responses import etag_matches  # noqa: E402
from chalicelib.views import live_options, live_regions  # noqa: E402
from drem_leaderboard.models import Race  # noqa: E402

if TYPE_CHECKING:
    from pydantic import BaseModel

__all__ = ["MAX_WAKE_BODY_BYTES", "MIN_WAKE_SECRET_CHARS", "WAKE_PATH", "WAKE_SECRET_ENV", "WAKE_SECRET_HEADER",
           "AppCode", "LiveWaker", "PublicView", "etag_matches", "live_regions", "wake_socket_path"]

QUERY_MODELS: Mapping[str, type[BaseModel]] = {
    "leaderboard": live_regions.LeaderboardQuery, "overlay": live_regions.OverlayQuery}


@dataclass
class AppCode:
    """Reads storage the way the app's public routes do, through the live server's own read cache (`reads`): every
    channel and poll of an event reading at about the same time shares one read of each item (single flight), an
    item is re-read once it is older than half the poll interval, and `changed(event_id)` (the writer's wake-up)
    forgets the event's items at once, so the next read after a write always reaches storage."""
    publisher: LeaderboardPublisher
    reads: PublicViewCache | None = None

    @classmethod
    def from_settings(cls, poll_s: float) -> AppCode:
        reads = PublicViewCache(fresh_ms=poll_s * 1000 / 2)
        return cls(services.live_publisher(reads), reads)

    def changed(self, event_id: str) -> None:
        if self.reads is not None:
            self.reads.invalidate_event(event_id)

    @staticmethod
    def now_ms() -> int:
        return services.now_ms()

    @staticmethod
    def parse_query(kind: str, params: Mapping[str, str]) -> Any:
        """The fragment route's query model (pydantic ValidationError on bad input), spelled the one way its HTML is
        keyed by (live_options.canonical): queries that render the same region share one channel."""
        return live_options.canonical(QUERY_MODELS[kind].model_validate(dict(params)))

    @staticmethod
    def offered(query: Any, event_tracks: list[str]) -> bool:
        """Whether the app's own pages and links hand out this option set (live_options.offered)."""
        return live_options.offered(query, event_tracks)

    def region(self, kind: str, event_id: str, query: Any, now_ms: int) -> live_regions.LiveRegion:
        if kind == "leaderboard":
            track, footer_tracks = live_regions.leaderboard_fragment_tracks(query)
            return live_regions.leaderboard_region(self.publisher, event_id, track, query, footer_tracks, now_ms)
        return live_regions.overlay_region(self.publisher, read_race, event_id, query, now_ms)

    @staticmethod
    def channel_options(kind: str, event_id: str, query: Any) -> tuple[Any, ...]:
        if kind == "leaderboard":
            return ("leaderboard", *live_regions.leaderboard_options(event_id, query))
        return ("overlay", *live_regions.overlay_options(event_id, query))

    def view(self, kind: str, event_id: str, track: str) -> PublicView:
        """What `GET /api/leaderboard|overlay/{event}?track=` answers (the stored body and its version)."""
        if kind == "leaderboard":
            return self.publisher.board(event_id, track)
        return self.publisher.overlay(event_id, track)

    @staticmethod
    def event_tracks(event_id: str) -> list[str] | None:
        """The event's track ids, or None when there is no such event."""
        event = services.event_store().get(event_id)
        return None if event is None else [track.track_id or "" for track in event.tracks]


def read_race(event_id: str, race_id: str) -> Race | None:
    record = services.race_store().get(event_id, race_id)
    return record.race if record else None


def token_is_newer(candidate: str, shown: str | None) -> bool:
    return live_regions.token_is_newer(candidate, shown)
