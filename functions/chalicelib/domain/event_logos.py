"""An event's logo (the organiser's or the sponsor's): uploaded by staff, shown on the big screen, the overlay and the
event's landing page. One logo per event; uploading again replaces it, and removing it leaves the pages text-only.

The stored image is never the uploaded file: `formats.logo_image` draws it again from its pixels. Its `version` (a
hash of the stored bytes) is part of the address pages link to, so a new logo shows at once and browsers may cache
each version for good.
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

from pydantic import BaseModel, ConfigDict

from chalicelib.core.errors import NotFound
from chalicelib.domain.events import Event, EventRepository
from chalicelib.formats.logo_image import LogoImage, normalised_logo


class LogoVersion(BaseModel):
    """What a page needs to link to the logo without reading its bytes."""
    model_config = ConfigDict(frozen=True)

    version: str
    width: int
    height: int


class LogoRepository(Protocol):
    def get(self, event_id: str) -> LogoImage | None: ...
    def version(self, event_id: str) -> LogoVersion | None: ...
    def put(self, event_id: str, logo: LogoImage) -> None: ...
    def delete(self, event_id: str) -> None: ...


class EventLogoService:
    def __init__(self, events: EventRepository, logos: LogoRepository,
                 on_changed: Callable[[Event], None] | None = None) -> None:
        """`on_changed(event)` after a logo is saved or removed: the big screen shows it (big_screen.py)."""
        self._events = events
        self._logos = logos
        self._on_changed = on_changed

    def save(self, event_id: str, upload: bytes) -> LogoVersion:
        """Store `upload` as the event's logo; InvalidInput (field "logo") for a file that is not a usable image."""
        event = self._require_event(event_id)
        logo = normalised_logo(upload)
        self._logos.put(event_id, logo)
        self._changed(event)
        return LogoVersion(version=logo.version, width=logo.width, height=logo.height)

    def remove(self, event_id: str) -> None:
        event = self._require_event(event_id)
        self._logos.delete(event_id)
        self._changed(event)

    def _changed(self, event: Event) -> None:
        if self._on_changed is not None:
            self._on_changed(event)

    def logo(self, event_id: str) -> LogoImage:
        logo = self._logos.get(event_id)
        if logo is None:
            raise NotFound(f"Event {event_id} has no logo.", field="event_id")
        return logo

    def version(self, event_id: str) -> LogoVersion | None:
        return self._logos.version(event_id)

    def _require_event(self, event_id: str) -> Event:
        event = self._events.get(event_id)
        if event is None:
            raise NotFound(f"There is no event {event_id}.", field="event_id")
        return event
