"""What the big screen shows around its board: the event's name, sponsor and logo, each track's title and footer
text, the landing page's links. Staff edit them on the event (and its logo); an open big screen shows the edit without a
reload because they are published like a board: one materialised item per event (`SCREEN`, next to its boards),
versioned, read by the live region with one GetItem (cached like the boards' polls) and woken like a board write
(views/live_regions.py swaps the parts in, out of band of the rows).

An event saved before this item existed has none: its pages show what the event says and the live region leaves
those parts alone until the next edit publishes the item.
"""
from __future__ import annotations

import json
import logging
from typing import Protocol

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import DremError
from chalicelib.domain.events import Event, LandingPageLink
from chalicelib.domain.leaderboards import PublicView

log = logging.getLogger(__name__)


class ScreenTrack(BaseModel):
    model_config = ConfigDict(frozen=True)
    title: str = ""
    footer: str = ""


class ScreenSettings(BaseModel):
    """The parts of the big screen staff edit, as published."""
    model_config = ConfigDict(frozen=True)
    title: str
    sponsor: str = ""
    logo_version: str = ""
    tracks: dict[str, ScreenTrack] = {}
    first_track: str = ""
    links: tuple[LandingPageLink, ...] = ()

    @classmethod
    def of(cls, event: Event, logo_version: str | None) -> ScreenSettings:
        tracks = {t.track_id or "": ScreenTrack(title=t.leaderboard_title, footer=t.leaderboard_footer)
                  for t in event.tracks}
        return cls(title=event.name, sponsor=event.sponsor, logo_version=logo_version or "", tracks=tracks,
                   first_track=event.tracks[0].track_id or "", links=event.landing_page_links)

    def view(self, event_id: str, board_track: str) -> ScreenView:
        """What one board's page shows (the combined board has no track title and the first track's footer)."""
        shown = self.tracks.get(board_track)
        footer_of = shown or self.tracks.get(self.first_track) or ScreenTrack()
        return ScreenView(title=self.title, sponsor=self.sponsor, track_title=shown.title if shown else "",
                          footer=footer_of.footer, links=self.links,
                          logo_url=f"/event/{event_id}/logo?v={self.logo_version}" if self.logo_version else "")


class ScreenView(BaseModel):
    model_config = ConfigDict(frozen=True)
    title: str
    sponsor: str
    track_title: str
    footer: str
    links: tuple[LandingPageLink, ...]
    logo_url: str


def parse_screen(body: str) -> ScreenSettings | None:
    """The published item's body; None when the event has none yet."""
    if not body:
        return None
    data = json.loads(body)
    data.pop("version", None)
    return ScreenSettings.model_validate(data)


class ScreenWriter(Protocol):
    def screen(self, event_id: str) -> PublicView: ...
    def publish_screen(self, event_id: str, body: str) -> None: ...


class ScreenPublisher:
    """Publishes an event's big-screen settings after staff save the event or change its logo."""

    def __init__(self, writer: ScreenWriter, logo_version: LogoVersionLookup) -> None:
        self._writer = writer
        self._logo_version = logo_version

    def publish(self, event: Event) -> None:
        settings = ScreenSettings.of(event, self._logo_version(event.event_id))
        self._writer.publish_screen(event.event_id, settings.model_dump_json())

    def caught_up(self, event: Event) -> ScreenSettings:
        """The settings as the event says now, published first if what open screens got differs: an edit whose
        publish failed after the event was saved (or an event saved before screens were published) is finished by
        the next big screen opened. A failed publish here still shows the page."""
        settings = ScreenSettings.of(event, self._logo_version(event.event_id))
        if parse_screen(self._writer.screen(event.event_id).body) != settings:
            try:
                self._writer.publish_screen(event.event_id, settings.model_dump_json())
            except DremError as exc:
                log.warning("big screen settings of %s not published yet (%s)", event.event_id, exc.message)
        return settings


class LogoVersionLookup(Protocol):
    def __call__(self, event_id: str) -> str | None: ...
