"""Which tracks, in which direction, a model trains on and is evaluated on (leave-some-tracks-out).

A *track spec* is a track name (raced its own way round) or `name:reverse` (the other way). `all` stands
for every closed track this install knows (`drem sim tracks`, open routes left out). `generated-A..B` stands for
the generated tracks of seeds A to B (`drem_sim.generated_tracks`: random loops with hairpins and coarse route
files, the same on every machine; `generated-7` alone is one of them). Holding a name out removes both of its
directions; holding `name:reverse` out removes only that direction.
"""
from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

REVERSE_SUFFIX = ":reverse"
ALL = "all"
GENERATED_RANGE = re.compile(r"generated-(\d{1,6})\.\.(\d{1,6})")
MOST_GENERATED = 200  # a range is a few dozen tracks; a typo like 1..10000 would record for hours


class TrackSetError(ValueError):
    """A track spec names no known closed track, or a selection leaves nothing to train on."""


@dataclass(frozen=True, order=True)
class TrackDirection:
    name: str
    reverse: bool = False

    @property
    def label(self) -> str:
        return self.name + (REVERSE_SUFFIX if self.reverse else "")

    def load(self):  # noqa: ANN201 - drem_sim.tracks.Track, imported lazily
        from drem_sim.tracks import load_track

        return load_track(self.name, reverse=self.reverse)


def parse_spec(text: str) -> TrackDirection:
    text = text.strip()
    if text.endswith(REVERSE_SUFFIX):
        return TrackDirection(text[: -len(REVERSE_SUFFIX)], True)
    return TrackDirection(text, False)


def closed_track_names() -> list[str]:
    """Every closed (raceable) track this install ships or finds in $DREM_TRACKS_DIR, sorted by name."""
    from drem_sim.tracks import TrackError, available_tracks, load_track

    names = []
    for name in sorted(available_tracks()):
        try:
            if load_track(name).direction != "open":
                names.append(name)
        except TrackError:
            continue  # a broken file in a tracks folder is not a reason to refuse the others
    return names


def split_specs(values: Iterable[str]) -> list[str]:
    """`--track a,b --track c` → ["a", "b", "c"]."""
    return [part.strip() for value in values for part in str(value).split(",") if part.strip()]


def expand(specs: Iterable[str], both_directions: bool = False) -> list[TrackDirection]:
    """Track specs (with `all`) → distinct (track, direction) pairs in the order given; unknown names refused."""
    known: list[str] | None = None
    out: list[TrackDirection] = []
    for spec in split_specs(specs):
        if spec == ALL:
            known = known if known is not None else closed_track_names()
            picked = [TrackDirection(name) for name in known]
        else:
            picked = _named(spec)
        for item in picked:
            for candidate in ([item, TrackDirection(item.name, not item.reverse)] if both_directions else [item]):
                if candidate not in out:
                    out.append(candidate)
    from drem_sim.tracks import TrackError, load_track

    for item in out:
        try:
            load_track(item.name).require_racing_loop()
        except TrackError as error:
            raise TrackSetError(str(error)) from None
    return out


def _named(spec: str) -> list[TrackDirection]:
    """A spec that names its tracks (not `all`): one track and direction, or each track of a generated range."""
    seeds = GENERATED_RANGE.fullmatch(spec)
    if seeds is None:
        return [parse_spec(spec)]
    return [TrackDirection(f"generated-{seed}") for seed in _seed_range(spec, *seeds.groups())]


def _seed_range(spec: str, first: str, last: str) -> range:
    seeds = range(int(first), int(last) + 1)
    if not seeds:
        raise TrackSetError(f"{spec!r}: the range is empty (write generated-FIRST..LAST, FIRST <= LAST)")
    if len(seeds) > MOST_GENERATED:
        raise TrackSetError(f"{spec!r}: {len(seeds)} generated tracks; at most {MOST_GENERATED} in one range")
    return seeds


def hold_out(selection: list[TrackDirection], held: Iterable[str],
             both_directions: bool = False) -> tuple[list[TrackDirection], list[TrackDirection]]:
    """(kept, held out). A plain name holds out both its directions, `name:reverse` only that one; the held-out
    list is what evaluation drives (also tracks the selection never had)."""
    held_specs = [item for spec in split_specs(held) for item in _named(spec)]
    names = {spec.name for spec in held_specs if not spec.reverse}
    exact = set(held_specs)
    kept = [item for item in selection if item.name not in names and item not in exact]
    return kept, expand([spec.label for spec in held_specs], both_directions)
