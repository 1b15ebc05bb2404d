"""Paired comparisons for bench/lan.py: the same measurement taken through two doors in alternating rounds, so that
the load other work puts on this shared machine hits both alike; the figure is a statistic over the pairs, with a
percentile bootstrap confidence interval that resamples whole pairs (it keeps what a pair shares, e.g. the
round's machine load or the lap's poll phase).
"""
from __future__ import annotations

import random
import statistics
from collections.abc import Callable, Sequence

Pair = tuple[float, float]  # (loopback, LAN)


def median_of_ratios(pairs: Sequence[Pair]) -> float:
    """Median of LAN / loopback over the pairs (one ratio per round or lap)."""
    return statistics.median(lan / loopback for loopback, lan in pairs)


def bootstrap_ci(pairs: Sequence[Pair], statistic: Callable[[Sequence[Pair]], float], *, resamples: int = 4000,
                 confidence: float = 0.95, seed: int = 12) -> tuple[float, float]:
    """(low, high) percentile bootstrap interval of `statistic`, resampling whole pairs with replacement."""
    rng = random.Random(seed)
    values = sorted(statistic([pairs[rng.randrange(len(pairs))] for _ in pairs]) for _ in range(resamples))
    tail = (1 - confidence) / 2
    return values[int(tail * (resamples - 1))], values[int((1 - tail) * (resamples - 1))]
