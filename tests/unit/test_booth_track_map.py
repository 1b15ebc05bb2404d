"""The booth's top-down map as a visitor reads it on a saved run's page: the track, the trail the car drove, a ring
where it left the track, and the car where the run ended, drawn on top so no mark hides it."""
from __future__ import annotations

import re

import pytest

from chalicelib.domain.booth_tracks import TrackDetail, TrackService
from chalicelib.views.track_map import track_map

pytestmark = pytest.mark.unit


def rows_along(track: TrackDetail, count: int, off_at: int) -> list[dict]:
    points = track.centerline
    return [{"x": points[i % len(points)][0], "y": points[i % len(points)][1], "t_ms": i * 67,
             "offtrack": i == off_at} for i in range(count)]


def test_the_map_shows_the_trail_the_off_track_ring_and_the_car_on_top() -> None:
    track = TrackService().get("drem_oval")
    rows = rows_along(track, 40, off_at=39)  # the run ended where the car left the track (put back there)
    svg = str(track_map(track, rows, testid="run-map"))

    trail = re.search(r'points="([^"]*)" class="map-trail"', svg)
    assert trail is not None and len(trail.group(1).split()) == 41  # every row, and the last one again
    assert svg.count('class="map-off"') == 1 and "off the track at 2.6 s" in svg
    car = re.search(r'<circle cx="([-0-9.]+)" cy="([-0-9.]+)" r="[0-9.]+" class="map-car"', svg)
    assert car is not None
    assert (float(car.group(1)), float(car.group(2))) == pytest.approx((rows[-1]["x"], rows[-1]["y"]), abs=1e-3)
    assert svg.index('class="map-car"') > svg.rindex('class="map-off"')  # drawn last: on top of the ring
    ring, dot = (re.search(rf'r="([0-9.]+)" class="{name}"', svg) for name in ("map-off", "map-car"))
    assert ring is not None and dot is not None and float(ring.group(1)) > float(dot.group(1))  # ring around the car
    box = re.search(r'viewBox="([^"]+)"', svg)
    assert box is not None
    left, top, width, height = (float(v) for v in box.group(1).split())
    for x, y in track.centerline:  # the whole track in the picture (y flipped: seen from above)
        assert left < x < left + width and top < -y < top + height


def test_a_drive_not_started_shows_the_car_on_the_start_line() -> None:
    track = TrackService().get("drem_oval")
    svg = str(track_map(track, testid="drive-map"))
    start = track.centerline[0]
    assert f'<circle cx="{start[0]:.3f}" cy="{start[1]:.3f}" r="0.18" class="map-car"' in svg
    assert 'class="map-off"' not in svg
