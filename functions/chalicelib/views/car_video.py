"""Where a page finds a car's camera on the live server (drem_live.video_routes), like `stream_url` for the live
regions: "" when no live server runs (the page then shows no camera at all)."""
from __future__ import annotations

from collections.abc import Mapping
from urllib.parse import quote, urlencode

from chalicelib.settings import get_settings
from drem_web import render


def _live(path: str) -> str:
    base = get_settings().live_stream_base
    if base is None:
        return ""
    if render.base_path():
        return path  # the template's url() adds the prefix; the proxy routes it to the live server (docs/operations.md)
    return f"{base}{path}"


def racing_video_url(event_id: str, track_id: str) -> str:
    """The public MJPEG of the car of the track's live race."""
    return _live(f"/live/video/{quote(event_id, safe='')}?{urlencode({'track': track_id})}")


def preview_video_url(device_id: str) -> str:
    """A car's camera for staff (their session cookie goes along: an <img> on the same host, any port)."""
    return _live(f"/live/video/cars/{quote(device_id, safe='')}")


def shown_when_asked(event_id: str, track_id: str, query_params: Mapping[str, str] | None) -> str:
    """The racing car's camera for a page whose link asked for it (`carEye=true`, the overlay link builder's
    option), else ""."""
    asked = (query_params or {}).get("carEye", "").lower() in ("true", "1", "on")
    return racing_video_url(event_id, track_id) if asked else ""
