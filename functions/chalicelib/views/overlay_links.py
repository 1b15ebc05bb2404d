"""The overlay's options as the console's link builder offers them, and the address they make (pure).

The overlay page (`routes/public_pages.OverlayQuery`) reads the same names: `trackId`, `chroma`, `chromaColor`,
`gapToLeader`, `showLeaderboard`, `lang`, and `carEye` (read by the page route itself, not the live region's query).
"""
from __future__ import annotations

import re
from urllib.parse import quote, urlencode

from pydantic import BaseModel, ConfigDict, Field, field_validator

from drem_web.i18n import LANGUAGE_NAMES

_COLOUR = re.compile(r"^#[0-9A-Fa-f]{6}$")
LANGUAGES = tuple((code, LANGUAGE_NAMES[code]) for code in LANGUAGE_NAMES)


class OverlayLinkOptions(BaseModel):
    model_config = ConfigDict(extra="ignore")

    track: str = Field(default="1", max_length=32, pattern=r"^[A-Za-z0-9_-]+$")
    chroma: bool = Field(default=False, description="paint a key colour behind the panels (OBS chroma key filter)")
    chroma_color: str = Field(default="#00FF00", max_length=7)
    gap_to_leader: bool = Field(default=True, description="show each racer's gap to the leader in the top list")
    show_leaderboard: bool = Field(default=True, description="show the top list between races")
    lang: str = Field(default="en", max_length=2)
    car_eye: bool = Field(default=False, description="the racing car's camera, picture in picture (left, under the "
                                                     "title; never over the lower third)")

    @field_validator("chroma_color")
    @classmethod
    def _hex_colour(cls, value: str) -> str:
        if not _COLOUR.match(value):
            raise ValueError("a colour like #00FF00")
        return value.upper()

    @field_validator("lang")
    @classmethod
    def _known_language(cls, value: str) -> str:
        return value if value in dict(LANGUAGES) else "en"


def overlay_link(public_url: str, event_id: str, options: OverlayLinkOptions) -> str:
    params: dict[str, str] = {"trackId": options.track}
    if options.chroma:
        params.update(chroma="true", chromaColor=options.chroma_color)
    if not options.gap_to_leader:
        params["gapToLeader"] = "false"
    if not options.show_leaderboard:
        params["showLeaderboard"] = "false"
    if options.lang != "en":
        params["lang"] = options.lang
    if options.car_eye:
        params["carEye"] = "true"
    return f"{public_url.rstrip('/')}/overlay/{quote(event_id, safe='')}?{urlencode(params)}"
