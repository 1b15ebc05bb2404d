"""Which option sets of a live region exist, for the live server's channels (issue 27: one page's option-set slots
could be filled by one client with made-up queries, after which a real variant was refused).

- `canonical`: the query with only what changes the region's HTML, written one way: the language as the catalogue
  code it resolves to ("DE", "de-AT" → "de"), the overlay's track under one name, and the page-only switches (the QR
  code's place, chroma keying: they style the page around the region) at their defaults. Queries that render the same
  HTML are then one channel, however they are spelled.
- `offered`: whether a canonical option set is one the app itself hands out: the big screen's own stream for a board
  of the event (any language), and every overlay the console's link builder makes (a track of the event, with or
  without the gap to the leader and the top list, any language). These are bounded by the event's tracks, so the live
  server admits them beyond a page's cap on other option sets (hand-edited queries): nobody can fill them.
Pure: no storage; the caller passes the event's track ids.
"""
from __future__ import annotations

from typing import Any

from chalicelib.views.live_regions import MAX_FOOTER_TRACKS, LeaderboardQuery, OverlayQuery
from drem_leaderboard.ranking import COMBINED_TRACK_ID
from drem_web import i18n

_BOARD_DEFAULTS = LeaderboardQuery()
_OVERLAY_DEFAULTS = OverlayQuery()
# What the overlay link builder varies (chalicelib.views.overlay_links): everything else stays at its default.
_OVERLAY_LINK_FIELDS = {"track", "gap_to_leader", "show_leaderboard", "lang"}
_BOARD_PAGE_FIELDS = {"track", "tracks", "lang"}


def canonical(query: Any) -> Any:
    """The same query, spelled the one way its HTML is keyed by (see the module docstring)."""
    lang = i18n.resolve_language(query.lang)
    if isinstance(query, LeaderboardQuery):
        return query.model_copy(update={"lang": lang, "qr": _BOARD_DEFAULTS.qr, "v": ""})
    if isinstance(query, OverlayQuery):
        return query.model_copy(update={"lang": lang, "track": query.overlay_track, "track_id": None,
                                        "chroma": False, "chroma_color": "", "v": ""})
    raise TypeError(f"not a live region query: {type(query).__name__}")


def offered(query: Any, event_tracks: list[str]) -> bool:
    """Whether canonical `query` is an option set the app's own pages and links produce for an event with these
    tracks (the board: `event_tracks` plus the combined board)."""
    if isinstance(query, LeaderboardQuery):
        track = query.track or COMBINED_TRACK_ID
        footers = [t for t in query.tracks.split(",") if t]
        page_footers = [track] if track != COMBINED_TRACK_ID else event_tracks[:MAX_FOOTER_TRACKS]
        return ((track in event_tracks or track == COMBINED_TRACK_ID) and footers in (page_footers, [])
                and _defaults_except(query, _BOARD_DEFAULTS, _BOARD_PAGE_FIELDS))
    if isinstance(query, OverlayQuery):
        return query.overlay_track in event_tracks and _defaults_except(query, _OVERLAY_DEFAULTS,
                                                                      _OVERLAY_LINK_FIELDS | {"track_id"})
    return False


def _defaults_except(query: Any, defaults: Any, varied: set[str]) -> bool:
    return all(getattr(query, name) == getattr(defaults, name) for name in type(query).model_fields
               if name not in varied | {"v", "qr", "chroma", "chroma_color"})
