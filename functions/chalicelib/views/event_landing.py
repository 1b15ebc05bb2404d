"""The public landing page of an event: what the QR code on every board opens. Its tracks with their live board,
the combined board, the stream team's overlay links (plain and chroma-key), and the links the organiser configured
(`landing_page_links`, validated on input as http(s) addresses or paths on this site)."""
from __future__ import annotations

from urllib.parse import quote, urlencode

from pydantic import BaseModel, ConfigDict

from chalicelib.domain.countries import country_name
from chalicelib.domain.events import COMBINED_TRACK_ID, Event

DIRECTIONS = {"counter_clockwise": "counter-clockwise", "clockwise": "clockwise"}


class TrackLinks(BaseModel):
    model_config = ConfigDict(frozen=True)
    title: str
    direction: str
    board: str
    overlay: str
    overlay_chroma: str


class LandingView(BaseModel):
    model_config = ConfigDict(frozen=True)
    name: str
    date: str
    country_code: str
    country: str
    sponsor: str
    tracks: tuple[TrackLinks, ...]
    combined_board: str | None
    links: tuple[tuple[str, str, str], ...]  # (name, href, description)
    stats: str | None


def landing_url(public_url: str, event_id: str, lang: str | None = None) -> str:
    query = f"?{urlencode({'lang': lang})}" if lang and lang != "en" else ""
    return f"{public_url.rstrip('/')}/event/{quote(event_id, safe='')}{query}"


def landing_view(event: Event) -> LandingView:
    base = quote(event.event_id, safe="")
    tracks = tuple(TrackLinks(
        title=t.leaderboard_title or f"Track {t.track_id}", direction=DIRECTIONS[t.direction],
        board=f"/leaderboard/{base}?{urlencode({'track': t.track_id})}",
        overlay=f"/overlay/{base}?{urlencode({'trackId': t.track_id})}",
        overlay_chroma=f"/overlay/{base}?{urlencode({'trackId': t.track_id, 'chroma': 'true'})}")
        for t in event.tracks)
    return LandingView(
        name=event.name, date=event.date.isoformat(), country_code=event.country_code,
        country=country_name(event.country_code), sponsor=event.sponsor, tracks=tracks,
        combined_board=f"/leaderboard/{base}?track={COMBINED_TRACK_ID}" if event.combined_board else None,
        links=tuple((link.name, link.href, link.description) for link in event.landing_page_links),
        stats=f"/stats?country={event.country_code}" if event.stats_visibility == "public" else None)
