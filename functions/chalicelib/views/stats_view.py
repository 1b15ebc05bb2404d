"""What the /stats template prints: the figures of `stats.compute` as KPI cards, SVG charts (the plotting style of
`svg_plots`), the world map and tables, plus the filter form's choices."""
from __future__ import annotations

from typing import Any

from markupsafe import Markup
from pygal_maps_world.i18n import COUNTRIES as COUNTRY_NAMES

from chalicelib.domain.stats import DIRECTION_LABELS, Stats, StatsFilter
from chalicelib.views.svg_plots import Series, bar_chart, line_chart
from chalicelib.views.world_map import world_map
from drem_web import labels


def country_name(code: str) -> str:
    return COUNTRY_NAMES.get(code.lower(), code)


def _activity(stats: Stats, months: list[str]) -> Markup:
    """Races and events per month; one month is no line (a single point each), so its figures are bars."""
    if len(months) == 1:
        [(_, events, races)] = stats.by_month
        return bar_chart([("Races", float(races)), ("Events", float(events))], title=f"Activity in {months[0]}",
                         y_label="count", testid="stats-activity")
    return line_chart([Series("Races", [(i, float(r)) for i, (_, _, r) in enumerate(stats.by_month)]),
                       Series("Events", [(i, float(e)) for i, (_, e, _) in enumerate(stats.by_month)])],
                      months, title="Activity per month", y_label="count", testid="stats-activity")


def stats_page(stats: Stats, wanted: StatsFilter, *, staff: bool) -> dict[str, Any]:
    months = [m for m, _, _ in stats.by_month]
    names = {code.upper(): name for code, name in COUNTRY_NAMES.items()}
    totals = stats.totals
    completion = f"{100 * totals.valid_laps / totals.laps:.0f}%" if totals.laps else "—"
    return {
        "staff": staff,
        "cards": [("Events", totals.events), ("Racers", totals.racers), ("Races", totals.races),
                  ("Valid laps", totals.valid_laps), ("Countries", totals.countries), ("Valid lap ratio", completion)],
        "activity": _activity(stats, months),
        "track_chart": bar_chart([(labels.label(t.track_type), float(t.races)) for t in stats.track_types],
                                 title="Races per track type", y_label="races", testid="stats-track-types"),
        "map": world_map(stats.events_by_country, names, title="Events by country", unit="events",
                         testid="stats-world-map"),
        "countries": [(code, country_name(code), stats.events_by_country.get(code, 0),
                       stats.racers_by_country.get(code, 0))
                      for code in sorted(stats.events_by_country, key=lambda c: (-stats.events_by_country[c], c))],
        "fastest": stats.fastest,
        "track_types": stats.track_types,
        "filters": {"direction": wanted.direction or "", "country": (wanted.country or "").upper(),
                    "from": wanted.date_from.isoformat() if wanted.date_from else "",
                    "to": wanted.date_to.isoformat() if wanted.date_to else ""},
        "directions": list(DIRECTION_LABELS.items()),
        "country_choices": [(code, country_name(code)) for code in stats.countries],
    }
