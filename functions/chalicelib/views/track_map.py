"""The top-down map of a booth drive (server-built SVG, no script needed to read it): the track, the car's trail,
where it left the track, and the car.

Coordinates are the simulator's metres (y up); one group flips y so the picture is the track seen from above. The
drive page's own script (web/drem_web/static/booth_drive.js) moves the car and extends the trail as frames arrive,
through the `data-map` elements; the run page draws the whole saved run.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from markupsafe import Markup, escape

from chalicelib.domain.booth_tracks import TrackDetail

MAX_TRAIL_POINTS = 1500  # a five-minute drive is 4,500 frames; every third still draws the line the car took
CAR_RADIUS_M = 0.18  # about the real car's length across: a 0.12 m dot was lost under the marks at 420 px
OFF_RADIUS_M = 0.28  # a ring, wider than the car: seen around the car when it is put back where it left the track


def track_map(track: TrackDetail, rows: Sequence[dict[str, Any]] = (), *, testid: str) -> Markup:
    xs = [x for x, _ in track.centerline]
    ys = [y for _, y in track.centerline]
    margin = track.width_m + 0.3
    left, right, bottom, top = min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin
    loop = [*track.centerline, track.centerline[0]]
    step = max(1, -(-len(rows) // MAX_TRAIL_POINTS))
    trail = _points((r["x"], r["y"]) for r in [*rows[::step], *rows[-1:]])
    off = "".join(f'<circle cx="{r["x"]:.3f}" cy="{r["y"]:.3f}" r="{OFF_RADIUS_M}" class="map-off">'
                  f'<title>off the track at {r["t_ms"] / 1000:.1f} s</title></circle>' for r in rows if r["offtrack"])
    car_x, car_y = (rows[-1]["x"], rows[-1]["y"]) if rows else track.centerline[0]
    start_x, start_y = track.centerline[0]
    return Markup(
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{left:.3f} {-top:.3f} {right - left:.3f} '
        f'{top - bottom:.3f}" class="track-map" role="img" data-testid="{escape(testid)}" '
        f'aria-label="{escape(track.name)} seen from above: the car, its trail and where it left the track">'
        f'<g transform="scale(1,-1)">'
        f'<polyline points="{_points(loop)}" class="map-track" stroke-width="{track.width_m:.3f}"/>'
        f'<polyline points="{_points(loop)}" class="map-centre"/>'
        f'<circle cx="{start_x:.3f}" cy="{start_y:.3f}" r="{track.width_m / 2:.3f}" class="map-start">'
        f'<title>start and timing line</title></circle>'
        f'<polyline points="{trail}" class="map-trail" data-map="trail"/>'
        f'<g data-map="off" data-mark-radius="{OFF_RADIUS_M}">{off}</g>'
        f'<circle cx="{car_x:.3f}" cy="{car_y:.3f}" r="{CAR_RADIUS_M}" class="map-car" data-map="car">'
        f'<title>the car</title></circle>'  # last, so on top: never hidden under the marks
        f'</g></svg>')


def _points(points: Any) -> str:
    return " ".join(f"{x:.3f},{y:.3f}" for x, y in points)
