"""A tiny message catalogue for the public pages (leaderboard, overlay, commentator): English and German.

`translator(lang)` returns a function key → text; an unknown language falls back to English, and a key missing in a
language falls back to its English text, so a half-translated catalogue never shows a raw key.
"""
from __future__ import annotations

from collections.abc import Callable

DEFAULT_LANGUAGE = "en"

CATALOGUE: dict[str, dict[str, str]] = {
    "en": {
        "leaderboard": "Leaderboard",
        "position": "Pos",
        "racer": "Racer",
        "time": "Time",
        "gap": "Gap",
        "laps": "Laps",
        "dnf": "DNF",
        "raced_by_proxy": "raced by proxy",
        "no_entries": "No results yet. The first racer is on the way!",
        "now_racing": "Now racing",
        "ready_to_start": "Ready to start",
        "paused": "Paused",
        "finished": "Finished",
        "time_left": "Time left",
        "current_lap": "Current lap",
        "best_lap": "Best lap",
        "best_average": "Best average",
        "previous_lap": "Previous lap",
        "gap_to_leader": "Gap to leader",
        "gap_to_fastest": "Gap to fastest",
        "position_now": "Position",
        "projected_position": "Projected position",
        "follow_live": "Follow the race live",
        "top_racers": "Top racers",
        "just_finished": "Just finished",
        "status": "Status",
        "no_race": "No race on track",
        "lap": "Lap",
        "resets": "Resets",
        "valid": "valid",
        "invalid": "invalid",
        "lap_times": "Lap times",
        "event_best": "Event best",
        "commentator": "Commentator",
        "track": "Track",
        "combined": "Combined",
        "fastest_lap_of_event": "fastest of the event",
        "fastest_lap_of_race": "fastest of this race",
        "sponsored_by": "Sponsored by",
    },
    "de": {
        "leaderboard": "Bestenliste",
        "position": "Pos",
        "racer": "Fahrer",
        "time": "Zeit",
        "gap": "Abstand",
        "laps": "Runden",
        "dnf": "Kein Ergebnis",
        "raced_by_proxy": "vertreten gefahren",
        "no_entries": "Noch keine Ergebnisse. Der erste Fahrer ist unterwegs!",
        "now_racing": "Jetzt auf der Strecke",
        "ready_to_start": "Startbereit",
        "paused": "Pausiert",
        "finished": "Beendet",
        "time_left": "Restzeit",
        "current_lap": "Aktuelle Runde",
        "best_lap": "Beste Runde",
        "best_average": "Bester Durchschnitt",
        "previous_lap": "Letzte Runde",
        "gap_to_leader": "Abstand zur Spitze",
        "gap_to_fastest": "Abstand zur Bestzeit",
        "position_now": "Platz",
        "projected_position": "Voraussichtlicher Platz",
        "follow_live": "Verfolge das Rennen live",
        "top_racers": "Die Besten",
        "just_finished": "Gerade beendet",
        "status": "Status",
        "no_race": "Kein Rennen auf der Strecke",
        "lap": "Runde",
        "resets": "Resets",
        "valid": "gültig",
        "invalid": "ungültig",
        "lap_times": "Rundenzeiten",
        "event_best": "Bestzeit der Veranstaltung",
        "commentator": "Kommentator",
        "track": "Strecke",
        "combined": "Gesamt",
        "fastest_lap_of_event": "schnellste der Veranstaltung",
        "fastest_lap_of_race": "schnellste dieses Rennens",
        "sponsored_by": "Gesponsert von",
    },
}

LANGUAGES = tuple(CATALOGUE)


def resolve_language(requested: str | None) -> str:
    """The catalogue language for a `lang=` value ("de", "DE", "de-AT" → "de"); anything else → English."""
    code = (requested or "").strip().lower()[:2]
    return code if code in CATALOGUE else DEFAULT_LANGUAGE


def translator(lang: str | None) -> Callable[[str], str]:
    chosen = CATALOGUE[resolve_language(lang)]
    english = CATALOGUE[DEFAULT_LANGUAGE]

    def translate(key: str) -> str:
        return chosen.get(key) or english[key]

    return translate
