"""The success message a console page shows after a change, carried through the 303 redirect as `?done=<key>`.

Only these fixed sentences are ever shown: the query names one of them and is never echoed, so a crafted link can
not put words on the page. Pages that answer a post with themselves (profile, password, registration desk, a
user's row) pass their `notice` directly instead."""
from __future__ import annotations

from collections.abc import Mapping

from chalice.app import Request

DONE: dict[str, str] = {
    "event-created": "Event created.",
    "event-saved": "Event saved.",
    "event-deleted": "Event deleted.",
    "logo-saved": "Logo saved; the big screen, the overlay and the event's page show it.",
    "logo-removed": "Logo removed; the boards show the event's name alone.",
    "fleet-created": "Fleet created.",
    "car-moved": "Car moved; its row below shows the fleet.",
    "car-video": "Camera settings saved; the car sends at them within about 10 seconds.",
    "car-models": "Models on the car changed; its row below shows them.",
    "car-deregistered": "Car deregistered; its credential no longer works.",
    "lap-saved": "Lap saved; the leaderboard shows the change.",
    "race-deleted": "Race deleted; the leaderboard no longer counts it.",
    "model-deleted": "Model deleted.",
}


def done_notice(request: Request) -> str:
    """The success message named by the request's `?done=` flag, or "" for none or an unknown key."""
    return _named(request.query_params or {})


def _named(query: Mapping[str, str]) -> str:
    return DONE.get(query.get("done", ""), "")
