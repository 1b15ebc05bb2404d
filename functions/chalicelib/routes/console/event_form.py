"""The event form of the operator console: posted fields → `EventInput` (the same model the JSON API takes), an
`Event` → the form's values, and error locations → the form fields they belong next to.

Tracks are rows `track-{n}-…` with a "use" checkbox; links are one per line: `name | address | description`.
"""
from __future__ import annotations

import re
from datetime import date
from typing import Any

from pydantic import BaseModel

from chalicelib.core.errors import InvalidInput
from chalicelib.domain.countries import country_code_from_text, unknown_country_message
from chalicelib.domain.events import DEFAULT_LINKS, Event, EventInput, EventType
from drem_leaderboard.models import RaceConfig, RankingMethod, TrackType
from drem_web import labels

SPARE_TRACK_ROWS = 2
CONFIG_FIELDS = ("race_time_min", "resets_per_lap", "track_type", "ranking_method", "lap_count_target",
                 "max_runs_per_racer", "average_window")
_TRACK_FIELD = {"track_id": "track_id", "fleet_id": "fleet_id", "leaderboard_title": "title",
                "leaderboard_footer": "footer"}


class TrackRow(BaseModel):
    number: int
    use: bool
    track_id: str
    fleet_id: str
    title: str
    footer: str
    existing: bool
    direction: str = "counter_clockwise"


class EventFormView(BaseModel):
    values: dict[str, str]
    tracks: list[TrackRow]
    event_types: list[tuple[str, str]] = labels.options(EventType)
    track_types: list[tuple[str, str]] = labels.options(TrackType)
    ranking_methods: list[tuple[str, str]] = labels.options(RankingMethod)


def blank_form() -> EventFormView:
    config = RaceConfig()
    # Most events are created for today or soon: today is a better start than an empty date field.
    values = {"name": "", "event_type": EventType.OFFICIAL_TRACK_RACE.value, "date": date.today().isoformat(),
              "country_code": "",
              "sponsor": "", **_config_values(config), "landing_page_links": _links_text(DEFAULT_LINKS),
              "stats_visibility": "public"}
    rows = [TrackRow(number=1, use=True, track_id="", fleet_id="", title="", footer="", existing=False)]
    return EventFormView(values=values, tracks=rows + _spare_rows(2, SPARE_TRACK_ROWS))


def form_of(event: Event) -> EventFormView:
    values = {"name": event.name, "event_type": event.event_type.value, "date": event.date.isoformat(),
              "country_code": event.country_code, "sponsor": event.sponsor, **_config_values(event.race_config),
              "landing_page_links": _links_text(event.landing_page_links), "stats_visibility": event.stats_visibility}
    rows = [TrackRow(number=i, use=True, track_id=t.track_id or "", fleet_id=t.fleet_id or "",
                     title=t.leaderboard_title, footer=t.leaderboard_footer, existing=True, direction=t.direction)
            for i, t in enumerate(event.tracks, start=1)]
    return EventFormView(values=values, tracks=rows + _spare_rows(len(rows) + 1, SPARE_TRACK_ROWS))


def posted_form(fields: dict[str, str]) -> EventFormView:
    """The form as the operator sent it (shown again next to the errors)."""
    numbers = _row_numbers(fields)
    rows = [TrackRow(number=n, use=fields.get(f"track-{n}-use") == "on",
                     track_id=fields.get(f"track-{n}-track_id", ""), fleet_id=fields.get(f"track-{n}-fleet_id", ""),
                     title=fields.get(f"track-{n}-title", ""), footer=fields.get(f"track-{n}-footer", ""),
                     existing=fields.get(f"track-{n}-existing") == "1",
                     direction=fields.get(f"track-{n}-direction", "counter_clockwise")) for n in numbers]
    values = {name: fields.get(name, "") for name in ("name", "event_type", "date", "country_code", "sponsor",
                                                     *CONFIG_FIELDS, "landing_page_links", "stats_visibility")}
    return EventFormView(values=values, tracks=rows)


def event_input(fields: dict[str, str]) -> EventInput:
    """Raises pydantic.ValidationError or InvalidInput naming the field; `rename_for(fields)` maps the names.
    The country picker may hold a name or a label ("Sweden (SE)"): the model gets the code, or the text to refuse
    along with the other fields (`rename_for` words that refusal as the picker's)."""
    config = {name: fields[name].strip() for name in CONFIG_FIELDS if fields.get(name, "").strip()}
    if not fields.get("resets_per_lap", "").strip():
        config["resets_per_lap"] = None
    if not fields.get("max_runs_per_racer", "").strip():
        config["max_runs_per_racer"] = None
    tracks = [{"track_id": fields.get(f"track-{n}-track_id", "").strip() or None,
               "fleet_id": fields.get(f"track-{n}-fleet_id", "").strip() or None,
               "leaderboard_title": fields.get(f"track-{n}-title", "").strip(),
               "leaderboard_footer": fields.get(f"track-{n}-footer", "").strip(),
               "direction": fields.get(f"track-{n}-direction", "").strip() or "counter_clockwise"}
              for n in _used_rows(fields)]
    for track in tracks:
        if not track["leaderboard_footer"]:
            del track["leaderboard_footer"]
    return EventInput.model_validate({
        "name": fields.get("name", ""), "event_type": fields.get("event_type", ""), "date": fields.get("date", ""),
        "country_code": _country_code(fields.get("country_code", "")), "sponsor": fields.get("sponsor", ""),
        "race_config": config,
        "tracks": tracks, "landing_page_links": _parse_links(fields.get("landing_page_links", "")),
        "stats_visibility": fields.get("stats_visibility", "").strip() or "public"})


def rename_for(fields: dict[str, str]):  # noqa: ANN201 - a small closure
    used = _used_rows(fields)

    def rename(location: str) -> str:
        parts = location.split(".")
        if parts[0] == "race_config":
            return parts[1] if len(parts) > 1 else "lap_count_target"
        if (parts[0] == "tracks" and len(parts) > 2 and parts[1].isascii() and parts[1].isdigit()
                and int(parts[1]) < len(used)):
            return f"track-{used[int(parts[1])]}-{_TRACK_FIELD.get(parts[2], parts[2])}"
        if parts[0] in {"tracks", "landing_page_links"}:
            return parts[0]
        return parts[0]

    return rename


def _country_code(typed: str) -> str:
    try:
        return country_code_from_text(typed)
    except InvalidInput:
        return typed


def country_message(errors: dict[str, str], fields: dict[str, str]) -> dict[str, str]:
    """The event model words a bad code for the API; on the form it is the picker's text that named no country."""
    if "country_code" in errors:
        errors["country_code"] = unknown_country_message(fields.get("country_code", ""))
    return errors


def _config_values(config: RaceConfig) -> dict[str, str]:
    dumped: dict[str, Any] = config.model_dump(mode="json")
    return {name: "" if dumped[name] is None else str(dumped[name]) for name in CONFIG_FIELDS}


def _links_text(links: Any) -> str:
    return "\n".join(" | ".join(filter(None, (link.name, link.href, link.description))) for link in links)


def _parse_links(text: str) -> list[dict[str, str]]:
    links = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        parts = [part.strip() for part in line.split("|")]
        if len(parts) < 2:
            raise InvalidInput(f"Line {number}: write 'name | address | description'.", field="landing_page_links")
        links.append({"name": parts[0], "href": parts[1], "description": " | ".join(parts[2:])})
    return links


def _row_numbers(fields: dict[str, str]) -> list[int]:
    found = {int(m.group(1)) for name in fields if (m := re.match(r"^track-(\d{1,2})-", name))}
    return sorted(found)


def _used_rows(fields: dict[str, str]) -> list[int]:
    return [n for n in _row_numbers(fields) if fields.get(f"track-{n}-use") == "on"]


def _spare_rows(first: int, count: int) -> list[TrackRow]:
    return [TrackRow(number=n, use=False, track_id="", fleet_id="", title="", footer="", existing=False)
            for n in range(first, first + count)]
